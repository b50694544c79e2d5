#include "core/coupling.hpp"

#include <algorithm>
#include <cmath>

#include <glm/geometric.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/matrix.hpp>

namespace tactile {

namespace {

// The smaller of two bounds, where 0 means "not given".
double lower_bound_of(double a, double b) {
  if (a > 0 && b > 0) return std::min(a, b);
  return a > 0 ? a : b;
}

// exp of a rotation vector: the unit quaternion turning by |r| about r.
Quat quat_of_rotation(const Vec3& r) {
  const double angle = glm::length(r);
  if (angle < 1e-300) return Quat(1.0, 0.0, 0.0, 0.0);
  const double s = std::sin(0.5 * angle) / angle;
  return Quat(std::cos(0.5 * angle), s * r.x, s * r.y, s * r.z);
}

// Scales v to at most `limit` in length; true if it did.
bool saturate(Vec3& v, double limit) {
  const double len = glm::length(v);
  if (!(len > limit)) return false;
  v *= limit / len;
  return true;
}

}  // namespace

Coupling resolve_coupling(const Coupling& scene, const DeviceLimits* device, double radius) {
  const DeviceLimits none;
  const DeviceLimits& dev = device ? *device : none;
  const double r = std::max(radius, 1e-6);
  Coupling c;
  c.stiffness = lower_bound_of(scene.stiffness, dev.stiffness);
  if (!(c.stiffness > 0)) c.stiffness = kDefaultCouplingStiffness;
  c.max_force = lower_bound_of(scene.max_force, dev.max_force);
  if (!(c.max_force > 0)) c.max_force = kDefaultCouplingForce;
  c.max_torque = lower_bound_of(scene.max_torque, dev.max_torque);
  if (!(c.max_torque > 0)) c.max_torque = c.max_force * r;
  c.angular_stiffness = scene.angular_stiffness > 0 ? scene.angular_stiffness : c.stiffness * r * r;
  c.mass = scene.mass > 0 ? scene.mass : kDefaultProxyMass;
  c.inertia = scene.inertia > 0 ? scene.inertia : 0.4 * c.mass * r * r;
  c.damping = scene.damping > 0 ? scene.damping : 2.0 * kCouplingDampingRatio * std::sqrt(c.stiffness * c.mass);
  c.angular_damping = scene.angular_damping > 0
                          ? scene.angular_damping
                          : 2.0 * kCouplingDampingRatio * std::sqrt(c.angular_stiffness * c.inertia);
  return c;
}

Coupling fit_to_step(Coupling c, double dt) {
  const double need = std::max({1.0, c.stiffness * dt * dt / c.mass, c.angular_stiffness * dt * dt / c.inertia});
  c.mass *= need;
  c.inertia *= need;
  return c;
}

Vec3 compute_rotation_vector(const Quat& a, const Quat& b) {
  Quat d = b * glm::conjugate(a);
  if (d.w < 0) d = -d;  // the shortest way
  const Vec3 axis(d.x, d.y, d.z);
  const double s = glm::length(axis);
  if (s < 1e-300) return Vec3(0.0);
  return (2.0 * std::atan2(s, d.w) / s) * axis;
}

CouplingWrench step_coupled_body(const Coupling& c, const BodyState& now, const Pose& target, const Vec3& target_v,
                                 const Vec3& target_w, double dt, BodyState& next) {
  CouplingWrench out;
  // Eq. (7): the prediction.
  next.pose.position = now.pose.position + dt * now.v + (0.5 * dt * dt) * now.a;
  const Vec3 v_half = now.v + (0.5 * dt) * now.a;
  // Eq. (9) with the coupling's damping implicit:
  // v1 = v_half + dt/(2m) (k (x_t - x1) + b (v_t - v1)).
  const double h = 0.5 * dt / c.mass;
  const Vec3 spring = c.stiffness * (target.position - next.pose.position);
  next.v = (v_half + h * (spring + c.damping * target_v)) / (1.0 + h * c.damping);
  out.force = spring + c.damping * (target_v - next.v);
  if (saturate(out.force, c.max_force)) {
    out.saturated = true;
    next.v = v_half + h * out.force;
  }
  next.a = out.force / c.mass;

  // The same for the rotation.
  next.pose.orientation =
      glm::normalize(quat_of_rotation(dt * now.w + (0.5 * dt * dt) * now.alpha) * now.pose.orientation);
  const Vec3 w_half = now.w + (0.5 * dt) * now.alpha;
  const double hr = 0.5 * dt / c.inertia;
  const Vec3 twist = c.angular_stiffness * compute_rotation_vector(next.pose.orientation, target.orientation);
  next.w = (w_half + hr * (twist + c.angular_damping * target_w)) / (1.0 + hr * c.angular_damping);
  out.torque = twist + c.angular_damping * (target_w - next.w);
  if (saturate(out.torque, c.max_torque)) {
    out.saturated = true;
    next.w = w_half + hr * out.torque;
  }
  next.alpha = out.torque / c.inertia;
  return out;
}

}  // namespace tactile
