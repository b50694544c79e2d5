#include "core/contact.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include <glm/geometric.hpp>
#include <glm/matrix.hpp>

namespace tactile {

namespace {

constexpr int32_t kClusterNodes = 32;
// Weight of the previous segments in the stiffness fit, per segment: about
// the last 10 count. A segment closes after an even number of steps once the
// proxy has moved kFitMinMotion from where it began, or after kFitMaxSteps.
constexpr double kFitMemory = 0.9;
constexpr double kFitMinMotion = 5e-6;  // [m]
constexpr int32_t kFitMaxSteps = 64;

bool boxes_meet(const Vec3& alo, const Vec3& ahi, const Vec3& blo, const Vec3& bhi) {
  return alo.x <= bhi.x && blo.x <= ahi.x && alo.y <= bhi.y && blo.y <= ahi.y && alo.z <= bhi.z && blo.z <= ahi.z;
}

}  // namespace

template <class Real>
Contact<Real>::Contact(const Model<Real>& model) : model_(model) {
  const size_t n_proxies = model.proxies.size();
  motion_.resize(n_proxies);
  for (size_t j = 0; j < n_proxies; ++j) motion_[j] = hold(model.proxies[j].pose);
  reports_.resize(n_proxies);
  device_reports_.resize(model.devices.size());
  hand_motion_.resize(model.hands.size());
  for (size_t h = 0; h < model.hands.size(); ++h) hand_motion_[h] = hold(model.hands[h].pose);
  fit_.resize(n_proxies);
  pose0_.resize(n_proxies);
  pose1_.resize(n_proxies);
  velocity_.resize(n_proxies);
  spin_.resize(n_proxies);
  lo_.resize(n_proxies);
  hi_.resize(n_proxies);
  alpha_ = model.effects.damping ? model.effects.alpha : 0.0;
  friction_ = model.effects.friction;
  if (n_proxies == 0) return;

  // Surface nodes that move freely, clustered in Morton order of rest positions.
  std::vector<int32_t> nodes = compute_boundary_nodes(model.surface);
  std::vector<int32_t> free;
  std::set_difference(nodes.begin(), nodes.end(), model.constrained.begin(), model.constrained.end(),
                      std::back_inserter(free));
  const Aabb box = compute_aabb(model.mesh.X);
  const Vec3 extent = glm::max(box.size(), Vec3(1e-30));
  std::vector<uint32_t> key(free.size());
  for (size_t k = 0; k < free.size(); ++k) key[k] = compute_morton_code((model.mesh.X[size_t(free[k])] - box.lo) / extent);
  std::vector<size_t> order(free.size());
  std::iota(order.begin(), order.end(), size_t(0));
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return key[a] < key[b]; });
  surface_.reserve(free.size());
  for (size_t k : order) surface_.push_back(free[k]);
  const auto n = static_cast<int32_t>(surface_.size());
  for (int32_t b = 0; b < n; b += kClusterNodes) clusters_.push_back({b, std::min(n, b + kClusterNodes), {}, {}});
  x_prev_.assign(surface_.size(), Vec3(0.0));
  x_now_.assign(surface_.size(), Vec3(0.0));
  f_prev_.assign(surface_.size(), Vec3(0.0));
  f_now_.assign(surface_.size(), Vec3(0.0));
  touched_prev_.reserve(surface_.size());
  touched_now_.reserve(surface_.size());
  memory_.assign(surface_.size(), Memory{});
}

template <class Real>
void Contact<Real>::set_hand_motion(int32_t hand, const ProxyMotion& m) {
  hand_motion_[size_t(hand)] = m;
  for (size_t j = 0; j < motion_.size(); ++j) {
    if (model_.proxy_hand[j] != hand) continue;
    const Pose& offset = model_.proxy_offset[j];
    ProxyMotion& pm = motion_[j];
    pm.t0 = m.t0;
    pm.t1 = m.t1;
    pm.from = {m.from.to_world(offset.position), m.from.orientation * offset.orientation};
    pm.to = {m.to.to_world(offset.position), m.to.orientation * offset.orientation};
  }
}

