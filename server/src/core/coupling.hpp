// The virtual coupling between a device and the proxy it drives (docs/design.md,
// item 8; Colgate, Stanley & Brown 1995; the god-object of Zilles &
// Salisbury, ref. 37 of the paper). A device-driven proxy, or a hand of them,
// is a rigid body of the simulation with a mass and an inertia. The device's
// pose pulls it through a spring-damper whose force and torque saturate at
// what the device can render; the body stops it through the paper's contact
// (core/contact/contact.hpp), which now changes the proxy's velocity as well as the
// nodes': the impulse J on a node is -J on the proxy, so momentum passes
// between them and none is made. The hand feels the coupling's force, never
// the body's stiffness at whatever depth the device has reached: a device
// pushed through a stiff body feels at most its own limit, and the body
// receives no more.
//
// The body is integrated as the nodes are, by explicit Newmark (eqs. 7-9):
// predict x and v_half with the previous acceleration, then the acceleration
// from the coupling at t_{n+1}, then v_{n+1} = v_half + dt/2 a_{n+1}; the
// contact's velocity change dv raises a by 2 dv / dt as it does a node's, so
// the proxy's next prediction carries the push it felt and it does not creep
// into the body. The coupling's damping is taken implicitly (v_{n+1} on both
// sides), so the damper is stable at any step; the spring is explicit, and
// set_coupling raises the mass where the spring would be too stiff for the
// step (omega dt <= 1).
//
// Rotation: the same with a scalar (isotropic) inertia about the body's
// origin, the spring acting on the rotation vector from the body's
// orientation to the device's.
#pragma once

#include <cstdint>

#include <glm/mat3x3.hpp>

#include "core/proxy.hpp"

namespace tactile {

// What a device says it renders (its Hello): 0 for a field it does not give.
// A device that renders no torque (a 3-DoF arm) gives max_torque 0; its
// body still turns with it, through the scene's (or the default) soft
// angular coupling.
struct DeviceLimits {
  double max_force = 0;   // [N]
  double max_torque = 0;  // [N m]
  double stiffness = 0;   // the stiffest spring it renders stably [N/m]
};

// A coupling: as a scene asks it of a proxy or hand (ProxySpec::coupling,
// HandSpec::coupling), where 0 leaves a field to the device (its Hello) or,
// where the device says nothing, to the defaults of resolve_coupling (its
// stiffness, force and torque are upper bounds on what the device asks for:
// a scene may lower them, never raise them); and as the body runs it, the
// one resolve_coupling returns, every field set.
struct Coupling {
  double stiffness = 0;          // [N/m]
  double damping = 0;            // [N s/m]
  double max_force = 0;          // [N]
  double angular_stiffness = 0;  // [N m/rad]
  double angular_damping = 0;    // [N m s/rad]
  double max_torque = 0;         // [N m]
  double mass = 0;               // [kg]
  double inertia = 0;            // [kg m^2]
};

// Defaults where neither scene nor device says: a soft coupling (a mouse,
// which renders no force, drives its proxy through it), a light body, and
// damping at 0.7 of critical for the body on its spring.
inline constexpr double kDefaultCouplingStiffness = 300;  // [N/m]
inline constexpr double kDefaultCouplingForce = 5;        // [N]
inline constexpr double kDefaultProxyMass = 0.01;         // [kg]
inline constexpr double kCouplingDampingRatio = 0.7;

// The coupling of a body of bounding radius `radius` [m] (about its origin)
// from the scene's spec and the device's limits (nullptr: none given): each
// bound the smaller of the two where both give it. The angular spring, when
// unset, is the linear one at the body's radius (k r^2, saturating at
// max_force r); inertia, when unset, a solid ball's 2/5 m r^2. Pure.
Coupling resolve_coupling(const Coupling& scene, const DeviceLimits* device, double radius);

// Raises c.mass and c.inertia where the explicit spring would not resolve
// the step dt (omega dt <= 1), keeping their ratio. Pure.
Coupling fit_to_step(Coupling c, double dt);

// A coupled body's motion: pose at t_n, Newmark velocity and acceleration.
struct BodyState {
  Pose pose;
  Vec3 v{0.0}, a{0.0};      // [m/s], [m/s^2]
  Vec3 w{0.0}, alpha{0.0};  // angular [rad/s], [rad/s^2] (world frame)
};

// The prediction of eq. (7) for the body over dt, and the coupling's force
// and torque at t_{n+1} toward the device's pose `target` moving at
// (target_v, target_w): writes the predicted pose, v_{n+1} and w_{n+1}
// (before contact) and a_{n+1}, alpha_{n+1} into `next`, and returns the
// force and torque on the body [N], [N m], saturated at the coupling's limits.
struct CouplingWrench {
  Vec3 force{0.0}, torque{0.0};
  bool saturated = false;
};
CouplingWrench step_coupled_body(const Coupling& c, const BodyState& now, const Pose& target, const Vec3& target_v,
                                 const Vec3& target_w, double dt, BodyState& next);

// The rotation vector (axis times angle, the shortest way) that turns a into b, world frame.
Vec3 compute_rotation_vector(const Quat& a, const Quat& b);

}  // namespace tactile
