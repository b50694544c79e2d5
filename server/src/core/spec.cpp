#include "core/spec.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <glm/geometric.hpp>

namespace tactile {

ProfileValue compute_profile(const MotionProfile& p, double t) {
  const double tau = t - p.start;
  if (tau <= 0.0) return {0.0, 0.0, 0.0};
  if (p.kind == MotionProfile::Kind::ConstantRate) {
    // The rate eases in over `duration` (cycloidal: zero acceleration at both
    // ends), s' = rate (x - sin(2 pi x) / (2 pi)), x = tau / T, and s is its
    // integral: a spin that started at full rate would be a velocity jump, an
    // impulse no step size resolves.
    const double T = p.duration;
    if (T <= 0.0) return {p.rate * tau, p.rate, 0.0};
    if (tau >= T) return {p.rate * (tau - 0.5 * T), p.rate, 0.0};
    const double x = tau / T, w = 2.0 * std::numbers::pi;
    return {p.rate * T * (0.5 * x * x + (std::cos(w * x) - 1.0) / (w * w)), p.rate * (x - std::sin(w * x) / w),
            p.rate / T * (1.0 - std::cos(w * x))};
  }
  if (p.duration <= 0.0 || tau >= p.duration) return {p.target, 0.0, 0.0};
  // Cycloidal ramp s = target (tau/T - sin(w tau)/(2 pi)), w = 2 pi / T: zero
  // velocity and acceleration at both ends, so a prescribed motion starts and
  // stops without a jump in acceleration (which would inject energy that the
  // explicit step cannot account for).
  const double T = p.duration;
  const double w = 2.0 * std::numbers::pi / T;
  return {p.target * (tau / T - std::sin(w * tau) / (2.0 * std::numbers::pi)), p.target / T * (1.0 - std::cos(w * tau)),
          p.target / T * w * std::sin(w * tau)};
}

std::vector<int32_t> select_nodes(const TetMesh& mesh, const NodeSelector& s) {
  std::vector<int32_t> out;
  const int32_t first = std::clamp(s.first, 0, mesh.n_nodes());
  const int32_t end = s.count < 0 ? mesh.n_nodes() : std::min(mesh.n_nodes(), first + s.count);
  switch (s.kind) {
    case NodeSelector::Kind::Box:
      for (int32_t i = first; i < end; ++i) {
        const Vec3& p = mesh.X[static_cast<size_t>(i)];
        if (p.x >= s.lo.x - s.tolerance && p.x <= s.hi.x + s.tolerance && p.y >= s.lo.y - s.tolerance &&
            p.y <= s.hi.y + s.tolerance && p.z >= s.lo.z - s.tolerance && p.z <= s.hi.z + s.tolerance)
          out.push_back(i);
      }
      break;
    case NodeSelector::Kind::Plane: {
      const double len = glm::length(s.normal);
      if (!(len > 0.0)) break;
      const Vec3 n = s.normal / len;
      for (int32_t i = first; i < end; ++i) {
        if (std::fabs(glm::dot(mesh.X[static_cast<size_t>(i)] - s.point, n)) <= s.tolerance) out.push_back(i);
      }
      break;
    }
    case NodeSelector::Kind::Nodes:
      for (int32_t i : s.nodes)
        if (i >= 0 && first + i < end) out.push_back(first + i);
      std::sort(out.begin(), out.end());
      out.erase(std::unique(out.begin(), out.end()), out.end());
      break;
  }
  return out;
}

}  // namespace tactile
