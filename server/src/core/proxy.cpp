#include "core/proxy.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

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

// Barycentric weights of the point of triangle (a, b, c) nearest p
// (Ericson, Real-Time Collision Detection, 5.1.5: by Voronoi regions, so a
// point on an edge or at a vertex has exact zeros).
Vec3 closest_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = glm::dot(ab, ap), d2 = glm::dot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return {1, 0, 0};
  const Vec3 bp = p - b;
  const double d3 = glm::dot(ab, bp), d4 = glm::dot(ac, bp);
  if (d3 >= 0 && d4 <= d3) return {0, 1, 0};
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double v = d1 / (d1 - d3);
    return {1 - v, v, 0};
  }
  const Vec3 cp = p - c;
  const double d5 = glm::dot(ab, cp), d6 = glm::dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return {0, 0, 1};
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double w = d2 / (d2 - d6);
    return {1 - w, 0, w};
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && d4 - d3 >= 0 && d5 - d6 >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return {0, 1 - w, w};
  }
  const double sum = va + vb + vc;
  if (!(sum > 0)) return {1, 0, 0};  // a triangle of no area: its first vertex
  const double v = vb / sum, w = vc / sum;
  return {1 - v - w, v, w};
}

// Parameters (s on p0-p1, t on q0-q1, both in [0, 1]) of the closest points of two segments (Ericson 5.1.9).
std::pair<double, double> closest_on_segments(const Vec3& p0, const Vec3& p1, const Vec3& q0, const Vec3& q1) {
  const Vec3 d1 = p1 - p0, d2 = q1 - q0, r = p0 - q0;
  const double a = glm::dot(d1, d1), e = glm::dot(d2, d2), f = glm::dot(d2, r);
  constexpr double tiny = 1e-300;
  if (a <= tiny && e <= tiny) return {0, 0};
  if (a <= tiny) return {0, std::clamp(f / e, 0.0, 1.0)};
  const double c = glm::dot(d1, r);
  if (e <= tiny) return {std::clamp(-c / a, 0.0, 1.0), 0};
  const double b = glm::dot(d1, d2), denom = a * e - b * b;
  double s = denom > 0 ? std::clamp((b * f - c * e) / denom, 0.0, 1.0) : 0.0;
  double t = (b * s + f) / e;
  if (t < 0) {
    t = 0;
    s = std::clamp(-c / a, 0.0, 1.0);
  } else if (t > 1) {
    t = 1;
    s = std::clamp((b - c) / a, 0.0, 1.0);
  }
  return {s, t};
}

// Barycentric weights where segment p0-p1 crosses triangle (a, b, c), if it does.
bool segment_meets_triangle(const Vec3& p0, const Vec3& p1, const Vec3& a, const Vec3& b, const Vec3& c, Vec3& w) {
  const Vec3 d = p1 - p0, e1 = b - a, e2 = c - a;
  const Vec3 h = glm::cross(d, e2);
  const double det = glm::dot(e1, h);
  if (std::fabs(det) <= 1e-300) return false;  // parallel to the triangle's plane
  const Vec3 s = p0 - a;
  const double u = glm::dot(s, h) / det;
  if (u < 0 || u > 1) return false;
  const Vec3 q = glm::cross(s, e1);
  const double v = glm::dot(d, q) / det;
  if (v < 0 || u + v > 1) return false;
  const double t = glm::dot(e2, q) / det;
  if (t < 0 || t > 1) return false;
  w = Vec3(1 - u - v, u, v);
  return true;
}

Vec3 at_weights(const Vec3& w, const Vec3& a, const Vec3& b, const Vec3& c) { return w.x * a + w.y * b + w.z * c; }

Vec3 deepest_in_capsule(double half_length, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 p0(-half_length, 0, 0), p1(half_length, 0, 0);
  Vec3 w;
  if (segment_meets_triangle(p0, p1, a, b, c, w)) return w;  // the axis passes through: as deep as can be
  // Otherwise the nearest pair has an end of the axis, or an edge of the triangle, in it.
  const auto axis_distance = [&](const Vec3& x) {
    return glm::distance(x, Vec3(std::clamp(x.x, -half_length, half_length), 0.0, 0.0));
  };
  Vec3 best = closest_on_triangle(p0, a, b, c);
  double best_d = axis_distance(at_weights(best, a, b, c));
  const auto consider = [&](const Vec3& cand) {
    const double d = axis_distance(at_weights(cand, a, b, c));
    if (d < best_d) {
      best_d = d;
      best = cand;
    }
  };
  consider(closest_on_triangle(p1, a, b, c));
  const Vec3 corner[3] = {a, b, c};
  for (int k = 0; k < 3; ++k) {
    const int l = (k + 1) % 3;
    const double t = closest_on_segments(p0, p1, corner[k], corner[l]).second;
    Vec3 cand(0.0);
    cand[k] = 1 - t;
    cand[l] = t;
    consider(cand);
  }
  return best;
}

