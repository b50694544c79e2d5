#include "scene/scene_mesh.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <new>
#include <string>

#include <glm/common.hpp>
#include <glm/geometric.hpp>

#include "mesh/mesh_error.hpp"
#include "mesh/mesh_io.hpp"
#include "mesh/primitives.hpp"
#include "mesh/tetgen.hpp"

namespace tactile {

using scene_json::Fields;
using scene_json::Json;
using scene_json::Origin;

namespace {

namespace fs = std::filesystem;

std::string lower(std::string s) {
  for (char& c : s) c = char(c >= 'A' && c <= 'Z' ? c - 'A' + 'a' : c);
  return s;
}

std::string list_ids(const std::vector<int32_t>& ids) {
  std::string s;
  for (size_t i = 0; i < ids.size() && i < 10; ++i) s += (i ? ", " : "") + std::to_string(ids[i]);
  if (ids.size() > 10) s += ", and " + std::to_string(ids.size() - 10) + " more";
  return s;
}

// The largest mesh a scene may ask for; beyond it a typo, not a wish.
constexpr int64_t kMaxTets = 20'000'000;
// TetGen's pace, rounded down from what docs/perf.md (Meshing) measured.
constexpr double kTetgenTetsPerSecond = 100e3;
std::atomic<MeshingWatch*> meshing_watch{nullptr};

// Announces a TetGen meshing of about `tets` to the watch, when one is set
// and it should take a second or more, and says when it ends.
class Watched {
 public:
  Watched(const std::string& field, double tets) {
    if (tets / kTetgenTetsPerSecond < 1.0) return;
    watch_ = meshing_watch.load();
    if (watch_) watch_->begin(field, tets, tets / kTetgenTetsPerSecond);
  }
  ~Watched() {
    if (watch_) watch_->end();
  }
  Watched(const Watched&) = delete;
  Watched& operator=(const Watched&) = delete;

