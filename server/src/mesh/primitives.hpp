// Tetrahedral meshes of simple solids, built in memory (no I/O).
//
// Every mesh is conforming (neighbouring tets share whole faces), positively
// oriented and deterministic: the same arguments give the same mesh.
// Invalid arguments throw MeshError.
#pragma once

#include <array>

#include "core/mesh.hpp"

namespace tactile {

// How make_box splits each hexahedral cell.
enum class BoxSplit {
  // 6 tets around the cell's main diagonal (Kuhn / Freudenthal split). The
  // grid nodes are the only nodes; every face diagonal runs from the face's
  // lowest to its highest corner, so neighbouring cells conform.
  kuhn6,
  // 24 tets: a node at each face centre and at the cell centre, one tet per
  // (cell edge, face). The split has the cube's symmetry, which removes the
  // slight anisotropy the Kuhn split gives in bending, at ~2.5x the nodes.
  centred24,
};

// Box [lo, hi] [m] on a structured grid of cells[0] x cells[1] x cells[2]
// hexahedral cells (each >= 1). Grid nodes come first, x fastest:
// node (i, j, k) = i + (cells[0]+1) * (j + (cells[1]+1) * k); the corner nodes
// lie exactly on lo and hi.
TetMesh make_box(const Vec3& lo, const Vec3& hi, std::array<int, 3> cells, BoxSplit split = BoxSplit::kuhn6);

// Solid cylinder [m], axis along +y, base disc at y = 0, top at y = height.
// The cross-section is a polygon of n_around (>= 3) sides inscribed in the
// circle, meshed with n_radial (>= 1) rings of nodes whose counts grow with the
// radius (so elements near the axis are not thin wedges), and extruded over
// n_height (>= 1) layers of prisms, each split into 3 tets. The mesh volume is
// the polygon's area times height: (n_around/2) r^2 sin(2 pi / n_around) h.
TetMesh make_cylinder(double radius, double height, int n_around, int n_height, int n_radial);

// Solid ball [m]: an icosahedron subdivided `resolution` (0..6) times and
// projected onto the sphere (20 * 4^resolution triangles), filled by TetGen
// with quality tets about the size of the surface triangles.
TetMesh make_sphere(const Vec3& centre, double radius, int resolution);

}  // namespace tactile
