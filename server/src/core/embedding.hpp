// An embedded surface: a fine triangle surface carried by the coarse tet mesh
// the body is simulated on (SOFA's barycentric mapping, Vega's coarse-to-fine
// deformer). Each surface vertex is bound once, at rest, to the tet that holds
// it (for a vertex just outside the body: the nearest tet) by its barycentric
// coordinates there, and follows the body as x = sum_i w_i x_{n_i}.
//
// The map is affine per tet, so it gives every rest vertex back exactly, a
// rigid motion of the body moves the surface rigidly, and a vertex outside
// its tet (weights below 0) still moves with that tet's deformation. Pure: no
// I/O; the scene loader reads the file and binds it (scene/scene.hpp).
//
// On quadratic tets a vertex follows the linear sub-tet of its tet (one of
// eight over the ten nodes, the inner octahedron cut along its shortest
// diagonal) that holds it: the quadratic field interpolated
// linearly on a mesh of half the size, four carriers a vertex as on linear
// tets (so that contact, the wire and the views take it as they are). Its
// distance from the quadratic shape functions' own interpolation is
// O((h/2)^2 |grad^2 u|): embedding_error.py prints both.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <stdexcept>
#include <vector>

#include "core/mesh.hpp"

namespace tactile {

struct EmbeddingError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct EmbeddedSurface {
  SurfaceMesh rest;                            // the fine surface at rest, wound outward where closed [m]
  std::vector<Tet> nodes;                      // the four mesh nodes each vertex follows (n_vertices)
  std::vector<std::array<double, 4>> weights;  // its barycentric coordinates in their (sub-)tet, summing to 1
  std::vector<int32_t> tet;                    // that tet (n_vertices)
  std::vector<double> outside;                 // how far the vertex is outside its (sub-)tet at rest [m] (0: inside)

  int32_t n_vertices() const { return static_cast<int32_t>(rest.vertices.size()); }
};

// Binds `surface` to `mesh` at rest. Triangles of each closed component are
// wound consistently and outward (the file's winding may be anything); an open
// component keeps a consistent winding of its first triangle. Throws
// EmbeddingError naming the first vertex further than `max_outside` [m] from
// every tet (its id, position and distance), a surface without triangles, or
// an index out of range.
EmbeddedSurface embed_surface(const TetMesh& mesh, SurfaceMesh surface, double max_outside);

// The surface's vertices at node positions x (mesh numbering, n_nodes): out
// gets n_vertices positions.
void compute_embedded_positions(const EmbeddedSurface& e, std::span<const Vec3> x, std::span<Vec3> out);

// Winds every triangle of `s` consistently with its neighbours across shared
// edges, and each closed component so that its signed volume is positive.
// Returns the number of triangles flipped.
int32_t orient_surface(SurfaceMesh& s);

}  // namespace tactile