template <class Real>
void Contact<Real>::clear_impulses() {
  for (ProxyReport& r : reports_) r.clear_impulses();
  for (DeviceReport& d : device_reports_) d.clear_impulses();
}

template <class Real>
void Contact<Real>::start(const State<Real>& s) {
  for (size_t k = 0; k < surface_.size(); ++k) {
    const size_t i = size_t(surface_[k]);
    x_prev_[k] = model_.mesh.X[i] + Vec3(double(s.u[3 * i]), double(s.u[3 * i + 1]), double(s.u[3 * i + 2]));
  }
  std::fill(f_prev_.begin(), f_prev_.end(), Vec3(0.0));
  std::fill(f_now_.begin(), f_now_.end(), Vec3(0.0));
  touched_prev_.clear();
  touched_now_.clear();
  std::fill(memory_.begin(), memory_.end(), Memory{});
  for (Fit& f : fit_) f = Fit{};
  for (ProxyReport& r : reports_) r = ProxyReport{};
  for (DeviceReport& d : device_reports_) d = DeviceReport{};
}

template <class Real>
ContactSums Contact<Real>::apply(State<Real>& s, double t0, double t1, double dt) {
  ContactSums sums;
  const size_t n_proxies = motion_.size();
  if (n_proxies == 0) return sums;
  for (ProxyReport& r : reports_) {
    r.force = r.torque = Vec3(0.0);
    r.contacts = 0;
  }
  for (DeviceReport& d : device_reports_) {
    const DeviceReport kept = d;
    d = DeviceReport{};  // summed from its proxies below, but for the impulse sums
    d.impulse = kept.impulse;
    d.angular_impulse = kept.angular_impulse;
    d.elapsed = kept.elapsed;
  }

  // Positions at t_{n+1}, and boxes around each cluster's motion over the step.
  for (Cluster& c : clusters_) {
    Vec3 clo(std::numeric_limits<double>::infinity()), chi(-std::numeric_limits<double>::infinity());
    for (int32_t k = c.begin; k < c.end; ++k) {
      const size_t i = size_t(surface_[size_t(k)]);
      const Vec3 x = model_.mesh.X[i] + Vec3(double(s.u[3 * i]), double(s.u[3 * i + 1]), double(s.u[3 * i + 2]));
      x_now_[size_t(k)] = x;
      clo = glm::min(clo, glm::min(x, x_prev_[size_t(k)]));
      chi = glm::max(chi, glm::max(x, x_prev_[size_t(k)]));
    }
    c.lo = clo;
    c.hi = chi;
  }

  // Each proxy's poses and the box its bounding sphere sweeps over the step.
  for (size_t j = 0; j < n_proxies; ++j) {
    pose0_[j] = motion_[j].at(t0);
    pose1_[j] = motion_[j].at(t1);
    velocity_[j] = motion_[j].velocity();
    spin_[j] = motion_[j].angular_velocity();
    const Aabb b0 = world_bounds(model_.proxies[j].geometry, pose0_[j]);
    const Aabb b1 = world_bounds(model_.proxies[j].geometry, pose1_[j]);
    lo_[j] = glm::min(b0.lo, b1.lo);
    hi_[j] = glm::max(b0.hi, b1.hi);
  }
  for (const Cluster& c : clusters_)
    for (size_t j = 0; j < n_proxies; ++j) {
      if (!boxes_meet(c.lo, c.hi, lo_[j], hi_[j])) continue;
      for (int32_t k = c.begin; k < c.end; ++k) {
        // The node's own path over the step against the proxy's swept box.
        const Vec3& x = x_now_[size_t(k)];
        const Vec3& xp = x_prev_[size_t(k)];
        if (!boxes_meet(glm::min(x, xp), glm::max(x, xp), lo_[j], hi_[j])) {
          Memory& mem = memory_[size_t(k)];
          if (mem.proxy == int32_t(j)) mem.proxy = -1;
          continue;
        }
        contact_node(s, k, int32_t(j), pose0_[j], pose1_[j], dt, sums);
      }
    }

  // Work of the contact forces on the body (trapezoid, as for the loads) and
  // by each proxy; then this step's positions and forces become the previous.
  // Only the nodes pushed in this step or the one before carry a force.
  for (int32_t k : touched_now_)
    sums.work += 0.5 * glm::dot(f_prev_[size_t(k)] + f_now_[size_t(k)], x_now_[size_t(k)] - x_prev_[size_t(k)]);
  for (int32_t k : touched_prev_) {
    if (f_now_[size_t(k)] != Vec3(0.0)) continue;  // counted above
    sums.work += 0.5 * glm::dot(f_prev_[size_t(k)], x_now_[size_t(k)] - x_prev_[size_t(k)]);
  }
  for (int32_t k : touched_prev_) f_prev_[size_t(k)] = Vec3(0.0);
  for (int32_t k : touched_now_) {
    f_prev_[size_t(k)] = f_now_[size_t(k)];
    f_now_[size_t(k)] = Vec3(0.0);
  }
  touched_prev_.swap(touched_now_);
  touched_now_.clear();
  x_prev_.swap(x_now_);
  for (size_t j = 0; j < n_proxies; ++j) {
    if (reports_[j].contacts > 0) update_stiffness(int32_t(j), pose1_[j].position, reports_[j].force, dt);
    else {
      fit_[j] = Fit{};
      reports_[j].stiffness = glm::dmat3(0.0);
    }
  }
  // Per device: its proxies' sums, torques moved to the device's reference point.
  for (size_t j = 0; j < n_proxies; ++j) {
    ProxyReport& r = reports_[j];
    r.add_step(dt);
    DeviceReport& d = device_reports_[size_t(model_.proxy_device[j])];
    const int32_t hand = model_.proxy_hand[j];
    const Vec3 reference = hand >= 0 ? hand_motion_[size_t(hand)].at(t1).position : pose1_[j].position;
    d.force += r.force;
    d.torque += r.torque + glm::cross(pose1_[j].position - reference, r.force);
    d.contacts += r.contacts;
    d.stiffness += r.stiffness;
  }
  for (DeviceReport& d : device_reports_) d.add_step(dt);
  return sums;
}