// Parameter range [t0, t1] of segment p + t d, t in [0, 1], inside the box [-h, h]; false if it misses.
bool clip_to_box(const Vec3& p, const Vec3& d, const Vec3& h, double& t0, double& t1) {
  t0 = 0;
  t1 = 1;
  for (int k = 0; k < 3; ++k) {
    if (std::fabs(d[k]) <= 1e-300) {
      if (p[k] < -h[k] || p[k] > h[k]) return false;
      continue;
    }
    double a = (-h[k] - p[k]) / d[k], b = (h[k] - p[k]) / d[k];
    if (a > b) std::swap(a, b);
    t0 = std::max(t0, a);
    t1 = std::min(t1, b);
    if (t0 > t1) return false;
  }
  return true;
}

// Squared distance between two boxes [alo, ahi] and [blo, bhi] (0 if they meet).
double box_gap2(const Vec3& alo, const Vec3& ahi, const Vec3& blo, const Vec3& bhi) {
  const Vec3 gap = glm::max(Vec3(0.0), glm::max(alo - bhi, blo - ahi));
  return glm::dot(gap, gap);
}

Vec3 deepest_in_box(const Vec3& h, const Vec3& a, const Vec3& b, const Vec3& c) {
  // The nearest pair of two convex polytopes is a corner of one against the
  // other, or an edge of each; where they meet, a common point is as deep
  // as the rounding and more. Each such candidate is ranked by its key: the
  // squared distance to the core box outside it, and its (negative) depth
  // inside; those whose box lies farther from the triangle's box than the
  // best so far are skipped.
  const Vec3 corner[3] = {a, b, c};
  const Vec3 tlo = glm::min(a, glm::min(b, c)), thi = glm::max(a, glm::max(b, c));
  const auto key = [&](const Vec3& p) {
    const Vec3 q = glm::abs(p) - h;
    const Vec3 out = glm::max(q, Vec3(0.0));
    const double d2 = glm::dot(out, out);
    return d2 > 0 ? d2 : std::max({q.x, q.y, q.z});
  };
  Vec3 best(1, 0, 0);
  double best_key = std::numeric_limits<double>::infinity();
  const auto consider = [&](const Vec3& w) {
    const double k = key(at_weights(w, a, b, c));
    if (k < best_key) {
      best_key = k;
      best = w;
    }
  };
  const auto on_edge = [](int k, double t) {
    Vec3 w(0.0);
    w[k] = 1 - t;
    w[(k + 1) % 3] = t;
    return w;
  };
  for (int k = 0; k < 3; ++k) {
    Vec3 w(0.0);
    w[k] = 1;
    consider(w);  // the triangle's corners
  }
  for (int k = 0; k < 3; ++k) {
    double t0, t1;
    if (clip_to_box(corner[k], corner[(k + 1) % 3] - corner[k], h, t0, t1))
      consider(on_edge(k, 0.5 * (t0 + t1)));  // an edge through the core
  }
  const auto worth = [&](const Vec3& lo, const Vec3& hi) { return box_gap2(lo, hi, tlo, thi) < best_key; };
  for (int sx = -1; sx <= 1; sx += 2)
    for (int sy = -1; sy <= 1; sy += 2)
      for (int sz = -1; sz <= 1; sz += 2) {
        const Vec3 p(sx * h.x, sy * h.y, sz * h.z);
        if (worth(p, p)) consider(closest_on_triangle(p, a, b, c));
      }
  for (int axis = 0; axis < 3; ++axis) {
    const int u = (axis + 1) % 3, v = (axis + 2) % 3;
    for (int su = -1; su <= 1; su += 2)
      for (int sv = -1; sv <= 1; sv += 2) {
        Vec3 e0(0.0);
        e0[u] = su * h[u];
        e0[v] = sv * h[v];
        Vec3 e1 = e0;
        e0[axis] = -h[axis];
        e1[axis] = h[axis];
        if (!worth(glm::min(e0, e1), glm::max(e0, e1))) continue;
        Vec3 w;
        if (segment_meets_triangle(e0, e1, a, b, c, w)) consider(w);  // a box edge through the triangle
        for (int k = 0; k < 3; ++k)
          consider(on_edge(k, closest_on_segments(e0, e1, corner[k], corner[(k + 1) % 3]).second));
      }
  }
  return best;
}

}  // namespace

Vec3 deepest_on_triangle(const ProxyGeometry& g, const Vec3& a, const Vec3& b, const Vec3& c) {
  switch (g.shape) {
    case ProxyShape::Sphere: return closest_on_triangle(Vec3(0.0), a, b, c);
    case ProxyShape::Capsule: return deepest_in_capsule(g.half_length, a, b, c);
    case ProxyShape::Box: return deepest_in_box(g.half_extents, a, b, c);
    case ProxyShape::Plane: break;
  }
  // A plane (the half-space y <= 0): the lowest vertex.
  if (a.y <= b.y && a.y <= c.y) return {1, 0, 0};
  return b.y <= c.y ? Vec3(0, 1, 0) : Vec3(0, 0, 1);
}

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
    case ProxyShape::Box: return 0.5 * (std::min({g.half_extents.x, g.half_extents.y, g.half_extents.z}) + g.radius);
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
