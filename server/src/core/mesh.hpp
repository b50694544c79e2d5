// Tetrahedral mesh: the immutable rest geometry every model is built from.
//
// Pure data and pure functions: no file I/O here (readers live in src/mesh/).
// SI units, y up. Tets are linear (4 nodes); a positively oriented tet has
// det[X1-X0, X2-X0, X3-X0] > 0.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <glm/vec3.hpp>

namespace tactile {

using Vec3 = glm::dvec3;
using Tet = std::array<int32_t, 4>;
using Tri = std::array<int32_t, 3>;

// A triangle surface: what a surface file holds, what TetGen meshes, what an
// embedded surface shows (core/embedding.hpp).
struct SurfaceMesh {
  std::vector<Vec3> vertices;  // positions [m] (n_vertices)
  std::vector<Tri> triangles;  // vertex ids, any consistent or inconsistent winding (n_triangles x 3)
};

struct TetMesh {
  std::vector<Vec3> X;          // rest positions [m] (n_nodes)
  std::vector<Tet> tets;        // node ids, positively oriented (n_tets x 4)
  std::vector<int32_t> region;  // region id per tet, selects a material (n_tets); empty = all 0

  int32_t n_nodes() const { return static_cast<int32_t>(X.size()); }
  int32_t n_tets() const { return static_cast<int32_t>(tets.size()); }
  int32_t region_of(int32_t e) const { return region.empty() ? 0 : region[static_cast<size_t>(e)]; }
};

// Signed volume of tet e at positions x [m^3]; positive when positively oriented.
double compute_tet_volume(const Vec3& x0, const Vec3& x1, const Vec3& x2, const Vec3& x3);

// Boundary triangles (faces that belong to exactly one tet), wound so that
// their normal points out of the body (n_faces x 3).
std::vector<Tri> compute_boundary_faces(const TetMesh& mesh);

// Sorted unique node ids on the boundary.
std::vector<int32_t> compute_boundary_nodes(const std::vector<Tri>& faces);

// Axis-aligned bounding box of positions [m].
struct Aabb {
  Vec3 lo{0.0}, hi{0.0};
  Vec3 size() const { return hi - lo; }
};
Aabb compute_aabb(const std::vector<Vec3>& x);

// Morton (Z-order) code of a point in [0, 1]^3 (clamped), 10 bits per axis:
// sorting by it keeps points that are near in space near in memory.
uint32_t compute_morton_code(const Vec3& p);

// Checks indices, counts and orientation; returns "" when the mesh is
// structurally valid, else a message naming the first offending tet or node.
std::string check_mesh_structure(const TetMesh& mesh);

}  // namespace tactile