template <class Real>
void Contact<Real>::contact_node(State<Real>& s, int32_t k, int32_t proxy, const Pose& p0, const Pose& p1, double dt,
                                 ContactSums& sums) {
  const ProxySpec& spec = model_.proxies[size_t(proxy)];
  const ProxyGeometry& g = spec.geometry;
  const size_t i = size_t(surface_[size_t(k)]);
  Memory& mem = memory_[size_t(k)];
  const Vec3 x1 = x_now_[size_t(k)];
  const Vec3 q1 = p1.to_local(x1);
  const SurfacePoint at1 = locate(g, q1);
  if (at1.phi > 0) {
    if (mem.proxy == proxy) mem.proxy = -1;
    return;
  }
  // Inside at t_{n+1}: which way is out?
  const Vec3 q0 = p0.to_local(x_prev_[size_t(k)]);
  const SurfacePoint at0 = locate(g, q0);
  Vec3 n_local;
  if (at0.phi > 0) {
    // Crossed the surface during the step: the normal where it crossed.
    double a = 0.0, b = 1.0;
    for (int it = 0; it < 20; ++it) {
      const double m = 0.5 * (a + b);
      (locate(g, q0 + m * (q1 - q0)).phi > 0 ? a : b) = m;
    }
    n_local = locate(g, q0 + b * (q1 - q0)).n;
  } else if (mem.proxy == proxy && -at1.phi > trust_depth(g)) {
    n_local = mem.normal;  // too deep to trust the nearest surface: the way it came in
  } else {
    n_local = at1.n;
  }
  mem.proxy = proxy;
  mem.normal = n_local;
  ++reports_[size_t(proxy)].contacts;

  const Vec3 n = p1.orientation * n_local;
  const Vec3 vp = velocity_[size_t(proxy)] + glm::cross(spin_[size_t(proxy)], x1 - p1.position);
  const Vec3 v(double(s.v[3 * i]), double(s.v[3 * i + 1]), double(s.v[3 * i + 2]));
  const Vec3 rel = v - vp;
  const double vn = glm::dot(rel, n);
  if (vn >= 0) return;  // leaving, or sliding along: no impulse
  Vec3 dv = -vn * n;    // eq. (11): the normal relative velocity drops to zero
  if (friction_ && spec.friction > 0) {
    const Vec3 vt = rel - vn * n;
    const double speed = glm::length(vt);
    const double limit = spec.friction * -vn;  // mu times the normal impulse, per unit mass
    if (speed <= limit) dv -= vt;                          // stick
    else if (speed > 0) dv -= vt * (limit / speed);        // slide
  }
  // eq. (9): v_{n+1} = v_half + dt/2 a_{n+1}, so a moves by 2 dv / dt; by
  // eq. (10) that is the force q 2 dv / dt, q = m (1 + alpha dt / 2).
  const double m = double(model_.m[i]);
  const Vec3 fc = (m * (1.0 + 0.5 * alpha_ * dt) * 2.0 / dt) * dv;
  const Vec3 a(double(s.a[3 * i]), double(s.a[3 * i + 1]), double(s.a[3 * i + 2]));
  const Vec3 v_new = v + dv, a_new = a + (2.0 / dt) * dv;
  for (int c = 0; c < 3; ++c) {
    s.v[3 * i + size_t(c)] = Real(v_new[c]);
    s.a[3 * i + size_t(c)] = Real(a_new[c]);
  }
  sums.mv2_delta += m * (glm::dot(v_new, v_new) - glm::dot(v, v));
  sums.ma2_delta += m * (glm::dot(a_new, a_new) - glm::dot(a, a));
  if (f_now_[size_t(k)] == Vec3(0.0)) touched_now_.push_back(k);  // (reserved: never allocates)
  f_now_[size_t(k)] += fc;
  ProxyReport& r = reports_[size_t(proxy)];
  r.force -= fc;
  r.torque -= glm::cross(x1 - p1.position, fc);
  const double w = glm::dot(fc, vp) * dt;
  r.work += w;
  sums.proxy_work += std::fabs(w);
}

