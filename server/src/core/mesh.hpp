// Tetrahedral mesh: the immutable rest geometry every model is built from.
//
// Pure data and pure functions: no file I/O here (readers live in src/mesh/).
// SI units, y up. A positively oriented tet has det[X1-X0, X2-X0, X3-X0] > 0.
// Tets are linear (4 nodes, P1) or, when the mesh lists edge nodes,
// quadratic (10 nodes, P2; core/quadratic.hpp): the corners, then one node
// on each edge, shared by every tet around the edge, in VTK's order
// (VTK_QUADRATIC_TETRA): 4 (0-1), 5 (1-2), 6 (0-2), 7 (0-3), 8 (1-3), 9 (2-3).
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
using TetEdges = std::array<int32_t, 6>;  // a quadratic tet's six edge nodes, in kTetEdges order

// The corners of each edge node 4..9 of a quadratic tet, in VTK's order.
inline constexpr int kTetEdges[6][2] = {{0, 1}, {1, 2}, {0, 2}, {0, 3}, {1, 3}, {2, 3}};

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
  std::vector<TetEdges> edges;  // quadratic: each tet's edge nodes (n_tets); empty = linear

  int32_t n_nodes() const { return static_cast<int32_t>(X.size()); }
  int32_t n_tets() const { return static_cast<int32_t>(tets.size()); }
  int32_t region_of(int32_t e) const { return region.empty() ? 0 : region[static_cast<size_t>(e)]; }
  bool quadratic() const { return !edges.empty(); }
  int nodes_per_tet() const { return quadratic() ? 10 : 4; }
  // Node k of tet e: a corner for k < 4, else edge node k (k < nodes_per_tet()).
  int32_t node(size_t e, int k) const { return k < 4 ? tets[e][size_t(k)] : edges[e][size_t(k - 4)]; }
};

// Signed volume of tet e at positions x [m^3]; positive when positively oriented.
double compute_tet_volume(const Vec3& x0, const Vec3& x1, const Vec3& x2, const Vec3& x3);

// The point of triangle (a, b, c) nearest p (Ericson, Real-Time Collision
// Detection, 5.1.5). (core/proxy.cpp has the same as barycentric weights.)
Vec3 compute_closest_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c);

// Boundary triangles (faces that belong to exactly one tet), wound so that
// their normal points out of the body (n_faces x 3). A quadratic mesh's
// boundary face is split at its three edge nodes into four, wound the same
// way: flat triangles over every surface node, what contact meets and the
// views draw.
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
// A quadratic mesh's edge nodes: one per edge, none a corner, the same node
// for every tet around an edge.
std::string check_mesh_structure(const TetMesh& mesh);

}  // namespace tactile
