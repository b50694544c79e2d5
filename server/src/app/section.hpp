// Area of a material cross-section: the part of the body that lay in a plane
// at rest, wherever it has moved to. This is what the paper's Fig. 2 shows:
// under a large twist, linear strain changes the section's size, Green
// strain (eqs. 5-6) does not.
//
// Each tet the rest plane cuts contributes a triangle or quadrilateral whose
// corners lie on the tet's edges at fixed parameters; a linear tet maps its
// edges affinely, so the deformed polygon has its corners at the same
// parameters between the deformed nodes.
#pragma once

#include <cstdint>
#include <vector>

#include "core/mesh.hpp"
#include "scene/scene.hpp"

namespace tactile {

struct SectionCut {
  struct Corner {
    int32_t a, b;  // node ids of the cut edge
    double s;      // x = x_a + s (x_b - x_a), s in (0, 1]
  };
  std::vector<Corner> corners;  // polygon corners, in cycle order (n_corners)
  std::vector<int32_t> first;   // polygon k has corners [first[k], first[k+1]) (n_polygons + 1)
};

// The polygons of the rest plane in each tet. Nodes on the plane count as on
// its positive side, so a face lying in the plane is counted once.
SectionCut make_section_cut(const TetMesh& mesh, const SectionPlane& plane);

// Sum of the polygons' areas at positions X + u [m^2]; u [m] (n_nodes x 3),
// or empty for the rest area.
double compute_section_area(const SectionCut& cut, const TetMesh& mesh, const std::vector<double>& u);

}  // namespace tactile
