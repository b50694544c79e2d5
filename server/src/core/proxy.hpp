// Rigid proxies (paper section 3): the shapes a device moves into the soft
// body, their poses and their motion between two device inputs.
//
// Each shape is described in its own frame by a signed distance: negative
// inside, with the outward normal as its gradient. A pose maps the proxy
// frame to the world: x = position + orientation * p.
#pragma once

#include <cstdint>
#include <string>

#include <glm/gtc/quaternion.hpp>

#include "core/mesh.hpp"

namespace tactile {

using Quat = glm::dquat;

enum class ProxyShape : uint8_t { Sphere, Capsule, Box, Plane };
const char* to_string(ProxyShape s);

// A proxy's geometry in its own frame.
//   Sphere: centred at the origin, `radius`.
//   Capsule: the segment from (-half_length, 0, 0) to (half_length, 0, 0),
//            swept by `radius` (the paper's cylinder with round ends).
//   Box: centred, `half_extents`, edges rounded by `radius` (0: sharp).
//   Plane: the half-space y <= 0 of the proxy frame (a floor, a wall).
struct ProxyGeometry {
  ProxyShape shape = ProxyShape::Sphere;
  double radius = 0.01;      // [m]
  double half_length = 0.0;  // Capsule [m]
  Vec3 half_extents{0.01};   // Box [m]
};

// Signed distance of p (proxy frame) and the outward unit normal there.
struct SurfacePoint {
  double phi;  // [m], < 0 inside
  Vec3 n;      // outward unit normal (proxy frame)
};
SurfacePoint locate(const ProxyGeometry& g, const Vec3& p);

// The point of the triangle (a, b, c) (proxy frame) deepest in the shape,
// as barycentric weights (w.x on a, w.y on b, w.z on c; exact zeros on the
// triangle's edges and vertices). Exact for a sphere and a capsule (their
// signed distance is the distance to a point or a segment, less the radius);
// for a box, the point nearest its core box (exact where the triangle stays
// outside the core; a triangle reaching into the core is deeper than the
// rounding, and gets a point in it). For a plane, the lowest corner.
Vec3 deepest_on_triangle(const ProxyGeometry& g, const Vec3& a, const Vec3& b, const Vec3& c);

// How deep a point may sit inside before its nearest-surface normal can no
// longer be trusted to point back the way it came in (half the thinnest
// section) [m]; infinite for a plane.
double trust_depth(const ProxyGeometry& g);

// Bounding radius about the proxy origin [m]; infinite for a plane.
double bounding_radius(const ProxyGeometry& g);

struct Pose;
// World-space box around the shape at a pose; infinite for a plane.
Aabb world_bounds(const ProxyGeometry& g, const Pose& pose);

struct Pose {
  Vec3 position{0.0};
  Quat orientation{1.0, 0.0, 0.0, 0.0};  // (w, x, y, z)
  Vec3 to_world(const Vec3& p) const { return position + orientation * p; }
  Vec3 to_local(const Vec3& x) const { return glm::conjugate(orientation) * (x - position); }
};

// A proxy's motion over one interval between device inputs (or scripted
// keyframes): position linear and orientation along the shortest arc, from
// `from` at t0 to `to` at t1; held at the ends outside [t0, t1]. Velocity
// and angular velocity are the interval's constants.
struct ProxyMotion {
  double t0 = 0.0, t1 = 0.0;  // [s]
  Pose from, to;
  Pose at(double t) const;
  Vec3 velocity() const;          // [m/s]
  Vec3 angular_velocity() const;  // [rad/s], world frame
  // Velocity of the proxy's material point at world position x, time in (t0, t1).
  Vec3 velocity_at(const Vec3& x, double t) const;
};

// Holds still at one pose.
ProxyMotion hold(const Pose& p);

}  // namespace tactile