 private:
  MeshingWatch* watch_ = nullptr;
};

// What one tet takes to mesh and simulate, all told (mesh, model, state,
// TetGen's own peak), rounded up from docs/perf.md (Meshing).
constexpr double kBytesPerTet = 400;
// How many tets TetGen makes with a volume bound (-a), per volume over the
// bound: rounded up from docs/perf.md (Meshing).
constexpr double kTetgenTetsPerBound = 3.5;

// The memory this machine has free [bytes] (MemAvailable), or infinity where it cannot be read.
double available_bytes() {
  std::ifstream in("/proc/meminfo");
  std::string key;
  double kb = 0;
  std::string unit;
  while (in >> key >> kb >> unit)
    if (key == "MemAvailable:") return kb * 1024.0;
  return std::numeric_limits<double>::infinity();
}

std::string format_count(double n) {
  char text[32];
  if (n >= 1e6)
    std::snprintf(text, sizeof text, "%.1f M", n / 1e6);
  else if (n >= 1e3)
    std::snprintf(text, sizeof text, "%.0f k", n / 1e3);
  else
    std::snprintf(text, sizeof text, "%.0f", n);
  return text;
}

// Refuses, before anything is built, a mesh of about `tets` (exact or
// estimated) that passes kMaxTets or would not fit in the memory free now,
// naming the field that asks for it.
void check_size(const Origin& origin, const std::string& field, double tets, bool estimated) {
  const std::string count = (estimated ? "about " : "") + format_count(tets) + " tets";
  if (tets > double(kMaxTets))
    origin.fail(field, "makes " + count + "; the limit is " + format_count(double(kMaxTets)));
  const double bytes = tets * kBytesPerTet, free = available_bytes();
  if (bytes > free) {
    char text[200];
    std::snprintf(text, sizeof text,
                  "makes %s, which need about %.1f GB to mesh and simulate; this machine has "
                  "%.1f GB free",
                  count.c_str(), bytes / 1e9, free / 1e9);
    origin.fail(field, text);
  }
}

// The volume of a surface's bounding box [m^3]: at least what it encloses,
// however its triangles are wound (an estimate that errs toward refusing).
double bounding_volume(const SurfaceMesh& s) {
  if (s.vertices.empty()) return 0;
  Vec3 lo = s.vertices.front(), hi = lo;
  for (const Vec3& v : s.vertices) {
    lo = glm::min(lo, v);
    hi = glm::max(hi, v);
  }
  return (hi.x - lo.x) * (hi.y - lo.y) * (hi.z - lo.z);
}

TetMesh build_box(const Fields& f) {
  const Vec3 lo = f.vec3("lo"), hi = f.vec3("hi");
  for (int d = 0; d < 3; ++d)
    if (!(hi[d] > lo[d])) f.origin().fail(f.path("hi"), "must exceed lo in every axis");
  const Json& cells = f.at("cells");
  const std::string cells_path = f.path("cells");
  if (!cells.is_array() || cells.size() != 3)
    f.origin().fail(cells_path, "must be an array of 3 integers [nx, ny, nz], got " + scene_json::describe(cells));
  std::array<int, 3> n{};
  int64_t count = 1;
  for (size_t d = 0; d < 3; ++d) {
    n[d] = int(scene_json::read_integer(cells[d], scene_json::join(cells_path, d), f.origin(), 1, 10000));
    count *= n[d];
  }
  const std::string split =
      f.has("split") ? scene_json::read_choice(f.at("split"), f.path("split"), f.origin(), {"kuhn6", "centred24"})
                     : "kuhn6";
  const BoxSplit how = split == "kuhn6" ? BoxSplit::kuhn6 : BoxSplit::centred24;
  count *= how == BoxSplit::kuhn6 ? 6 : 24;
  check_size(f.origin(), cells_path, double(count), false);
  return make_box(lo, hi, n, how);
}

TetMesh build_cylinder(const Fields& f) {
  const double radius = f.positive("radius"), height = f.positive("height");
  const auto around = int(f.integer("around", 3, 4096));
  const auto layers = int(f.integer("layers", 1, 100000));
  const auto rings = int(f.integer("rings", 1, 4096));
  // Its cross-section's triangles (ring k has max(3, ceil(around k / rings))
  // nodes; between rings k-1 and k, as many triangles as both together), three
  // tets per triangle per layer (make_cylinder).
  double triangles = 0;
  int previous = 1;  // the centre
  for (int k = 1; k <= rings; ++k) {
    const int m = std::max(3, (around * k + rings - 1) / rings);
    triangles += k == 1 ? m : previous + m;
    previous = m;
  }
  check_size(f.origin(), f.path("layers"), 3.0 * triangles * layers, false);
  return make_cylinder(radius, height, around, layers, rings);
}

TetMesh build_sphere(const Fields& f) {
  const Vec3 centre = f.vec3("centre");
  const double radius = f.positive("radius");
  const auto resolution = int(f.integer("resolution", 0, 6));
  // About 8 times as many tets per level, at or above what TetGen makes (docs/perf.md, Meshing).
  const double tets = 66.0 * std::pow(8.0, resolution);
  check_size(f.origin(), f.path("resolution"), tets, true);
  const Watched watched(f.path("resolution"), tets);
  return make_sphere(centre, radius, resolution);
}

TetMesh build_from_file(const Fields& f, const std::string& scene_dir) {
  const std::string given = f.string("file");
  const std::string where = f.path("file");
  if (given.empty()) f.origin().fail(where, "must name a mesh file");
  fs::path p(given);
  if (p.is_relative()) p = fs::path(scene_dir) / p;
  const std::string ext = lower(p.extension().string());
  const bool surface = ext == ".obj" || ext == ".stl" || ext == ".off" || ext == ".ply";
  const bool tetgen = ext == ".node" || ext == ".ele";
  if (!surface && !tetgen)
    f.origin().fail(where, "unknown mesh file extension '" + p.extension().string() +
                               "' (surfaces: .obj, .stl, .off, .ply; tet meshes: .node/.ele)");
  std::error_code ec;
  if (!fs::is_regular_file(p, ec))
    f.origin().fail(where, "no such file: " + p.string() + " (paths are relative to the scene file)");
  if (tetgen && f.has("tetgen"))
    f.origin().fail(f.path("tetgen"), "applies to surface files (.obj, .stl, .off, .ply) only, not " + ext);

  TetgenOptions options;
  if (const Json* t = f.find("tetgen")) {
    const Fields o(*t, f.path("tetgen"), f.origin(), {"max_radius_edge_ratio", "min_dihedral_deg", "max_volume"});
    options.max_radius_edge_ratio = o.non_negative_or("max_radius_edge_ratio", options.max_radius_edge_ratio);
    if (options.max_radius_edge_ratio != 0 && options.max_radius_edge_ratio < 1)
      f.origin().fail(o.path("max_radius_edge_ratio"), "must be 0 (no quality refinement) or >= 1 (TetGen -q)");
    options.min_dihedral_deg = o.non_negative_or("min_dihedral_deg", options.min_dihedral_deg);
    if (!(options.min_dihedral_deg < 60)) f.origin().fail(o.path("min_dihedral_deg"), "must be in [0, 60) degrees");
    if (options.min_dihedral_deg > 0 && options.max_radius_edge_ratio == 0)
      f.origin().fail(o.path("min_dihedral_deg"), "needs max_radius_edge_ratio > 0 (both are TetGen -q)");
    options.max_volume = o.non_negative_or("max_volume", options.max_volume);
  }
  try {
    if (tetgen) return read_tetgen(p.string());
    const SurfaceMesh s = read_surface(p.string());
    // (Without a volume bound TetGen makes a few tets per surface vertex.)
    const double tets = options.max_volume > 0 ? kTetgenTetsPerBound * bounding_volume(s) / options.max_volume
                                               : 6.0 * double(s.vertices.size());
    if (options.max_volume > 0) check_size(f.origin(), f.path("tetgen") + ".max_volume", tets, true);
    const Watched watched(where, tets);
    // TetGen may leave input vertices out of every tet (duplicates); they would get no mass.
    return compute_compacted(tetrahedralize(s, options));
  } catch (const MeshError& e) {
    f.origin().fail(where, e.what());
  }
}

// scale (a number or one per axis, > 0) then translate, applied to positions.
void apply_transform(const Fields& f, std::vector<Vec3>& X) {
  Vec3 scale(1.0), shift(0.0);
  if (const Json* s = f.find("scale")) {
    if (s->is_array()) {
      scale = scene_json::read_vec3(*s, f.path("scale"), f.origin());
      for (int d = 0; d < 3; ++d)
        if (!(scale[d] > 0)) f.origin().fail(scene_json::join(f.path("scale"), size_t(d)), "must be > 0");
    } else {
      scale = Vec3(scene_json::read_positive(*s, f.path("scale"), f.origin()));
    }
  }
  if (f.has("translate")) shift = f.vec3("translate");
  for (Vec3& x : X) x = x * scale + shift;
}

}  // namespace

void set_meshing_watch(MeshingWatch* watch) { meshing_watch.store(watch); }

std::shared_ptr<const EmbeddedSurface> build_embedded_surface(const Json& j, const std::string& path,
                                                              const Origin& origin, const std::string& scene_dir,
                                                              const TetMesh& mesh) {
  const Fields f(j, path, origin, {"file", "scale", "translate", "max_outside"});
  const std::string given = f.string("file");
  const std::string where = f.path("file");
  if (given.empty()) origin.fail(where, "must name a surface file (.obj, .stl, .ply, .off)");
  fs::path p(given);
  if (p.is_relative()) p = fs::path(scene_dir) / p;
  const std::string ext = lower(p.extension().string());
  if (ext != ".obj" && ext != ".stl" && ext != ".off" && ext != ".ply")
    origin.fail(where, "unknown surface file extension '" + p.extension().string() + "' (.obj, .stl, .ply, .off)");
  std::error_code ec;
  if (!fs::is_regular_file(p, ec))
    origin.fail(where, "no such file: " + p.string() + " (paths are relative to the scene file)");
  SurfaceMesh surface;
  try {
    surface = read_surface(p.string());
  } catch (const MeshError& e) {
    origin.fail(where, e.what());
  }
  apply_transform(f, surface.vertices);
  const double max_outside = f.non_negative_or("max_outside", 0.02 * glm::length(compute_aabb(mesh.X).size()));
  try {
    return std::make_shared<const EmbeddedSurface>(embed_surface(mesh, std::move(surface), max_outside));
  } catch (const EmbeddingError& e) {
    origin.fail(path, std::string(e.what()) + (f.has("max_outside") ? "" : " (the default: 2 % of the body's size)"));
  }
}

SceneMesh build_scene_mesh(const Json& j, const std::string& path, const Origin& origin, const std::string& scene_dir) {
  if (!j.is_object()) origin.fail(path, "must be an object, got " + scene_json::describe(j));
  const bool primitive = j.contains("primitive"), file = j.contains("file");
  if (primitive && file) origin.fail(path, "give \"primitive\" or \"file\", not both");
  if (!primitive && !file) origin.fail(path, "needs \"primitive\" (box, cylinder, sphere) or \"file\"");

  SceneMesh out;
  try {
    if (file) {
      const Fields f(j, path, origin, {"file", "tetgen", "scale", "translate"});
      out.mesh = build_from_file(f, scene_dir);
      apply_transform(f, out.mesh.X);
    } else {
      const std::string kind = scene_json::read_choice(j.at("primitive"), scene_json::join(path, "primitive"), origin,
                                                       {"box", "cylinder", "sphere"});
      if (kind == "box") {
        const Fields f(j, path, origin, {"primitive", "lo", "hi", "cells", "split", "scale", "translate"});
        out.mesh = build_box(f);
        apply_transform(f, out.mesh.X);
      } else if (kind == "cylinder") {
        const Fields f(j, path, origin,
                       {"primitive", "radius", "height", "around", "layers", "rings", "scale", "translate"});
        out.mesh = build_cylinder(f);
        apply_transform(f, out.mesh.X);
      } else {
        const Fields f(j, path, origin, {"primitive", "centre", "radius", "resolution", "scale", "translate"});
        out.mesh = build_sphere(f);
        apply_transform(f, out.mesh.X);
      }
    }
  } catch (const MeshError& e) {
    origin.fail(path, e.what());
  } catch (const std::bad_alloc&) {
    origin.fail(path, "ran out of memory while meshing (" + format_count(double(out.mesh.tets.size())) +
                          " tets built); ask for a coarser mesh");
  }

  // The quality gate: inverted (also folded) and degenerate tets are refused by id.
  out.quality = compute_quality(out.mesh);
  const std::vector<int32_t> folded = compute_folded_tets(out.mesh);
  if (!folded.empty()) {
    std::vector<int32_t>& inv = out.quality.inverted;
    inv.insert(inv.end(), folded.begin(), folded.end());
    std::sort(inv.begin(), inv.end());
    inv.erase(std::unique(inv.begin(), inv.end()), inv.end());
    // Folded tets are not poor ones, whatever their shape.
    std::vector<int32_t>& poor = out.quality.poor;
    poor.erase(std::remove_if(poor.begin(), poor.end(),
                              [&](int32_t e) { return std::binary_search(inv.begin(), inv.end(), e); }),
               poor.end());
  }
  try {
    check_mesh_or_throw(out.mesh, out.quality);
  } catch (const MeshError& e) {
    origin.fail(path, e.what());
  }
  if (!out.quality.unreferenced.empty())
    origin.fail(path, std::to_string(out.quality.unreferenced.size()) + " node(s) belong to no tet (ids " +
                          list_ids(out.quality.unreferenced) + "); they would get no mass: remove them");
  return out;
}

std::vector<int32_t> compute_folded_tets(const TetMesh& mesh) {
  // Faces of a positively oriented tet, wound outwards (as in core/mesh.cpp); kApex[f] is the node not on face f.
  static constexpr int kFace[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  static constexpr int kApex[4] = {3, 2, 1, 0};
  struct FaceRef {
    std::array<int32_t, 3> key;  // sorted node ids
    int32_t tet;
    int8_t face;
  };
  const auto nt = size_t(mesh.n_tets());
  std::vector<FaceRef> faces;
  faces.reserve(4 * nt);
  for (size_t e = 0; e < nt; ++e) {
    for (int8_t f = 0; f < 4; ++f) {
      const Tet& t = mesh.tets[e];
      std::array<int32_t, 3> key{t[size_t(kFace[f][0])], t[size_t(kFace[f][1])], t[size_t(kFace[f][2])]};
      std::sort(key.begin(), key.end());
      faces.push_back({key, int32_t(e), f});
    }
  }
  std::sort(faces.begin(), faces.end(), [](const FaceRef& a, const FaceRef& b) { return a.key < b.key; });

  // Each interior face links two tets: consistently (0) or folded (1).
  struct Link {
    int32_t other;
    int8_t folded;
  };
  std::vector<std::vector<Link>> links(nt);
  bool any_folded = false;
  for (size_t i = 0; i + 1 < faces.size(); ++i) {
    if (faces[i].key != faces[i + 1].key) continue;
    if (i + 2 < faces.size() && faces[i + 2].key == faces[i].key) {  // non-manifold: leave to the other checks
      while (i + 1 < faces.size() && faces[i + 1].key == faces[i].key) ++i;
      continue;
    }
    const FaceRef &a = faces[i], &b = faces[i + 1];
    const Tet& ta = mesh.tets[size_t(a.tet)];
    const Tet& tb = mesh.tets[size_t(b.tet)];
    const Vec3& p0 = mesh.X[size_t(ta[size_t(kFace[a.face][0])])];
    const Vec3& p1 = mesh.X[size_t(ta[size_t(kFace[a.face][1])])];
    const Vec3& p2 = mesh.X[size_t(ta[size_t(kFace[a.face][2])])];
    const Vec3 outward = glm::cross(p1 - p0, p2 - p0);  // of a, when a is positively oriented
    const double side_a = glm::dot(outward, mesh.X[size_t(ta[size_t(kApex[a.face])])] - p0);
    const double side_b = glm::dot(outward, mesh.X[size_t(tb[size_t(kApex[b.face])])] - p0);
    // Apexes on the same side of the shared face: the tets overlap.
    const int8_t folded = (side_a < 0) == (side_b < 0) && side_a != 0 && side_b != 0 ? 1 : 0;
    any_folded = any_folded || folded;
    links[size_t(a.tet)].push_back({b.tet, folded});
    links[size_t(b.tet)].push_back({a.tet, folded});
    ++i;
  }
  if (!any_folded) return {};

  // Two-colour each connected set by orientation; the minority colour is folded.
  std::vector<int8_t> colour(nt, -1);
  std::vector<int32_t> out, stack, members;
  for (size_t seed = 0; seed < nt; ++seed) {
    if (colour[seed] >= 0) continue;
    colour[seed] = 0;
    stack.assign(1, int32_t(seed));
    members.clear();
    size_t ones = 0;
    while (!stack.empty()) {
      const int32_t e = stack.back();
      stack.pop_back();
      members.push_back(e);
      ones += size_t(colour[size_t(e)]);
      for (const Link& l : links[size_t(e)]) {
        if (colour[size_t(l.other)] >= 0) continue;
        colour[size_t(l.other)] = int8_t(colour[size_t(e)] ^ l.folded);
        stack.push_back(l.other);
      }
    }
    const int8_t minority = ones * 2 <= members.size() ? 1 : 0;
    for (int32_t e : members)
      if (colour[size_t(e)] == minority) out.push_back(e);
  }
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace tactile
