// The energy guard's account: the balance of kinetic, elastic and gravity
// energy against the work of loads, essential BCs and contact and the energy
// damping removed (struct Energy, core/state.hpp), closed after every step
// from sums the passes compute anyway, and checked against the reference
// taken when the account opened. A step that makes energy beyond the work
// done, or runs away past the critical step, is a fault (core/stepper.hpp).
// The ledger is plain data in the State (EnergyLedger): a copied state checks
// its steps as the original would.
#pragma once

#include "core/model.hpp"
#include "core/state.hpp"

namespace tactile {

// What a step's passes summed at t_{n+1}, after the essential BCs and
// contact changed the nodes they hold and push.
struct StepEnergySums {
  double elastic = 0;  // sum V psi(F) [J]
  double mv2 = 0;      // sum m |v|^2 [J]
  double ma2 = 0;      // sum m |a|^2
  double mgu = 0;      // sum m g.u [J]
};

// How a closed step's balance compares with the reference.
struct EnergyCheck {
  enum class Verdict { Ok, Growth, Runaway };
  // Past the critical step the balance stays conserved while the motion
  // grows without bound (kinetic + discrete falls as fast as kinetic +
  // elastic rises), so the physical energy is checked too, against all the
  // energy the body was given. Below the critical step it exceeds that by
  // at most -discrete <= U (w dt)^2/4 / (1 - (w dt)^2/4), 4.3x at 0.9 of it.
  static constexpr double kRunaway = 10;
  Verdict verdict = Verdict::Ok;
  double growth = 0;   // of the balance since the reference [J]
  double allowed = 0;  // the tolerance it was checked against [J]
  double given = 0;    // all the energy the body was given [J]
};

// The elastic energy's round-off in Real, the balance's resolution [J]: a
// sum of densities that cancel to nearly nothing at small strain (psi =
// mu/2 (I1 - 3) - ..., I1 ~ 3), each carrying a few eps (mu + lambda) V. In
// float that is far above the energy of a small deformation.
template <class Real>
double energy_floor(const Model<Real>& model);

// Opens the account at t_n from the state's energies e0 (a full pass) for a
// first step of dt; the discrete term from s.energy.initial_ma2.
template <class Real>
void open_energy_account(State<Real>& s, Energy e0, double dt);

// Before a step of dt: the modified energy's -dt^2/8 sum m|a|^2 restated
// with the new step when it changed.
template <class Real>
void restate_energy_account(State<Real>& s, double dt);

// After a step of dt: the energies at t_{n+1}, and the damping's dissipation
// (alpha: the mass-proportional damping, 0 without) over the step.
template <class Real>
void close_energy_account(State<Real>& s, const StepEnergySums& sums, double dt, double alpha);

// The guard's check of the closed step against the reference, with the
// scene's relative tolerance and the balance's resolution `floor`; a window
// of `window` seconds that passes the check becomes the next one's reference.
template <class Real>
EnergyCheck check_energy_account(State<Real>& s, double tolerance, double floor, double window);

}  // namespace tactile
