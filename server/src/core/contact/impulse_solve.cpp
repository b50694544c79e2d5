#include "core/contact/impulse_solve.hpp"

#include <algorithm>
#include <cmath>

#include <glm/geometric.hpp>

namespace tactile {

Vec3 proxy_velocity(const std::vector<CoupledBodyState>& bodies, const ContactPoint& c) {
  if (c.body < 0) return c.vp;
  const CoupledBodyState& b = bodies[size_t(c.body)];
  return b.next.v + glm::cross(b.next.w, c.r);
}

void ImpulseSolve::reserve(size_t slots, size_t groups, size_t points) {
  if (dv_.size() < slots) {
    dv_.resize(slots, Vec3(0.0));
    guess_.resize(slots, Vec3(0.0));
    moved_flag_.resize(slots, 0);
  }
  moved_.reserve(slots);
  if (group_begin_.size() < groups + 1) {
    group_begin_.resize(groups + 1, 0);
    group_fill_.resize(groups, 0);
  }
  order_.reserve(points);
}

void ImpulseSolve::clear() {
  for (int32_t k : moved_) {
    dv_[size_t(k)] = Vec3(0.0);
    moved_flag_[size_t(k)] = 0;
  }
  moved_.clear();
}

Vec3 ImpulseSolve::point_velocity(const ContactPoint& c, const std::vector<Vec3>& v) const {
  Vec3 u = c.v_held;
  for (size_t j = 0; j < kPointCarriers && c.slot[j] >= 0; ++j) {
    const auto k = size_t(c.slot[j]);
    u += c.w[j] * (v[k] + dv_[k]);
  }
  return u;
}

void ImpulseSolve::give(std::vector<CoupledBodyState>& bodies, const ContactPoint& c, const Vec3& J,
                        const std::vector<double>& mass) {
  for (size_t j = 0; j < kPointCarriers && c.slot[j] >= 0; ++j) {
    const auto k = size_t(c.slot[j]);
    if (!moved_flag_[k]) {
      moved_flag_[k] = 1;
      moved_.push_back(int32_t(k));  // (reserved: never allocates)
    }
    dv_[k] += (c.w[j] / mass[k]) * J;
  }
  if (c.body >= 0) {  // and the opposite to the proxy's body
    CoupledBodyState& b = bodies[size_t(c.body)];
    b.next.v -= J / b.c.mass;
    b.next.w -= glm::cross(c.r, J) / b.c.inertia;
  }
}

double ImpulseSolve::warm_scale(const std::vector<ContactPoint>& points, const std::vector<Vec3>& v,
                                const std::vector<double>& mass) {
  // Along the guess J, the objective is s J . b + s^2 J^T A J / 2, with b
  // each point's velocity less its vp and J^T A J = sum_k |sum w J|^2 / m_k.
  double jb = 0;
  for (const ContactPoint& c : points) {
    const Vec3 J = c.jn * c.n + c.jt;
    if (J == Vec3(0.0)) continue;
    jb += glm::dot(J, point_velocity(c, v) - c.vp);
    for (size_t j = 0; j < kPointCarriers && c.slot[j] >= 0; ++j) guess_[size_t(c.slot[j])] += c.w[j] * J;
  }
  double jaj = 0;
  for (const ContactPoint& c : points)
    for (size_t j = 0; j < kPointCarriers && c.slot[j] >= 0; ++j) {
      Vec3& g = guess_[size_t(c.slot[j])];
      jaj += glm::dot(g, g) / mass[size_t(c.slot[j])];
      g = Vec3(0.0);  // (each slot counted once)
    }
  return jaj > 0 ? std::clamp(-jb / jaj, 0.0, 1.0) : 0.0;
}

void ImpulseSolve::solve(std::vector<ContactPoint>& points, size_t n_proxies, std::vector<CoupledBodyState>& bodies,
                         const std::vector<Vec3>& v, const std::vector<double>& mass, double tolerance, double floor) {
  // A coupled body's points see its mass and inertia in series with their
  // nodes' (the effective inverse mass along a direction e: sum w^2/m + 1/M
  // + |r x e|^2 / I). They take more sweeps to settle than a kinematic
  // proxy's.
  constexpr int kMaxSweeps = 32, kMaxBodySweeps = 128;
  // The points in group order (stable: each group's in the order found).
  const auto group = [&](const ContactPoint& c) { return c.body >= 0 ? n_proxies + size_t(c.body) : size_t(c.proxy); };
  const size_t n_groups = n_proxies + bodies.size();
  reserve(dv_.size(), n_groups, points.size());
  std::fill(group_begin_.begin(), group_begin_.begin() + ptrdiff_t(n_groups + 1), 0);
  for (const ContactPoint& c : points) ++group_begin_[group(c) + 1];
  for (size_t g = 0; g < n_groups; ++g) group_begin_[g + 1] += group_begin_[g];
  order_.resize(points.size());
  std::copy(group_begin_.begin(), group_begin_.begin() + ptrdiff_t(n_groups), group_fill_.begin());
  for (size_t m = 0; m < points.size(); ++m) order_[size_t(group_fill_[group(points[m])]++)] = int32_t(m);
  settled_ = true;
  for (size_t g = 0; g < n_groups; ++g) {
    if (group_begin_[g] == group_begin_[g + 1]) continue;
    const CoupledBodyState* body = g >= n_proxies ? &bodies[g - n_proxies] : nullptr;
    const auto inv_mass = [&](const ContactPoint& c, const Vec3& e) {
      if (!body) return c.inv_mass;
      const Vec3 re = glm::cross(c.r, e);
      return c.inv_mass + 1.0 / body->c.mass + glm::dot(re, re) / body->c.inertia;
    };
    // A warm start's guess, given first; the sweeps' scale is then the
    // largest approach before it (what a cold first sweep would take out).
    double first = 0;
    for (int32_t m = group_begin_[g]; m < group_begin_[g + 1]; ++m) {
      const ContactPoint& c = points[size_t(order_[size_t(m)])];
      if (c.jn == 0 && c.jt == Vec3(0.0)) continue;
      first = std::max(first, -glm::dot(point_velocity(c, v) - proxy_velocity(bodies, c), c.n));
    }
    for (int32_t m = group_begin_[g]; m < group_begin_[g + 1]; ++m) {
      const ContactPoint& c = points[size_t(order_[size_t(m)])];
      if (c.jn != 0 || c.jt != Vec3(0.0)) give(bodies, c, c.jn * c.n + c.jt, mass);
    }
    bool stopped = false;
    for (int sweep = 0; sweep < (body ? kMaxBodySweeps : kMaxSweeps) && !stopped; ++sweep) {
      double largest = 0;
      for (int32_t m = group_begin_[g]; m < group_begin_[g + 1]; ++m) {
        ContactPoint& c = points[size_t(order_[size_t(m)])];
        const Vec3 rel = point_velocity(c, v) - proxy_velocity(bodies, c);
        const double vn = glm::dot(rel, c.n);
        const double kn = inv_mass(c, c.n);
        const double jn = std::max(0.0, c.jn - vn / kn);
        const double djn = jn - c.jn;
        Vec3 J = djn * c.n;
        c.jn = jn;
        double change = std::fabs(djn) * kn;
        if (c.mu > 0) {
          const Vec3 vt = rel - vn * c.n;  // the normal impulse moves the point along n alone
          const double vt_len = glm::length(vt);
          const double kt = vt_len > 0 ? inv_mass(c, vt / vt_len) : c.inv_mass;
          Vec3 jt = c.jt - vt / kt;
          const double bound = c.mu * c.jn, len = glm::length(jt);
          if (len > bound) jt *= bound / len;
          J += jt - c.jt;
          change = std::max(change, glm::length(jt - c.jt) * kt);
          c.jt = jt;
        }
        if (J != Vec3(0.0)) give(bodies, c, J, mass);
        largest = std::max(largest, change);
      }
      if (sweep == 0) first = std::max(first, largest);
      stopped = largest <= std::max(tolerance * first, floor);
    }
    settled_ = settled_ && stopped;
  }
}

}  // namespace tactile
