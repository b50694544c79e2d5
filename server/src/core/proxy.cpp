#include "core/proxy.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <glm/geometric.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/mat3x3.hpp>

namespace tactile {

const char* to_string(ProxyShape s) {
  switch (s) {
    case ProxyShape::Sphere: return "sphere";
    case ProxyShape::Capsule: return "capsule";
    case ProxyShape::Box: return "box";
    case ProxyShape::Plane: return "plane";
  }
  return "?";
}

namespace {

// Unit vector along p, or `fallback` at the origin.
Vec3 direction_or(const Vec3& p, const Vec3& fallback) {
  const double len = glm::length(p);
  return len > 0 ? p / len : fallback;
}

SurfacePoint locate_box(const Vec3& h, double r, const Vec3& p) {
  // Rounded box: the core box h shrunk by nothing (r is added outside).
  const Vec3 q = glm::abs(p) - h;
  const Vec3 sign(p.x < 0 ? -1.0 : 1.0, p.y < 0 ? -1.0 : 1.0, p.z < 0 ? -1.0 : 1.0);
  const Vec3 outside = glm::max(q, Vec3(0.0));
  const double out_len = glm::length(outside);
  if (out_len > 0) return {out_len - r, direction_or(outside * sign, Vec3(0.0, 1.0, 0.0))};
  // Inside the core box: the nearest face.
  int axis = 0;
  if (q.y > q[axis]) axis = 1;
  if (q.z > q[axis]) axis = 2;
  Vec3 n(0.0);
  n[axis] = sign[axis];
  return {q[axis] - r, n};
}

}  // namespace

SurfacePoint locate(const ProxyGeometry& g, const Vec3& p) {
  switch (g.shape) {
    case ProxyShape::Sphere: return {glm::length(p) - g.radius, direction_or(p, Vec3(0.0, 1.0, 0.0))};
    case ProxyShape::Capsule: {
      const Vec3 axis_point(std::clamp(p.x, -g.half_length, g.half_length), 0.0, 0.0);
      const Vec3 d = p - axis_point;
      return {glm::length(d) - g.radius, direction_or(d, Vec3(0.0, 1.0, 0.0))};
    }
    case ProxyShape::Box: return locate_box(g.half_extents, g.radius, p);
    case ProxyShape::Plane: return {p.y, Vec3(0.0, 1.0, 0.0)};
  }
  return {std::numeric_limits<double>::infinity(), Vec3(0.0, 1.0, 0.0)};
}

double trust_depth(const ProxyGeometry& g) {
  switch (g.shape) {
    case ProxyShape::Sphere:
    case ProxyShape::Capsule: return 0.5 * g.radius;
    case ProxyShape::Box:
      return 0.5 * (std::min({g.half_extents.x, g.half_extents.y, g.half_extents.z}) + g.radius);
    case ProxyShape::Plane: return std::numeric_limits<double>::infinity();
  }
  return 0.0;
}

double bounding_radius(const ProxyGeometry& g) {
  switch (g.shape) {
    case ProxyShape::Sphere: return g.radius;
    case ProxyShape::Capsule: return g.half_length + g.radius;
    case ProxyShape::Box: return glm::length(g.half_extents) + g.radius;
    case ProxyShape::Plane: return std::numeric_limits<double>::infinity();
  }
  return 0.0;
}

Aabb world_bounds(const ProxyGeometry& g, const Pose& pose) {
  const double inf = std::numeric_limits<double>::infinity();
  Vec3 half(0.0);  // half-size of the box around the core shape, before adding the radius
  switch (g.shape) {
    case ProxyShape::Sphere: break;
    case ProxyShape::Capsule: half = glm::abs(pose.orientation * Vec3(g.half_length, 0.0, 0.0)); break;
    case ProxyShape::Box: {
      const glm::dmat3 R = glm::mat3_cast(pose.orientation);
      for (int c = 0; c < 3; ++c) half += glm::abs(R[c]) * g.half_extents[c];  // R[c]: column c, local axis c
      break;
    }
    case ProxyShape::Plane: return {Vec3(-inf), Vec3(inf)};
  }
  const Vec3 r = half + Vec3(g.radius);
  return {pose.position - r, pose.position + r};
}

Pose ProxyMotion::at(double t) const {
  if (!(t1 > t0)) return t >= t1 ? to : from;
  const double s = std::clamp((t - t0) / (t1 - t0), 0.0, 1.0);
  Pose p;
  p.position = from.position + s * (to.position - from.position);
  // Shortest arc: q and -q are one rotation.
  Quat b = to.orientation;
  if (glm::dot(from.orientation, b) < 0) b = -b;
  p.orientation = glm::normalize(glm::slerp(from.orientation, b, s));
  return p;
}

Vec3 ProxyMotion::velocity() const {
  if (!(t1 > t0)) return Vec3(0.0);
  return (to.position - from.position) / (t1 - t0);
}

Vec3 ProxyMotion::angular_velocity() const {
  if (!(t1 > t0)) return Vec3(0.0);
  Quat d = to.orientation * glm::conjugate(from.orientation);  // world-frame turn from `from` to `to`
  if (d.w < 0) d = -d;
  const Vec3 v(d.x, d.y, d.z);
  const double s = glm::length(v);
  if (s < 1e-300) return Vec3(0.0);
  const double angle = 2.0 * std::atan2(s, d.w);
  return (angle / (t1 - t0)) * (v / s);
}

Vec3 ProxyMotion::velocity_at(const Vec3& x, double t) const {
  const Pose p = at(t);
  return velocity() + glm::cross(angular_velocity(), x - p.position);
}

ProxyMotion hold(const Pose& p) {
  ProxyMotion m;
  m.from = m.to = p;
  return m;
}

}  // namespace tactile
