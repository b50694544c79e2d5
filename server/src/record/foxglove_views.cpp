#include "record/foxglove_views.hpp"

#include <cmath>

#include <nlohmann/json.hpp>

namespace tactile {
namespace {

using nlohmann::json;

json time_of(int64_t ns) { return {{"sec", ns / 1'000'000'000}, {"nsec", ns % 1'000'000'000}}; }

// Positions to 1 um: the JSON stays short (a float printed in full takes
// 17 digits) and no eye tells the difference.
double micrometres(double x) { return std::round(x * 1e6) * 1e-6; }

json point(double x, double y, double z) {
  return {{"x", micrometres(x)}, {"y", micrometres(y)}, {"z", micrometres(z)}};
}

json pose(const proto::ProxyPose* p) {
  if (!p) return {{"position", point(0, 0, 0)}, {"orientation", {{"x", 0}, {"y", 0}, {"z", 0}, {"w", 1}}}};
  const proto::Quatf& q = p->orientation();
  return {{"position", point(p->position().x(), p->position().y(), p->position().z())},
          {"orientation", {{"x", q.x()}, {"y", q.y()}, {"z", q.z()}, {"w", q.w()}}}};
}

json colour(double r, double g, double b, double a) { return {{"r", r}, {"g", g}, {"b", b}, {"a", a}}; }

// A SceneUpdate of one entity `id` in frame `scene`, lasting until replaced.
std::string scene_update(int64_t log_ns, const char* id, json triangles, json spheres, json cubes) {
  json entity = {{"timestamp", time_of(log_ns)},
                 {"frame_id", "scene"},
                 {"id", id},
                 {"lifetime", {{"sec", 0}, {"nsec", 0}}},
                 {"frame_locked", false},
                 {"metadata", json::array()},
                 {"arrows", json::array()},
                 {"cubes", std::move(cubes)},
                 {"spheres", std::move(spheres)},
                 {"cylinders", json::array()},
                 {"lines", json::array()},
                 {"triangles", std::move(triangles)},
                 {"texts", json::array()},
                 {"models", json::array()}};
  return json{{"deletions", json::array()}, {"entities", json::array({std::move(entity)})}}.dump();
}

}  // namespace

std::string_view scene_update_json_schema() {
  return R"({"title":"foxglove.SceneUpdate","type":"object","properties":{)"
         R"("deletions":{"type":"array"},)"
         R"("entities":{"type":"array","items":{"type":"object","properties":{)"
         R"("timestamp":{"type":"object"},"frame_id":{"type":"string"},"id":{"type":"string"},)"
         R"("lifetime":{"type":"object"},"frame_locked":{"type":"boolean"},"metadata":{"type":"array"},)"
         R"("arrows":{"type":"array"},"cubes":{"type":"array"},"spheres":{"type":"array"},)"
         R"("cylinders":{"type":"array"},"lines":{"type":"array"},"triangles":{"type":"array"},)"
         R"("texts":{"type":"array"},"models":{"type":"array"}}}}}})";
}

std::string_view log_json_schema() {
  return R"({"title":"foxglove.Log","type":"object","properties":{)"
         R"("timestamp":{"type":"object"},"level":{"type":"integer","description":"1 debug, 2 info, 3 warning, 4 error"},)"
         R"("message":{"type":"string"},"name":{"type":"string"},"file":{"type":"string"},"line":{"type":"integer"}}})";
}

void FoxgloveViews::scene(const proto::SceneDescription& s) {
  scene_id_ = s.scene_id();
  described_ = true;
  n_vertices_ = s.rest_positions() ? s.rest_positions()->size() / 3 : 0;
  triangles_.clear();
  if (s.triangles()) triangles_.assign(s.triangles()->begin(), s.triangles()->end());
  fine_triangles_.clear();
  carriers_.clear();
  weights_.clear();
  last_surface_ns_.reset();
  const proto::EmbeddedSurface* fine = s.embedded();
  if (fine && fine->triangles() && fine->carriers() && fine->weights() && fine->rest_positions() &&
      fine->carriers()->size() == fine->weights()->size() && fine->carriers()->size() % 4 == 0 &&
      fine->carriers()->size() / 4 == fine->rest_positions()->size() / 3) {
    const auto fine_vertices = uint32_t(fine->carriers()->size() / 4);
    bool fits = true;  // a carrier or corner out of range would read past the frame or the points
    for (uint32_t c : *fine->carriers()) fits = fits && size_t(c) < n_vertices_;
    for (uint32_t v : *fine->triangles()) fits = fits && v < fine_vertices;
    if (fits) {
      fine_triangles_.assign(fine->triangles()->begin(), fine->triangles()->end());
      carriers_.assign(fine->carriers()->begin(), fine->carriers()->end());
      weights_.assign(fine->weights()->begin(), fine->weights()->end());
    }
  }
  proxies_.clear();
  if (s.proxies())
    for (const proto::ProxyInfo* p : *s.proxies()) {
      Proxy q{p->shape(), p->radius(), p->half_length(), {0, 0, 0}};
      if (p->half_extents()) {
        q.half_extents[0] = p->half_extents()->x();
        q.half_extents[1] = p->half_extents()->y();
        q.half_extents[2] = p->half_extents()->z();
      }
      proxies_.push_back(q);
    }
}

std::optional<std::string> FoxgloveViews::body(const proto::StateFrame& f, int64_t log_ns) const {
  if (!described_ || f.scene_id() != scene_id_ || !f.positions() || f.positions()->size() != 3 * n_vertices_)
    return std::nullopt;
  const auto* x = f.positions();
  json points = json::array();
  for (uint32_t v = 0; v < uint32_t(n_vertices_); ++v)
    points.push_back(point(x->Get(3 * v), x->Get(3 * v + 1), x->Get(3 * v + 2)));
  json triangles = json::array();
  triangles.push_back({{"pose", pose(nullptr)},
                       {"points", std::move(points)},
                       {"color", colour(0.85, 0.55, 0.45, 1.0)},
                       {"colors", json::array()},
                       {"indices", triangles_}});
  json spheres = json::array(), cubes = json::array();
  for (size_t k = 0; k < proxies_.size(); ++k) {
    const proto::ProxyPose* p = f.proxies() && k < f.proxies()->size() ? f.proxies()->Get(uint32_t(k)) : nullptr;
    const Proxy& q = proxies_[k];
    if (q.shape == proto::ProxyShape::Box) {
      cubes.push_back({{"pose", pose(p)},
                       {"size", point(2 * q.half_extents[0], 2 * q.half_extents[1], 2 * q.half_extents[2])},
                       {"color", colour(0.3, 0.6, 0.9, 0.8)}});
    } else if (q.shape != proto::ProxyShape::Plane) {
      const double d = 2 * q.radius;
      spheres.push_back({{"pose", pose(p)}, {"size", point(d, d, d)}, {"color", colour(0.3, 0.6, 0.9, 0.8)}});
    }
  }
  return scene_update(log_ns, "body", std::move(triangles), std::move(spheres), std::move(cubes));
}

std::optional<std::string> FoxgloveViews::surface(const proto::StateFrame& f, int64_t log_ns) {
  if (carriers_.empty() || !described_ || f.scene_id() != scene_id_ || !f.positions() ||
      f.positions()->size() != 3 * n_vertices_ || (last_surface_ns_ && log_ns - *last_surface_ns_ < kSurfaceEveryNs))
    return std::nullopt;
  last_surface_ns_ = log_ns;
  // Where the browser draws it: x = sum_k w_k x_{c_k}.
  const auto* x = f.positions();
  json points = json::array();
  for (size_t v = 0; v < carriers_.size(); v += 4) {
    double p[3] = {0, 0, 0};
    for (size_t k = 0; k < 4; ++k)
      for (uint32_t d = 0; d < 3; ++d) p[d] += double(weights_[v + k]) * x->Get(3 * carriers_[v + k] + d);
    points.push_back(point(p[0], p[1], p[2]));
  }
  json triangles = json::array();
  triangles.push_back({{"pose", pose(nullptr)},
                       {"points", std::move(points)},
                       {"color", colour(0.85, 0.55, 0.45, 1.0)},
                       {"colors", json::array()},
                       {"indices", fine_triangles_}});
  return scene_update(log_ns, "surface", std::move(triangles), json::array(), json::array());
}

std::string FoxgloveViews::log(const proto::SafetyEvent& e, int64_t log_ns) {
  // Forces stopped or limited are warnings; a fault is an error.
  const proto::SafetyKind k = e.kind();
  const int level = k == proto::SafetyKind::Engaged                                            ? 2
                    : k == proto::SafetyKind::ServerFault || k == proto::SafetyKind::NonFinite ? 4
                                                                                               : 3;
  const std::string device = e.device() ? e.device()->str() : "";
  const std::string text = std::string(proto::EnumNameSafetyKind(k)) + (e.message() ? ": " + e.message()->str() : "") +
                           " (" + std::to_string(e.force_N()) + " N)";
  return json{{"timestamp", time_of(log_ns)}, {"level", level}, {"message", text},
              {"name", "bridge/" + device},   {"file", ""},     {"line", 0}}
      .dump();
}

std::string FoxgloveViews::log(const proto::Error& e, int64_t log_ns) {
  const std::string text =
      std::string(proto::EnumNameErrorCode(e.code())) + (e.message() ? ": " + e.message()->str() : "");
  return json{
      {"timestamp", time_of(log_ns)}, {"level", 4}, {"message", text}, {"name", "server"}, {"file", ""}, {"line", 0}}
      .dump();
}

}  // namespace tactile
