// Element quality report and the gate that refuses unusable meshes (pure).
//
// Classification of each tet, in this order:
//   degenerate: a node id out of range, or |V| <= max(min_volume,
//               degenerate_volume_ratio * L_max^3) -- flat or collapsed (a
//               regular tet has V / L^3 = 0.118);
//   inverted:   V < 0 (and not degenerate);
//   poor:       neither, but a dihedral angle or the aspect ratio is past the
//               poor_* thresholds. Poor tets are allowed; they make the model
//               stiffer and the stable time step smaller.
// Aspect ratio = L_max / (2 sqrt(6) r_in), longest edge over inradius, scaled
// so a regular tet is 1; it grows without bound for needles, caps and slivers.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/mesh.hpp"

namespace tactile {

struct QualityThresholds {
  double min_volume = 0;                  // [m^3] absolute floor: |V| <= min_volume is degenerate
  double poor_min_dihedral_deg = 5.0;     // [deg] a smaller dihedral angle is poor
  double poor_max_dihedral_deg = 170.0;   // [deg] a larger dihedral angle is poor
  double poor_aspect_ratio = 10.0;        // a larger aspect ratio is poor
  double degenerate_volume_ratio = 1e-9;  // |V| <= ratio * L_max^3 is degenerate (scale-free)
};

struct MeshQuality {
  // Shape statistics over the tets that are not degenerate (0 when none).
  double min_dihedral_deg = 0, max_dihedral_deg = 0;  // [deg]
  double max_aspect_ratio = 0;                        // L_max / (2 sqrt(6) r_in), regular tet = 1
  // Size statistics over all tets with valid node ids (0 when none).
  double min_volume = 0, max_volume = 0;  // signed [m^3]
  double min_edge = 0, max_edge = 0;      // [m]
  int32_t n_tets = 0, n_nodes = 0;
  std::vector<int32_t> inverted;      // tet ids, ascending
  std::vector<int32_t> degenerate;    // tet ids, ascending
  std::vector<int32_t> poor;          // tet ids, ascending
  std::vector<int32_t> unreferenced;  // node ids in no tet (they would get no mass), ascending

  // A few human-readable lines: counts, ranges, and the number of bad tets.
  std::string summary() const;
};

MeshQuality compute_quality(const TetMesh& mesh, const QualityThresholds& t = {});

// Throws MeshError when check_mesh_structure finds a fault, or when q lists
// inverted or degenerate tets, naming up to 10 ids of each, e.g.
// "mesh refused: 2 inverted tets (ids 4, 17); 1 degenerate tet (id 9)".
// Poor tets and unreferenced nodes are not refused.
void check_mesh_or_throw(const TetMesh& mesh, const MeshQuality& q);

// The same mesh without unreferenced nodes (node order kept, tets renumbered,
// regions kept). Throws MeshError when a tet refers to a node out of range.
TetMesh compute_compacted(const TetMesh& mesh);

}  // namespace tactile
