#include "record/foxglove_views.hpp"

#include <algorithm>
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

// An entity `id` in frame `scene`, lasting until replaced.
json entity(int64_t log_ns, const std::string& id, json triangles, json spheres, json cubes) {
  return {{"timestamp", time_of(log_ns)},
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
}

std::string scene_update(json entities) {
  return json{{"deletions", json::array()}, {"entities", std::move(entities)}}.dump();
}

// Body b's colour in a scene of several: a palette the eye tells apart, the
// first body the colour a scene of one has.
json body_colour(size_t b) {
  static constexpr double kPalette[][3] = {
      {0.85, 0.55, 0.45}, {0.45, 0.65, 0.85}, {0.55, 0.80, 0.50}, {0.85, 0.75, 0.40}, {0.70, 0.55, 0.85}};
  const double* c = kPalette[b % (sizeof kPalette / sizeof kPalette[0])];
  return colour(c[0], c[1], c[2], 1.0);
}

// A triangle list of the points and indices, in colour c, or in colours
// per point where `colours` has them.
json triangle_list(json points, const std::vector<uint32_t>& indices, json c, json colours = json::array()) {
  return json::array({{{"pose", pose(nullptr)},
                       {"points", std::move(points)},
                       {"color", std::move(c)},
                       {"colors", std::move(colours)},
                       {"indices", indices}}});
}

// Viridis at u in [0, 1] (clamped; NaN reads as 0), sampled at the stops
// the browser's colour map uses (client-web/src/colormap.js), so that a
// field looks the same in Foxglove as on the page.
json viridis(double u) {
  static constexpr double kStops[][3] = {{0.267, 0.005, 0.329}, {0.283, 0.141, 0.458}, {0.254, 0.265, 0.53},
                                         {0.207, 0.372, 0.553}, {0.164, 0.471, 0.558}, {0.128, 0.567, 0.551},
                                         {0.135, 0.659, 0.518}, {0.267, 0.749, 0.441}, {0.478, 0.821, 0.318},
                                         {0.741, 0.873, 0.15},  {0.993, 0.906, 0.144}};
  constexpr size_t n = sizeof kStops / sizeof kStops[0];
  const double x = (std::isfinite(u) ? std::clamp(u, 0.0, 1.0) : 0.0) * double(n - 1);
  const size_t i = std::min(n - 2, size_t(x));
  const double f = x - double(i);
  const auto at = [&](int c) {
    return std::round((kStops[i][c] + f * (kStops[i + 1][c] - kStops[i][c])) * 1e3) * 1e-3;
  };
  return colour(at(0), at(1), at(2), 1.0);
}

}  // namespace

namespace {

// JSON Schema pieces. Every object lists its properties and every array its
// items: Foxglove builds a datatype from the whole schema before it decodes
// a message (parseJsonSchema in its mcap-support), and refuses an object
// without properties or an array without items.
json object_of(json properties) { return {{"type", "object"}, {"properties", std::move(properties)}}; }
json array_of(json items) { return {{"type", "array"}, {"items", std::move(items)}}; }
json of_type(const char* type, const char* description = nullptr) {
  json t{{"type", type}};
  if (description) t["description"] = description;
  return t;
}
json xyz(const char* description) {
  return object_of({{"x", of_type("number", description)},
                    {"y", of_type("number", description)},
                    {"z", of_type("number", description)}});
}
json quaternion() {
  return object_of(
      {{"x", of_type("number")}, {"y", of_type("number")}, {"z", of_type("number")}, {"w", of_type("number")}});
}
json time_schema() { return object_of({{"sec", of_type("integer")}, {"nsec", of_type("integer")}}); }
json pose_schema() { return object_of({{"position", xyz("[m]")}, {"orientation", quaternion()}}); }
json colour_schema() {
  return object_of(
      {{"r", of_type("number")}, {"g", of_type("number")}, {"b", of_type("number")}, {"a", of_type("number")}});
}
// A primitive: its pose and colour, and `more`.
json primitive(json more) {
  json p = object_of({{"pose", pose_schema()}, {"color", colour_schema()}});
  p["properties"].update(more);
  return p;
}

std::string schema_text(const char* title, json schema) {
  schema["title"] = title;
  return schema.dump();
}

}  // namespace

