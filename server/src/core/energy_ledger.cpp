#include "core/energy_ledger.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace tactile {

template <class Real>
double energy_floor(const Model<Real>& model) {
  double stiffness_volume = 0;
  for (size_t e = 0; e < model.tet_volume.size(); ++e)
    stiffness_volume += (model.tet_mu[e] + model.tet_lambda[e]) * model.tet_volume[e];
  return 16.0 * double(std::numeric_limits<Real>::epsilon()) * stiffness_volume;
}

template <class Real>
void open_energy_account(State<Real>& s, Energy e0, double dt) {
  EnergyLedger& L = s.energy;
  e0.discrete = -0.125 * dt * dt * L.initial_ma2;
  L.reference = e0.balance();
  L.window_start = double(s.t);
  L.latest = e0;  // the kinetic energy at t_n for the dissipation trapezoid
  L.scale = std::fabs(e0.kinetic) + std::fabs(e0.elastic) + std::fabs(e0.gravity);
  L.proxy_given = 0;
  L.dt = dt;
  L.open = true;
}

template <class Real>
void restate_energy_account(State<Real>& s, double dt) {
  EnergyLedger& L = s.energy;
  if (dt != L.dt && L.dt > 0) {
    // The discrete term is measured with the step that follows: a new step
    // size restates it at t_n. That is no energy the body gained or lost:
    // the balance leaves the change out.
    const double restated = L.latest.discrete * (dt * dt) / (L.dt * L.dt);
    L.latest.restated += restated - L.latest.discrete;
    L.latest.discrete = restated;
  }
  L.dt = dt;
}

template <class Real>
void close_energy_account(State<Real>& s, const StepEnergySums& sums, double dt, double alpha) {
  Energy& e = s.energy.latest;
  const double mv2 = std::max(0.0, sums.mv2), ma2 = std::max(0.0, sums.ma2);
  // Power alpha m |v|^2 integrated by the trapezoid over the step: its error
  // telescopes (O(dt^2) in all), where the rectangle alpha m |v_{n+1}|^2 dt
  // drifted by alpha dt times the change of kinetic energy.
  if (alpha != 0) s.dissipated += alpha * dt * 0.5 * (2.0 * e.kinetic + mv2);
  e.kinetic = 0.5 * mv2;
  e.discrete = -0.125 * dt * dt * ma2;
  e.elastic = sums.elastic;
  e.gravity = -sums.mgu;
  e.work_loads = s.work_loads;
  e.work_essential = s.work_essential;
  e.work_contact = s.work_contact;
  e.dissipated = s.dissipated;
}

template <class Real>
EnergyCheck check_energy_account(State<Real>& s, double tolerance, double floor, double window) {
  EnergyLedger& L = s.energy;
  const Energy& e = L.latest;
  const double magnitude = std::fabs(e.kinetic) + std::fabs(e.elastic) + std::fabs(e.gravity) +
                           std::fabs(s.work_loads) + std::fabs(s.work_essential) + std::fabs(s.work_contact) +
                           s.dissipated;
  L.scale = std::max(L.scale, magnitude);
  EnergyCheck check;
  check.growth = e.balance() - L.reference;
  check.allowed = tolerance * L.scale + floor + 1e-12;
  check.given = std::fabs(L.reference) + std::fabs(e.gravity) + std::fabs(s.work_loads) + std::fabs(s.work_essential) +
                std::fabs(s.work_contact) + L.proxy_given + s.dissipated;
  if (check.growth - e.discrete - EnergyCheck::kRunaway * check.given > check.allowed) {
    check.verdict = EnergyCheck::Verdict::Runaway;
  } else if (check.growth > check.allowed) {
    check.verdict = EnergyCheck::Verdict::Growth;
  } else if (double(s.t) - L.window_start >= window) {
    L.reference = e.balance();  // the next window's growth counts from here
    L.window_start = double(s.t);
  }
  return check;
}

#define TACTILE_ENERGY_LEDGER(Real)                                                        \
  template double energy_floor(const Model<Real>&);                                        \
  template void open_energy_account(State<Real>&, Energy, double);                         \
  template void restate_energy_account(State<Real>&, double);                              \
  template void close_energy_account(State<Real>&, const StepEnergySums&, double, double); \
  template EnergyCheck check_energy_account(State<Real>&, double, double, double);
TACTILE_ENERGY_LEDGER(float)
TACTILE_ENERGY_LEDGER(double)
#undef TACTILE_ENERGY_LEDGER

}  // namespace tactile
