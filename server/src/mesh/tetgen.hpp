// Closed triangle surface -> quality tetrahedral mesh, through the TetGen
// library (in memory, tetgenio). TetGen is a well-tested mesher; this file
// only checks its input, builds its switches and turns its failures into
// MeshError.
#pragma once

#include <vector>

#include "core/mesh.hpp"

namespace tactile {

struct TetgenOptions {
  double max_radius_edge_ratio = 1.5;  // TetGen -q: circumradius / shortest edge bound; 0 = no quality refinement
  double min_dihedral_deg = 0;         // TetGen -q ratio/angle form when > 0 [deg]
  double max_volume = 0;               // TetGen -a: largest tet volume [m^3]; 0 = no limit
  bool quiet = true;                   // TetGen -Q: print nothing
};

// Tetrahedralizes the volume enclosed by `surface` (TetGen -p, piecewise linear
// complex) with the quality and size bounds of `options`. TetGen may add
// nodes, also on the surface. The tets are returned positively oriented.
//
// Throws MeshError, before calling TetGen, when the surface is empty, has an
// index out of range, a non-finite coordinate, a triangle that repeats a
// vertex, or is not closed (names the first edge not shared by exactly two
// triangles), or when the options are out of range; and after, when TetGen
// fails (self-intersecting surfaces name a pair of crossing triangles).
TetMesh tetrahedralize(const SurfaceMesh& surface, const TetgenOptions& options);

}  // namespace tactile
