// Mesh files: triangle surfaces in, TetGen .node/.ele tet meshes in and out.
//
// The one place of the mesh library that touches files. Every error throws
// MeshError naming the path (and line, for text formats read here) and what is
// wrong with it.
#pragma once

#include <string>

#include "core/mesh.hpp"
#include "mesh/tetgen.hpp"

namespace tactile {

// Reads a triangle surface; the format is chosen by the extension, in any case:
// .obj, .stl (ASCII or binary), .ply (ASCII or binary) through Assimp, and .off
// by a reader of our own (Assimp 5.2 silently clamps out-of-range OFF indices).
// Polygons are split into triangles; vertices at the same position are welded,
// so the result is indexed. Assimp stores coordinates as float, so positions
// from .obj/.stl/.ply carry about 7 significant digits.
// Throws MeshError for a missing file, an unknown extension, a parse error, an
// index out of range, a non-finite coordinate or a file without triangles.
SurfaceMesh read_surface(const std::string& path);

// Reads a TetGen tet mesh: `path` is the .node file, the .ele file or their
// common base name. Numbering may start at 0 or 1 (taken from the first node);
// node attributes and boundary markers are skipped; the first tet attribute,
// when present, becomes the region id (it must be an integer). Tets of
// negative volume are reoriented (files from other tools may use the other
// handedness); flat tets are kept as read, for the quality check to report.
// Ten nodes a tet (TetGen -o2) make a quadratic mesh (core/mesh.hpp): the
// corners first, then the edge nodes in any order, each matched to the edge
// whose midpoint it sits at; one off every midpoint (a curved tet) is refused.
TetMesh read_tetgen(const std::string& path);

// Writes base + ".node" and base + ".ele", numbered from 0, with the region id
// as the one tet attribute when the mesh has regions; a quadratic mesh's tets
// with ten nodes, the corners then the edge nodes in core/mesh.hpp's order. Coordinates round-trip
// exactly (17 significant digits).
void write_tetgen(const TetMesh& mesh, const std::string& base);

// Writes a Wavefront OBJ with "v" and "f" lines only (1-based ids).
void write_surface_obj(const SurfaceMesh& surface, const std::string& path);

}  // namespace tactile
