// The `mesh` field of a scene: a primitive, a surface file meshed by TetGen,
// or a TetGen .node/.ele mesh; then the quality gate.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "core/embedding.hpp"
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

// The `surface` field of a scene: a fine triangle surface file (.obj, .stl,
// .ply, .off; relative to `scene_dir`), scaled and translated as `mesh` is,
// bound to `mesh` at rest (core/embedding.hpp). max_outside: how far outside
// the body a vertex may be [m] (default 2 % of the body's bounding-box
// diagonal). Throws SceneError naming the field: the file, or the vertex too
// far out.
std::shared_ptr<const EmbeddedSurface> build_embedded_surface(const scene_json::Json& j, const std::string& path,
                                                              const scene_json::Origin& origin,
                                                              const std::string& scene_dir, const TetMesh& mesh);

// What watches long meshing: TetGen reports no progress of its own, so a
// meshing expected to take a while is announced with the tets the size
// check expects (an estimate) and the time that takes at TetGen's pace
// (docs/perf.md, Meshing); the command-line tools draw a progress bar on it
// (app/progress.hpp, MeshingProgress).
class MeshingWatch {
 public:
  virtual ~MeshingWatch() = default;
  // field: the scene's field that asks for the mesh ("mesh.resolution").
  virtual void begin(const std::string& field, double expected_tets, double expected_s) = 0;
  virtual void end() = 0;
};
// The watch of every meshing from now on (nullptr: none). Set it before any
// scene is loaded; the watch must outlive the meshings it sees.
void set_meshing_watch(MeshingWatch* watch);

// Tets that overlap a neighbour: two tets sharing a face with their fourth
// nodes on the same side of it. Readers orient every tet positively on its
// own (mesh/mesh_io.hpp), so a tet inverted in a file comes back positive but
// folded over its neighbours. Of each connected set of tets, those whose
// orientation disagrees with the majority are returned (sorted).
std::vector<int32_t> compute_folded_tets(const TetMesh& mesh);

}  // namespace tactile
