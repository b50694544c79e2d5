// The local contact stiffness a proxy or a device feels, dF/dx of the
// contact's force against its position, from the forces of the latest steps:
// a secant fit over segments of motion, made passive (symmetric, negative
// semidefinite) before anything renders it. Contact (core/contact/contact.hpp)
// fits one per proxy and one per coupled device; the bridge renders it.
#pragma once

#include <cstdint>
#include <limits>

#include <glm/mat3x3.hpp>

#include "core/contact/contact_state.hpp"

namespace tactile {

// A proxy's fit ends after this many steps without contact (a proxy resting
// on the body is pushed only every other step or so, eq. (13)).
constexpr int32_t kFitIdleSteps = 16;

// The nearest symmetric negative semidefinite matrix to K (Frobenius norm):
// its symmetric part with every positive eigenvalue set to zero. A passive
// contact's dF/dx on the proxy is one (minus the Hessian of the body's
// energy in the proxy's position): the body pushes back harder as the proxy
// presses in, never pulls it further in, and stores what it is given.
// With `stiffest`, every eigenvalue is also held at or above -stiffest.
glm::dmat3 nearest_passive(const glm::dmat3& K, double stiffest = std::numeric_limits<double>::infinity());

// Which segments a fit closes. Proxy: once the proxy has moved a few
// micrometres (or after a few dozen steps), fitted in every direction it has
// moved along (least squares with memory). Device: segments of milliseconds
// and tens of micrometres, fitted along the motion alone, so that it gives
// the stiffness felt over the time a bridge renders between states, not the
// coupling's spring that a device's encoder noise meets first.
enum class FitWindow { Proxy, Device };

// Adds one step (the proxy or device at `position` under `force`, over dt)
// to the fit; where a segment closes with motion, sets `stiffness` to the
// fit, made passive.
void fit_stiffness(StiffnessFit& f, FitWindow window, const Vec3& position, const Vec3& force, double dt,
                   glm::dmat3& stiffness);

}  // namespace tactile
