// The `mesh` field of a scene: a primitive, a surface file meshed by TetGen,
// or a TetGen .node/.ele mesh; then the quality gate.
#pragma once

#include <string>
#include <vector>

#include "core/mesh.hpp"
#include "mesh/quality.hpp"
#include "scene/json_fields.hpp"

namespace tactile {

struct SceneMesh {
  TetMesh mesh;
  MeshQuality quality;  // inverted includes the folded tets (compute_folded_tets)
};

// Builds the mesh the JSON object `j` (at JSON path `path`) describes; file
// paths are relative to `scene_dir`. Refuses meshes with inverted, folded or
// degenerate tets or unreferenced nodes, naming them. Throws SceneError.
SceneMesh build_scene_mesh(const scene_json::Json& j, const std::string& path, const scene_json::Origin& origin,
                           const std::string& scene_dir);

// Tets that overlap a neighbour: two tets sharing a face with their fourth
// nodes on the same side of it. Readers orient every tet positively on its
// own (mesh/mesh_io.hpp), so a tet inverted in a file comes back positive but
// folded over its neighbours. Of each connected set of tets, those whose
// orientation disagrees with the majority are returned (sorted).
std::vector<int32_t> compute_folded_tets(const TetMesh& mesh);

}  // namespace tactile
