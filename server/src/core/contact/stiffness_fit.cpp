#include "core/contact/stiffness_fit.hpp"

#include <algorithm>
#include <cmath>

#include <glm/geometric.hpp>
#include <glm/matrix.hpp>

namespace tactile {

namespace {

// Weight of the previous segments in a proxy's fit, per segment: about the
// last 10 count. A segment closes after an even number of steps once the
// proxy has moved kFitMinMotion from where it began, or after kFitMaxSteps.
constexpr double kFitMemory = 0.9;
constexpr double kFitMinMotion = 5e-6;  // [m]
constexpr int32_t kFitMaxSteps = 64;
// A coupled device's fit: segments of at least 2 ms and 20 um (or 50 ms),
// so that it gives the stiffness felt over the milliseconds a bridge
// renders between states (the hand's motion), not the coupling's spring
// alone that a device's encoder noise meets before the proxy can follow
// (free space would then read as the coupling's 2000 N/m).
constexpr double kDeviceFitMinTime = 2e-3, kDeviceFitMaxTime = 50e-3;  // [s]
constexpr double kDeviceFitMinMotion = 20e-6;                          // [m]
constexpr double kDeviceFitGain = 0.3;                                 // of each segment's secant, along its motion

}  // namespace

glm::dmat3 nearest_passive(const glm::dmat3& K, double stiffest) {
  glm::dmat3 A = 0.5 * (K + glm::transpose(K));
  glm::dmat3 V(1.0);  // columns: eigenvectors (cyclic Jacobi rotations)
  for (int sweep = 0; sweep < 12; ++sweep) {
    const double off = A[0][1] * A[0][1] + A[0][2] * A[0][2] + A[1][2] * A[1][2];
    const double diag = A[0][0] * A[0][0] + A[1][1] * A[1][1] + A[2][2] * A[2][2];
    if (off <= 1e-30 * diag || off == 0) break;
    for (int p = 0; p < 2; ++p)
      for (int q = p + 1; q < 3; ++q) {
        if (A[p][q] == 0) continue;
        const double theta = 0.5 * (A[q][q] - A[p][p]) / A[p][q];
        const double t = (theta >= 0 ? 1.0 : -1.0) / (std::fabs(theta) + std::sqrt(theta * theta + 1.0));
        const double c = 1.0 / std::sqrt(t * t + 1.0), sn = t * c;
        glm::dmat3 J(1.0);  // rotation in the (p, q) plane: A <- J^T A J
        J[p][p] = c;
        J[q][q] = c;
        J[q][p] = sn;   // column q, row p
        J[p][q] = -sn;  // column p, row q
        A = glm::transpose(J) * A * J;
        V = V * J;
      }
  }
  glm::dmat3 D(0.0);
  for (int k = 0; k < 3; ++k) D[k][k] = std::clamp(A[k][k], -stiffest, 0.0);
  return V * D * glm::transpose(V);
}

void fit_stiffness(StiffnessFit& f, FitWindow window, const Vec3& position, const Vec3& force, double dt,
                   glm::dmat3& stiffness) {
  if (f.seg_steps == 0) f.seg_start = position;
  f.seg_impulse += force * dt;
  f.seg_moment += position * dt;
  f.seg_time += dt;
  ++f.seg_steps;
  if (f.seg_steps % 2 != 0) return;
  const Vec3 moved = position - f.seg_start;
  const double moved2 = glm::dot(moved, moved);
  const bool device = window == FitWindow::Device;
  if (device ? f.seg_time < kDeviceFitMaxTime &&
                   (f.seg_time < kDeviceFitMinTime || moved2 < kDeviceFitMinMotion * kDeviceFitMinMotion)
             : moved2 < kFitMinMotion * kFitMinMotion && f.seg_steps < kFitMaxSteps)
    return;
  const Vec3 mean_force = f.seg_impulse / f.seg_time;
  const Vec3 mean_position = f.seg_moment / f.seg_time;
  f.seg_impulse = f.seg_moment = Vec3(0.0);
  f.seg_time = 0;
  f.seg_steps = 0;
  if (f.has_last) {
    const Vec3 dx = mean_position - f.last_position;
    const Vec3 dF = mean_force - f.last_force;
    const double dx2 = glm::dot(dx, dx);
    if (device) {
      // Along the motion alone (a damped Broyden update): a device moves
      // along a line for milliseconds, and across it only by its encoder's
      // noise, whose dF/dx is the coupling's spring before the proxy follows.
      if (dx2 >= kDeviceFitMinMotion * kDeviceFitMinMotion) {
        f.fx += kDeviceFitGain * glm::outerProduct(dF - f.fx * dx, dx) / dx2;
        stiffness = nearest_passive(f.fx);
      }
    } else if (dx2 > 0) {
      f.fx = kFitMemory * f.fx + glm::outerProduct(dF, dx);
      f.xx = kFitMemory * f.xx + glm::outerProduct(dx, dx);
      // K = S_fx (S_xx + eps I)^-1; eps keeps directions never moved along at
      // zero stiffness instead of dividing by nothing.
      const double eps = 1e-6 * (f.xx[0][0] + f.xx[1][1] + f.xx[2][2]) + 1e-300;
      stiffness = nearest_passive(f.fx * glm::inverse(f.xx + glm::dmat3(eps)));
    }
  }
  f.last_position = mean_position;
  f.last_force = mean_force;
  f.has_last = true;
}

}  // namespace tactile
