// Scenes of several bodies: each body is read on its own (its mesh, fine
// surface, materials and node sets in its own numbering) and the bodies are
// put one after another into the one ModelSpec that the core steps
// (BodySpec, core/spec.hpp). Pure: no I/O.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "core/spec.hpp"

namespace tactile {

struct BodyParts {
  std::string name;
  TetMesh mesh;                                    // region ids index `materials`
  std::shared_ptr<const EmbeddedSurface> surface;  // bound to `mesh`; null: none
  std::vector<MaterialSpec> materials;
  std::vector<EssentialBc> essential;  // selectors in the body's own node ids
  std::vector<NaturalLoad> loads;
};

// Appends the bodies to `spec` (which holds none yet): meshes one after
// another, region ids offset past the earlier bodies' materials, selectors
// restricted to the body's nodes, fine surfaces concatenated. When some body
// has a fine surface, one without shows and is touched by its own boundary,
// bound as its fine surface (each vertex at a node, of weight 1 on it), so
// that contact meets every body the same way. All bodies must have the same
// element order (ModelError otherwise, naming the body).
void add_bodies(ModelSpec& spec, std::vector<BodyParts> bodies);

// Appends `b` to `a`: its vertices, triangles (offset) and bindings, its
// nodes and tets offset by `node_offset` and `tet_offset`.
void append_embedded(EmbeddedSurface& a, const EmbeddedSurface& b, int32_t node_offset, int32_t tet_offset);

}  // namespace tactile