const std::string& scene_update_json_schema() {
  static const std::string text = [] {
    const json points = array_of(xyz("[m]"));
    const json colours = array_of(colour_schema());
    const json indices = array_of(of_type("integer"));
    const json entity = object_of({
        {"timestamp", time_schema()},
        {"frame_id", of_type("string")},
        {"id", of_type("string")},
        {"lifetime", time_schema()},
        {"frame_locked", of_type("boolean")},
        {"metadata", array_of(object_of({{"key", of_type("string")}, {"value", of_type("string")}}))},
        {"arrows", array_of(primitive({{"shaft_length", of_type("number")},
                                       {"shaft_diameter", of_type("number")},
                                       {"head_length", of_type("number")},
                                       {"head_diameter", of_type("number")}}))},
        {"cubes", array_of(primitive({{"size", xyz("[m]")}}))},
        {"spheres", array_of(primitive({{"size", xyz("[m]")}}))},
        {"cylinders",
         array_of(
             primitive({{"size", xyz("[m]")}, {"bottom_scale", of_type("number")}, {"top_scale", of_type("number")}}))},
        {"lines", array_of(primitive({{"type", of_type("integer", "0 strip, 1 loop, 2 list")},
                                      {"thickness", of_type("number")},
                                      {"scale_invariant", of_type("boolean")},
                                      {"points", points},
                                      {"colors", colours},
                                      {"indices", indices}}))},
        {"triangles", array_of(primitive({{"points", points}, {"colors", colours}, {"indices", indices}}))},
        {"texts", array_of(primitive({{"billboard", of_type("boolean")},
                                      {"font_size", of_type("number")},
                                      {"scale_invariant", of_type("boolean")},
                                      {"text", of_type("string")}}))},
        {"models", array_of(primitive({{"scale", xyz("")},
                                       {"override_color", of_type("boolean")},
                                       {"url", of_type("string")},
                                       {"media_type", of_type("string")},
                                       {"data", {{"type", "string"}, {"contentEncoding", "base64"}}}}))},
    });
    const json deletion = object_of(
        {{"timestamp", time_schema()}, {"type", of_type("integer", "0 by id, 1 all")}, {"id", of_type("string")}});
    return schema_text("foxglove.SceneUpdate",
                       object_of({{"deletions", array_of(deletion)}, {"entities", array_of(entity)}}));
  }();
  return text;
}

const std::string& log_json_schema() {
  static const std::string text = schema_text(
      "foxglove.Log", object_of({{"timestamp", time_schema()},
                                 {"level", of_type("integer", "1 debug, 2 info, 3 warning, 4 error, 5 fatal")},
                                 {"message", of_type("string")},
                                 {"name", of_type("string")},
                                 {"file", of_type("string")},
                                 {"line", of_type("integer")}}));
  return text;
}

const std::string& frame_transform_json_schema() {
  static const std::string text =
      schema_text("foxglove.FrameTransform", object_of({{"timestamp", time_schema()},
                                                        {"parent_frame_id", of_type("string")},
                                                        {"child_frame_id", of_type("string")},
                                                        {"translation", xyz("[m]")},
                                                        {"rotation", quaternion()}}));
  return text;
}

std::string FoxgloveViews::upright(int64_t log_ns) {
  // The scenes are y-up, Foxglove's world z-up: a quarter turn about x
  // takes the scene's y to the world's z.
  const double h = std::sqrt(0.5);
  return json{{"timestamp", time_of(log_ns)},
              {"parent_frame_id", "world"},
              {"child_frame_id", "scene"},
              {"translation", {{"x", 0}, {"y", 0}, {"z", 0}}},
              {"rotation", {{"x", h}, {"y", 0}, {"z", 0}, {"w", h}}}}
      .dump();
}