template <class Real>
void Contact<Real>::update_stiffness(int32_t proxy, const Vec3& position, const Vec3& force, double dt) {
  Fit& f = fit_[size_t(proxy)];
  ProxyReport& r = reports_[size_t(proxy)];
  if (f.seg_steps == 0) f.seg_start = position;
  f.seg_impulse += force * dt;
  f.seg_moment += position * dt;
  f.seg_time += dt;
  ++f.seg_steps;
  const Vec3 moved = position - f.seg_start;
  if (f.seg_steps % 2 != 0 || (glm::dot(moved, moved) < kFitMinMotion * kFitMinMotion && f.seg_steps < kFitMaxSteps))
    return;
  const Vec3 mean_force = f.seg_impulse / f.seg_time;
  const Vec3 mean_position = f.seg_moment / f.seg_time;
  f.seg_impulse = f.seg_moment = Vec3(0.0);
  f.seg_time = 0;
  f.seg_steps = 0;
  if (f.has_last) {
    const Vec3 dx = mean_position - f.last_position;
    if (glm::dot(dx, dx) > 0) {
      const Vec3 dF = mean_force - f.last_force;
      f.fx = kFitMemory * f.fx + glm::outerProduct(dF, dx);
      f.xx = kFitMemory * f.xx + glm::outerProduct(dx, dx);
      // K = S_fx (S_xx + eps I)^-1; eps keeps directions never moved along at
      // zero stiffness instead of dividing by nothing.
      const double eps = 1e-6 * (f.xx[0][0] + f.xx[1][1] + f.xx[2][2]) + 1e-300;
      r.stiffness = f.fx * glm::inverse(f.xx + glm::dmat3(eps));
    }
  }
  f.last_position = mean_position;
  f.last_force = mean_force;
  f.has_last = true;
}

template class Contact<float>;
template class Contact<double>;

}  // namespace tactile