void FoxgloveViews::scene(const proto::SceneDescription& s) {
  scene_id_ = s.scene_id();
  described_ = true;
  n_vertices_ = s.rest_positions() ? s.rest_positions()->size() / 3 : 0;
  triangles_.clear();
  field_ranges_.clear();
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
  // The bodies of a scene of several, when their slices fit the frame and
  // each triangle lies in its body's vertices (else one entity, as a scene
  // of one).
  bodies_.clear();
  if (s.bodies() && s.bodies()->size() > 1) {
    const size_t n_triangles = triangles_.size() / 3, n_fine_triangles = fine_triangles_.size() / 3;
    const size_t n_fine = carriers_.size() / 4;
    bool fits = true;
    for (const proto::BodyInfo* b : *s.bodies()) {
      Body body{b->name() ? b->name()->str() : "",
                b->vertex_begin(),
                b->vertex_end(),
                b->triangle_begin(),
                b->triangle_end(),
                b->fine_vertex_begin(),
                b->fine_vertex_end(),
                b->fine_triangle_begin(),
                b->fine_triangle_end()};
      fits = fits && body.vertex_begin <= body.vertex_end && body.vertex_end <= n_vertices_ &&
             body.triangle_begin <= body.triangle_end && body.triangle_end <= n_triangles;
      for (size_t k = 3 * size_t(body.triangle_begin); fits && k < 3 * size_t(body.triangle_end); ++k)
        fits = triangles_[k] >= body.vertex_begin && triangles_[k] < body.vertex_end;
      if (!carriers_.empty()) {
        fits = fits && body.fine_vertex_begin <= body.fine_vertex_end && body.fine_vertex_end <= n_fine &&
               body.fine_triangle_begin <= body.fine_triangle_end && body.fine_triangle_end <= n_fine_triangles;
        for (size_t k = 3 * size_t(body.fine_triangle_begin); fits && k < 3 * size_t(body.fine_triangle_end); ++k)
          fits = fine_triangles_[k] >= body.fine_vertex_begin && fine_triangles_[k] < body.fine_vertex_end;
      }
      bodies_.push_back(std::move(body));
    }
    if (!fits) bodies_.clear();
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

std::optional<std::string> FoxgloveViews::body(const proto::StateFrame& f, int64_t log_ns) {
  if (!described_ || f.scene_id() != scene_id_ || !f.positions() || f.positions()->size() != 3 * n_vertices_)
    return std::nullopt;
  const auto* x = f.positions();
  const auto points = [&](uint32_t begin, uint32_t end) {
    json out = json::array();
    for (uint32_t v = begin; v < end; ++v) out.push_back(point(x->Get(3 * v), x->Get(3 * v + 1), x->Get(3 * v + 2)));
    return out;
  };
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
  // The frame's first field, as colours over the range it has shown so far
  // in this scene (it only widens, as on the page, so colours do not
  // flicker); none without one.
  const proto::FrameField* field = nullptr;
  if (f.fields())
    for (const proto::FrameField* ff : *f.fields())
      if (ff->name() && ff->values() && ff->values()->size() == n_vertices_) {
        field = ff;
        break;
      }
  std::pair<double, double>* range = nullptr;
  if (field) {
    range = &field_ranges_.try_emplace(field->name()->str(), INFINITY, -INFINITY).first->second;
    for (float v : *field->values())
      if (std::isfinite(v))
        range->first = std::min(range->first, double(v)), range->second = std::max(range->second, double(v));
  }
  const auto colours = [&](uint32_t begin, uint32_t end) {
    json out = json::array();
    if (!field || !(range->second >= range->first)) return out;
    const double span = range->second > range->first ? range->second - range->first : 1.0;
    for (uint32_t v = begin; v < end; ++v)
      out.push_back(viridis((double(field->values()->Get(v)) - range->first) / span));
    return out;
  };
  if (bodies_.empty())
    return scene_update(json::array({entity(
        log_ns, "body",
        triangle_list(points(0, uint32_t(n_vertices_)), triangles_, body_colour(0), colours(0, uint32_t(n_vertices_))),
        std::move(spheres), std::move(cubes))}));
  // A scene of several: an entity per body ("body/<name>", its own vertices
  // and colour), and one for the proxies.
  json entities = json::array();
  std::vector<uint32_t> indices;
  for (size_t b = 0; b < bodies_.size(); ++b) {
    const Body& body = bodies_[b];
    indices.assign(triangles_.begin() + ptrdiff_t(3 * size_t(body.triangle_begin)),
                   triangles_.begin() + ptrdiff_t(3 * size_t(body.triangle_end)));
    for (uint32_t& v : indices) v -= body.vertex_begin;
    entities.push_back(entity(log_ns, "body/" + body.name,
                              triangle_list(points(body.vertex_begin, body.vertex_end), indices, body_colour(b),
                                            colours(body.vertex_begin, body.vertex_end)),
                              json::array(), json::array()));
  }
  entities.push_back(entity(log_ns, "proxies", json::array(), std::move(spheres), std::move(cubes)));
  return scene_update(std::move(entities));
}

std::optional<std::string> FoxgloveViews::surface(const proto::StateFrame& f, int64_t log_ns) {
  if (carriers_.empty() || !described_ || f.scene_id() != scene_id_ || !f.positions() ||
      f.positions()->size() != 3 * n_vertices_ || (last_surface_ns_ && log_ns - *last_surface_ns_ < kSurfaceEveryNs))
    return std::nullopt;
  last_surface_ns_ = log_ns;
  // Where the browser draws it: x = sum_k w_k x_{c_k}.
  const auto* x = f.positions();
  const auto points = [&](size_t begin, size_t end) {
    json out = json::array();
    for (size_t v = 4 * begin; v < 4 * end; v += 4) {
      double p[3] = {0, 0, 0};
      for (size_t k = 0; k < 4; ++k)
        for (uint32_t d = 0; d < 3; ++d) p[d] += double(weights_[v + k]) * x->Get(3 * carriers_[v + k] + d);
      out.push_back(point(p[0], p[1], p[2]));
    }
    return out;
  };
  if (bodies_.empty())
    return scene_update(json::array(
        {entity(log_ns, "surface", triangle_list(points(0, carriers_.size() / 4), fine_triangles_, body_colour(0)),
                json::array(), json::array())}));
  json entities = json::array();
  std::vector<uint32_t> indices;
  for (size_t b = 0; b < bodies_.size(); ++b) {
    const Body& body = bodies_[b];
    indices.assign(fine_triangles_.begin() + ptrdiff_t(3 * size_t(body.fine_triangle_begin)),
                   fine_triangles_.begin() + ptrdiff_t(3 * size_t(body.fine_triangle_end)));
    for (uint32_t& v : indices) v -= body.fine_vertex_begin;
    entities.push_back(
        entity(log_ns, "surface/" + body.name,
               triangle_list(points(body.fine_vertex_begin, body.fine_vertex_end), indices, body_colour(b)),
               json::array(), json::array()));
  }
  return scene_update(std::move(entities));
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
