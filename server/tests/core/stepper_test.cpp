#include "core/stepper.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <vector>

#include "core/fem_fixtures.hpp"

namespace tactile {
namespace {

using test::compute_momenta;
using test::kAllModels;
using test::kRotationInvariantModels;
using test::make_jittered_box;
using test::make_rotation;
using test::make_spec;
using test::node_vec;
using test::OneAfterTheOther;

// A cube of side 1 m on an irregular mesh; E = 1e5 Pa, rho = 1000 kg/m^3:
// the dilatational wave speed is 11.6 m/s.
TetMesh make_test_cube(int cells = 3) { return make_jittered_box(Vec3(0.0), Vec3(1.0), {cells, cells, cells}, 0.2); }

// Random velocities of up to `amplitude` m/s per component.
template <class Real>
void set_random_velocities(State<Real>& s, double amplitude, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  for (Real& v : s.v) v = Real(amplitude * unit(rng));
}

template <class Real>
bool all_finite(const std::vector<Real>& a) {
  return std::all_of(a.begin(), a.end(), [](Real x) { return std::isfinite(x); });
}

// Ids of the tets that have node i as a corner, sorted.
std::vector<int32_t> find_tets_around(const TetMesh& mesh, int32_t i) {
  std::vector<int32_t> out;
  for (int32_t e = 0; e < mesh.n_tets(); ++e)
    if (std::find(mesh.tets[size_t(e)].begin(), mesh.tets[size_t(e)].end(), i) != mesh.tets[size_t(e)].end())
      out.push_back(e);
  return out;
}

// ---- conservation ------------------------------------------------------------

// No external force: the elastic forces of each element sum to zero
// (translation invariance), so sum m v is conserved to round-off. Forces of
// rotation-invariant models also have no net torque (P F^T is symmetric),
// and the central-difference scheme then conserves sum m x cross v exactly;
// the linear model's forces have a torque of second order in u.
template <class Real>
void check_momentum_is_conserved(MaterialModel model_kind, double amplitude, double p_tol, double L_tol) {
  const Model<Real> model = build_model<Real>(make_spec(make_test_cube(), model_kind));
  Stepper<Real> stepper(model);
  State<Real> s = stepper.make_state();
  set_random_velocities(s, amplitude, 42);
  Vec3 p0, L0;
  compute_momenta(model, s, &p0, &L0);
  double scale_p = 0, scale_L = 0;  // sum m |v|, sum m |x| |v|
  for (int32_t i = 0; i < model.n_nodes; ++i) {
    scale_p += double(model.m[size_t(i)]) * glm::length(node_vec(s.v, i));
    scale_L += double(model.m[size_t(i)]) * glm::length(node_vec(s.v, i)) * glm::length(model.mesh.X[size_t(i)]);
  }
  const double dt = 0.5 * model.dt_rest;
  double max_u = 0;
  for (int n = 0; n < 400; ++n) {
    const Fault f = stepper.step(s, dt);
    ASSERT_FALSE(f) << f.message;
    for (Real u : s.u) max_u = std::max(max_u, double(std::fabs(u)));
  }
  EXPECT_GT(max_u, 0.05 * amplitude) << "the test should move the cube";
  Vec3 p, L;
  compute_momenta(model, s, &p, &L);
  EXPECT_LT(glm::length(p - p0), p_tol * scale_p) << to_string(model_kind);
  EXPECT_LT(glm::length(L - L0), L_tol * scale_L) << to_string(model_kind);
}

TEST(Stepper, LinearAndAngularMomentumAreConserved) {
  for (MaterialModel m : kRotationInvariantModels) {
    check_momentum_is_conserved<double>(m, 1.0, 1e-12, 1e-10);
    check_momentum_is_conserved<float>(m, 1.0, 1e-5, 1e-4);
  }
  // Linear strain: momentum exactly, angular momentum only while u and the
  // rotations stay small (the spinning-body test in physics_test.cpp shows why).
  check_momentum_is_conserved<double>(MaterialModel::Linear, 0.01, 1e-12, 1e-3);
  check_momentum_is_conserved<float>(MaterialModel::Linear, 0.01, 1e-5, 1e-3);
}

// Energy of the central-difference scheme (state.hpp: the balance, with the
// discrete term) for a run of fixed duration at step dt; returns the largest
// |balance - balance(0)| relative to the initial energy.
double run_energy_drift(MaterialModel kind, double dt_fraction, double duration, double* final_mech = nullptr) {
  const Model<double> model = build_model<double>(make_spec(make_test_cube(), kind));
  Stepper<double> stepper(model);
  State<double> s = stepper.make_state();
  set_random_velocities(s, 1.5, 5);
  const double E0 = stepper.compute_energy(s).balance();
  const double dt = dt_fraction * model.dt_rest;
  const int n = int(std::lround(duration / dt));
  double drift = 0;
  for (int k = 0; k < n; ++k) {
    const Fault f = stepper.step(s, dt);
    EXPECT_FALSE(f) << f.message;
    if (f) break;
    drift = std::max(drift, std::fabs(s.energy.latest.balance() - E0));
  }
  if (final_mech) *final_mech = s.energy.latest.kinetic + s.energy.latest.elastic;
  return drift / E0;
}

// For a linear system, 1/2 v_{n-1/2} M v_{n+1/2} + U(u_n) is exactly the
// conserved quantity of eqs. (7)-(9): the balance holds to round-off.
TEST(Stepper, LinearModelConservesTheDiscreteEnergyExactly) {
  for (double fraction : {0.3, 0.95}) {
    const double drift = run_energy_drift(MaterialModel::Linear, fraction, 0.3);
    EXPECT_LT(drift, 1e-11) << fraction;
  }
}

// Nonlinear models: the scheme is symplectic, so the energy error stays
// bounded and falls as dt^2 (halving dt divides the drift by about 4).
TEST(Stepper, EnergyDriftFallsWithTheStep) {
  for (MaterialModel m : kRotationInvariantModels) {
    const double d1 = run_energy_drift(m, 0.8, 0.3);
    const double d2 = run_energy_drift(m, 0.4, 0.3);
    const double d4 = run_energy_drift(m, 0.2, 0.3);
    std::printf("[ energy  ] %-12s drift / E0 at dt = 0.8, 0.4, 0.2 dt_rest: %.3e %.3e %.3e\n",
                std::string(to_string(m)).c_str(), d1, d2, d4);
    EXPECT_LT(d1, 1e-2) << to_string(m);
    EXPECT_LT(d2, 0.4 * d1) << to_string(m);
    EXPECT_LT(d4, 0.4 * d2) << to_string(m);
  }
}

// The conserved quantity's -dt^2/8 sum m|a|^2 is measured with the step that
// follows: when the step size changes (advance() re-plans an interval, the
// estimate moves) it is restated, and the balance of a linear body stays
// exact to round-off through any sequence of steps.
TEST(Stepper, ChangingTheStepKeepsTheBalanceExact) {
  const Model<double> model = build_model<double>(make_spec(make_test_cube(), MaterialModel::Linear, 1e5, 0.3, 1000));
  Stepper<double> stepper(model);
  State<double> s = stepper.make_state();
  set_random_velocities(s, 1.5, 7);
  const double E0 = stepper.compute_energy(s).balance();
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> fraction(0.2, 0.95);
  double drift = 0, restated = 0;
  for (int k = 0; k < 400; ++k) {
    ASSERT_FALSE(stepper.step(s, fraction(rng) * model.dt_rest)) << s.fault.message;
    drift = std::max(drift, std::fabs(s.energy.latest.balance() - E0));
    restated = std::max(restated, std::fabs(s.energy.latest.restated));
  }
  EXPECT_LT(drift / E0, 1e-11);
  EXPECT_GT(restated / E0, 1e-4) << "the steps changed, so the term was restated";
}

// The energies the step reports come from sums taken in the step; they match a full pass.
TEST(Stepper, ReportedEnergiesMatchAFullPass) {
  for (MaterialModel m : kAllModels) {
    ModelSpec spec = make_spec(make_test_cube(), m);
    spec.effects.gravity = true;
    const Model<double> model = build_model<double>(spec);
    Stepper<double> stepper(model);
    State<double> s = stepper.make_state();
    set_random_velocities(s, 1.0, 8);
    for (int k = 0; k < 50; ++k) ASSERT_FALSE(stepper.step(s, 0.5 * model.dt_rest));
    const Energy full = stepper.compute_energy(s);
    const Energy& fast = s.energy.latest;
    EXPECT_NEAR(fast.kinetic, full.kinetic, 1e-12 * full.kinetic);
    EXPECT_NEAR(fast.elastic, full.elastic, 1e-12 * full.elastic);
    EXPECT_NEAR(fast.gravity, full.gravity, 1e-12 * std::fabs(full.gravity) + 1e-15);
    EXPECT_GT(full.elastic, 0.0);
    EXPECT_NE(full.gravity, 0.0);
  }
}

// Rayleigh damping D = alpha M (eq. 10) only removes energy: kinetic plus
// elastic plus the discrete term falls step by step, and what it loses is
// booked as dissipated, to O(dt^2), so the balance still holds. Returns the
// largest |balance - balance(0)| relative to the initial energy.
double run_damped(MaterialModel m, double dt_fraction) {
  ModelSpec spec = make_spec(make_test_cube(), m);
  spec.effects.damping = true;
  spec.effects.alpha = 20.0;  // [1/s]
  const Model<double> model = build_model<double>(spec);
  Stepper<double> stepper(model);
  State<double> s = stepper.make_state();
  set_random_velocities(s, 1.0, 13);
  // The acceleration consistent with eq. (8) at t = 0 (no strain yet, only damping).
  for (size_t k = 0; k < s.v.size(); ++k) s.a[k] = -spec.effects.alpha * s.v[k];
  const double E0 = stepper.compute_energy(s).balance();
  const double dt = dt_fraction * model.dt_rest;
  double previous = E0, worst_rise = 0, worst_balance = 0;
  while (s.t < 0.5) {
    const Fault f = stepper.step(s, dt);
    EXPECT_FALSE(f) << to_string(m) << ": " << f.message;
    if (f) break;
    const Energy& e = s.energy.latest;
    const double mech = e.kinetic + e.discrete + e.elastic;
    worst_rise = std::max(worst_rise, mech - previous);
    worst_balance = std::max(worst_balance, std::fabs(e.balance() - E0));
    previous = mech;
  }
  EXPECT_LE(worst_rise, 1e-12 * E0) << to_string(m);
  EXPECT_LT(previous, 1e-3 * E0) << to_string(m);  // alpha t = 10: nearly all of it gone
  EXPECT_NEAR(s.dissipated, E0, 2e-2 * E0) << to_string(m);
  return worst_balance / E0;
}

TEST(Stepper, DampingDissipatesMonotonicallyAndIsAccounted) {
  for (MaterialModel m : kAllModels) {
    const double b1 = run_damped(m, 0.8), b2 = run_damped(m, 0.4);
    std::printf("[ damping ] %-12s |balance error| / E0 at dt = 0.8, 0.4 dt_rest: %.3e %.3e\n",
                std::string(to_string(m)).c_str(), b1, b2);
    EXPECT_LT(b1, 2e-2) << to_string(m);
    EXPECT_LT(b2, 0.35 * b1) << to_string(m);  // second order
  }
}

// Gravity is a potential and a natural load does work: after a damped
// settling under both, the balance holds and the supports carry the weight
// plus the load.
TEST(Stepper, GravityAndLoadsAreAccountedAndCarriedByTheSupports) {
  const double E = 1e6, rho = 1000, w = 0.3, L = 1.0;
  ModelSpec spec = make_spec(make_box(Vec3(0.0), Vec3(w, L, w), {2, 6, 2}), MaterialModel::StVK, E, 0.3, rho);
  // Damped at twice the first bending frequency (Euler-Bernoulli): critical for that mode.
  const double omega1 = 3.516 * std::sqrt(E * w * w / 12 / rho) / (L * L);
  spec.effects.gravity = true;
  spec.effects.damping = true;
  spec.effects.alpha = 2 * omega1;
  EssentialBc base;
  base.name = "base";
  base.where.kind = NodeSelector::Kind::Plane;
  base.where.point = Vec3(0.0);
  spec.essential = {base};
  NaturalLoad push;
  push.where.kind = NodeSelector::Kind::Plane;
  push.where.point = Vec3(0.0, L, 0.0);
  push.force = Vec3(30.0, -50.0, 0.0);  // [N]
  push.scale = MotionProfile{MotionProfile::Kind::Ramp, 0.0, 0.05, 1.0, 0.0};
  spec.loads = {push};
  const Model<double> model = build_model<double>(spec);
  Stepper<double> stepper(model);
  State<double> s = stepper.make_state();
  while (s.t < 40 / omega1) {
    const AdvanceReport r = stepper.advance(s, 0.01);
    ASSERT_FALSE(r.fault) << r.fault.message;
  }
  const Energy& e = s.energy.latest;
  EXPECT_LT(e.kinetic, 1e-10 * e.elastic);
  EXPECT_GT(s.work_loads, 0.0);
  EXPECT_LT(std::fabs(e.balance()), 1e-3 * (std::fabs(e.gravity) + s.work_loads)) << e.balance();
  // At rest every free node is in equilibrium, so the reactions balance weight and load.
  Vec3 reaction(0.0);
  for (size_t c = 0; c < model.constrained.size(); ++c)
    reaction += Vec3(s.reaction[3 * c], s.reaction[3 * c + 1], s.reaction[3 * c + 2]);
  const Vec3 expected = -(model.total_mass * spec.effects.g + push.force);
  EXPECT_LT(glm::length(reaction - expected), 1e-4 * glm::length(expected))
      << reaction.x << " " << reaction.y << " " << reaction.z;
}

// ---- critical step -----------------------------------------------------------

struct RunOutcome {
  int steps = 0;  // steps taken before a fault
  Fault fault;
  bool nonfinite_state_without_fault = false;
  double max_energy_ratio = 0;  // max (kinetic + elastic) / initial
};
template <class Real>
RunOutcome run_at(const Model<Real>& model, double dt, int n_steps, double amplitude = 0.05) {
  Stepper<Real> stepper(model);
  State<Real> s = stepper.make_state();
  set_random_velocities(s, amplitude, 21);
  const double E0 = stepper.compute_energy(s).kinetic;
  RunOutcome out;
  for (; out.steps < n_steps; ++out.steps) {
    out.fault = stepper.step(s, dt);
    if (out.fault) break;
    if (!all_finite(s.u) || !all_finite(s.v) || !all_finite(s.a)) out.nonfinite_state_without_fault = true;
    out.max_energy_ratio = std::max(out.max_energy_ratio, (s.energy.latest.kinetic + s.energy.latest.elastic) / E0);
  }
  return out;
}

// Below the critical step the physical energy of a linear system is bounded
// by the scheme's conserved energy: K + U <= E / (1 - (dt / dt_crit)^2).
double bound_at(double fraction) { return 1.0 / (1.0 - fraction * fraction); }

// Largest generalised eigenvalue of the assembled linear model (K u = w^2 M u)
// by power iteration on M^-1/2 K M^-1/2, with K u = -f(u) from the stepper
// (in the mesh's node numbering, as the masses m are taken here).
double compute_assembled_omega_max(const Model<double>& model) {
  const size_t n = 3 * size_t(model.n_nodes);
  std::vector<double> mass(size_t(model.n_nodes));
  for (size_t i = 0; i < mass.size(); ++i) mass[i] = model.m[size_t(model.node_model[i])];
  std::vector<double> x(n), z(n);
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  for (double& v : x) v = unit(rng);
  double lambda = 0;
  for (int it = 0; it < 3000; ++it) {
    for (size_t k = 0; k < n; ++k) z[k] = x[k] / std::sqrt(mass[k / 3]);
    const std::vector<double> f = test::compute_elastic_forces(model, z);
    double norm = 0, xy = 0, xx = 0;
    for (size_t k = 0; k < n; ++k) {
      const double y = -f[k] / std::sqrt(mass[k / 3]);
      xy += x[k] * y;
      xx += x[k] * x[k];
      norm += y * y;
      z[k] = y;
    }
    lambda = xy / xx;
    norm = std::sqrt(norm);
    for (size_t k = 0; k < n; ++k) x[k] = z[k] / norm;
  }
  return std::sqrt(lambda);
}

// Irons' theorem: the smallest element critical step bounds the assembled
// one. On a regular mesh the bound is within 1.5x of the true limit; on an
// irregular one it is looser (its smallest element has heavier neighbours).
TEST(CriticalStep, EstimateBoundsTheAssembledLimit) {
  for (bool jittered : {false, true}) {
    const TetMesh mesh = jittered ? make_test_cube() : make_box(Vec3(0.0), Vec3(1.0), {3, 3, 3});
    const Model<double> model = build_model<double>(make_spec(mesh, MaterialModel::Linear));
    // Power iteration approaches omega_max from below, so this limit could be high;
    // the runs at 0.98x (stable) and 1.02x (faults) below check it to 2 %.
    const double dt_true = 2.0 / compute_assembled_omega_max(model);
    std::printf("[ dt      ] %s mesh: assembled limit / estimate = %.3f\n", jittered ? "jittered" : "regular ",
                dt_true / model.dt_rest);
    EXPECT_GE(dt_true, model.dt_rest);
    if (!jittered) {
      EXPECT_LT(dt_true, 1.45 * model.dt_rest);
    }
    // And the limit is real: just under it the energy stays bounded, just over it the run faults.
    EXPECT_FALSE(run_at(model, 0.98 * dt_true, 5000).fault);
    EXPECT_TRUE(run_at(model, 1.02 * dt_true, 5000).fault);
  }
}

// Running at 0.9x is stable for good; at 1.5x and 3x the highest mode grows
// and a guard stops the run with a fault, never a silent NaN.
TEST(CriticalStep, RunningPastTheEstimateFaults) {
  const TetMesh mesh = make_box(Vec3(0.0), Vec3(1.0), {3, 3, 3});
  for (MaterialModel m : kAllModels) {
    const Model<double> model = build_model<double>(make_spec(mesh, m));
    const RunOutcome stable = run_at(model, 0.9 * model.dt_rest, 5000);
    EXPECT_FALSE(stable.fault) << to_string(m) << ": " << stable.fault.message;
    EXPECT_LT(stable.max_energy_ratio, bound_at(0.9 / 1.3)) << to_string(m);  // the limit is >= 1.3 dt_rest here
    EXPECT_FALSE(stable.nonfinite_state_without_fault);
    for (double factor : {1.5, 3.0}) {
      const RunOutcome blown = run_at(model, factor * model.dt_rest, 5000);
      EXPECT_TRUE(blown.fault.kind == Fault::Kind::EnergyGrowth || blown.fault.kind == Fault::Kind::NonFinite ||
                  (blown.fault.kind == Fault::Kind::Inverted && !can_invert(m)))
          << to_string(m) << " at " << factor << "x: " << to_string(blown.fault.kind);
      EXPECT_FALSE(blown.nonfinite_state_without_fault) << to_string(m) << " at " << factor << "x";
      EXPECT_LT(blown.steps, 200) << to_string(m) << " at " << factor << "x";
      std::printf("[ dt      ] %-12s %.1fx dt_rest: %s after %d steps\n", std::string(to_string(m)).c_str(), factor,
                  to_string(blown.fault.kind), blown.steps);
    }
  }
}

// In float the elastic energy of a small deformation is below the round-off of the densities it is summed
// from (psi cancels to ~0 at small strain): the guard must not take that noise for growth (a small motion
// runs), and still stops a step past the critical one.
TEST(CriticalStep, FloatSmallMotionRunsAndARunawayIsStillCaught) {
  const TetMesh mesh = make_box(Vec3(0.0), Vec3(1.0), {3, 3, 3});
  for (MaterialModel m : kAllModels) {
    ModelSpec spec = make_spec(mesh, m);
    spec.integrator.precision = Precision::Float;
    const Model<float> model = build_model<float>(spec);
    const RunOutcome small = run_at(model, 0.9 * model.dt_rest, 3000, 1e-5);
    EXPECT_FALSE(small.fault) << to_string(m) << ": " << small.fault.message;
    EXPECT_FALSE(small.nonfinite_state_without_fault);
    const RunOutcome blown = run_at(model, 3.0 * model.dt_rest, 5000, 1e-5);
    EXPECT_TRUE(blown.fault.kind == Fault::Kind::EnergyGrowth || blown.fault.kind == Fault::Kind::NonFinite ||
                (blown.fault.kind == Fault::Kind::Inverted && !can_invert(m)))
        << to_string(m) << ": " << to_string(blown.fault.kind);
    EXPECT_FALSE(blown.nonfinite_state_without_fault) << to_string(m);
    EXPECT_LT(blown.steps, 400) << to_string(m);
  }
}

// A single free tet is its own assembly: the estimate is the exact limit, so
// even 1 % over it grows without bound while 1 % under stays bounded.
TEST(CriticalStep, SingleTetLimitIsExact) {
  const Model<double> model = build_model<double>(make_spec(test::make_regular_tet(0.1), MaterialModel::Linear));
  const RunOutcome under = run_at(model, 0.99 * model.dt_rest, 20000);
  EXPECT_FALSE(under.fault) << under.fault.message;
  EXPECT_LT(under.max_energy_ratio, bound_at(0.99));
  const RunOutcome over = run_at(model, 1.01 * model.dt_rest, 20000);
  EXPECT_EQ(over.fault.kind, Fault::Kind::EnergyGrowth) << "max energy ratio " << over.max_energy_ratio;
  EXPECT_LT(over.steps, 200);
}

// The estimate follows the configuration: a stretched StVK body is stiffer
// (eqs. 5-6 stiffen as (3 s^2 - 1) / 2), a squashed element shorter.
TEST(CriticalStep, EstimateShrinksWhenStretchedOrSquashed) {
  const Model<double> model = build_model<double>(make_spec(make_test_cube(), MaterialModel::StVK));
  Stepper<double> stepper(model);
  State<double> s = stepper.make_state();
  EXPECT_DOUBLE_EQ(stepper.compute_critical_dt(s), model.dt_rest);
  s.u = test::make_affine_displacement<double>(model.mesh, glm::dmat3(1.5), Vec3(0.0));
  const double stretched = stepper.compute_critical_dt(s);
  EXPECT_NEAR(stretched, model.dt_rest / std::sqrt((3 * 2.25 - 1) / 2), 1e-9 * model.dt_rest);
  s.u = test::make_affine_displacement<double>(model.mesh, glm::dmat3(1.0, 0, 0, 0, 0.5, 0, 0, 0, 1.0), Vec3(0.0));
  EXPECT_LT(stepper.compute_critical_dt(s), 0.99 * model.dt_rest);
  // Rigid motion changes nothing.
  s.u = test::make_affine_displacement<double>(model.mesh, make_rotation(Vec3(1, 1, 0), 2.0), Vec3(3.0));
  EXPECT_NEAR(stepper.compute_critical_dt(s), model.dt_rest, 1e-9 * model.dt_rest);
}

// advance() covers a frame with sub-steps under the estimate; a fixed step
// over it is split (Subdivide) or refused (Refuse), never taken.
TEST(Advance, AutoStepStaysUnderTheCriticalStep) {
  ModelSpec spec = make_spec(make_test_cube(), MaterialModel::StVK);
  spec.integrator.safety = 0.8;
  const Model<double> model = build_model<double>(spec);
  Stepper<double> stepper(model);
  State<double> s = stepper.make_state();
  set_random_velocities(s, 0.5, 3);
  const double frame = 1.0 / 30;
  const AdvanceReport r = stepper.advance(s, frame);
  ASSERT_FALSE(r.fault) << r.fault.message;
  EXPECT_LE(r.dt, 0.8 * r.dt_critical * (1 + 1e-12));
  EXPECT_GT(r.dt, 0.8 * r.dt_critical * (r.substeps - 1.0) / r.substeps);  // no more sub-steps than needed
  EXPECT_NEAR(r.substeps * r.dt, frame, 1e-12);
  EXPECT_NEAR(s.t, frame, 1e-12);
  EXPECT_EQ(s.step, r.substeps);
  EXPECT_FALSE(r.subdivided);
}

TEST(Advance, FixedStepAboveTheEstimateIsSubdividedOrRefused) {
  ModelSpec spec = make_spec(make_test_cube(), MaterialModel::StVK);
  const double dt_rest = build_model<double>(spec).dt_rest;
  const double frame = 40 * dt_rest;
  {
    spec.integrator.dt = 0.5 * dt_rest;  // under: taken as is
    const Model<double> model = build_model<double>(spec);
    Stepper<double> stepper(model);
    State<double> s = stepper.make_state();
    const AdvanceReport r = stepper.advance(s, frame);
    EXPECT_FALSE(r.fault);
    EXPECT_FALSE(r.subdivided);
    EXPECT_EQ(r.substeps, 80);
    EXPECT_NEAR(r.dt, 0.5 * dt_rest, 1e-15);
  }
  spec.integrator.dt = 4 * dt_rest;
  {
    spec.integrator.unstable = UnstablePolicy::Subdivide;
    const Model<double> model = build_model<double>(spec);
    Stepper<double> stepper(model);
    State<double> s = stepper.make_state();
    set_random_velocities(s, 0.5, 3);
    const AdvanceReport r = stepper.advance(s, frame);
    EXPECT_FALSE(r.fault) << r.fault.message;
    EXPECT_TRUE(r.subdivided);
    EXPECT_LE(r.dt, spec.integrator.safety * r.dt_critical * (1 + 1e-12));
    EXPECT_NEAR(r.substeps * r.dt, frame, 1e-12);
  }
  {
    spec.integrator.unstable = UnstablePolicy::Refuse;
    const Model<double> model = build_model<double>(spec);
    Stepper<double> stepper(model);
    State<double> s = stepper.make_state();
    set_random_velocities(s, 0.5, 3);
    const State<double> before = s;
    const AdvanceReport r = stepper.advance(s, frame);
    EXPECT_EQ(r.fault.kind, Fault::Kind::StepTooLarge);
    EXPECT_NE(r.fault.message.find("integrator.dt"), std::string::npos) << r.fault.message;
    EXPECT_EQ(r.substeps, 0);
    EXPECT_EQ(s.u, before.u);
    EXPECT_EQ(s.v, before.v);
    EXPECT_EQ(s.step, 0);
  }
}

// ---- guards ------------------------------------------------------------------

TEST(Guards, NanVelocityFaultsNamingTheElementsAroundTheNode) {
  const Model<double> model =
      build_model<double>(make_spec(make_box(Vec3(0.0), Vec3(1.0), {3, 3, 3}), MaterialModel::NeoHookean));
  Stepper<double> stepper(model);
  State<double> s = stepper.make_state();
  set_random_velocities(s, 0.1, 4);
  for (int k = 0; k < 10; ++k) ASSERT_FALSE(stepper.step(s, 0.5 * model.dt_rest));
  const int32_t node = 1 + 4 * (1 + 4 * 2);  // grid node (1, 1, 2): interior
  s.v[3 * size_t(node) + 1] = NAN;
  const Fault f = stepper.step(s, 0.5 * model.dt_rest);
  ASSERT_EQ(f.kind, Fault::Kind::NonFinite) << f.message;
  std::vector<int32_t> named = f.elements;
  std::sort(named.begin(), named.end());
  EXPECT_EQ(named, find_tets_around(model.mesh, node));
  EXPECT_EQ(f.step, 11);
}

TEST(Guards, InvertedStvkElementFaultsNamingIt) {
  // Two tets sharing the face (1, 2, 3); node 4 is driven through that face
  // into tet 0, which inverts tet 1 only.
  TetMesh mesh;
  mesh.X = {Vec3(0, 0, -1), Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0.2, 0.2, 1)};
  mesh.tets = {{0, 1, 2, 3}, {4, 1, 3, 2}};
  for (Tet& t : mesh.tets)
    if (compute_tet_volume(mesh.X[size_t(t[0])], mesh.X[size_t(t[1])], mesh.X[size_t(t[2])], mesh.X[size_t(t[3])]) < 0)
      std::swap(t[1], t[2]);
  const Model<double> model = build_model<double>(make_spec(mesh, MaterialModel::StVK));
  Stepper<double> stepper(model);
  State<double> s = stepper.make_state();
  const auto node4 = size_t(model.node_model[4]);  // the state's numbering
  s.v[3 * node4 + 2] = -200.0;                     // [m/s], far past what the material can stop
  Fault f;
  for (int k = 0; k < 1000 && !f; ++k) f = stepper.step(s, 0.5 * model.dt_rest);
  ASSERT_EQ(f.kind, Fault::Kind::Inverted) << f.message;
  EXPECT_EQ(f.elements, std::vector<int32_t>{1});
  EXPECT_NE(f.message.find("ids 1"), std::string::npos) << f.message;
  EXPECT_LT(mesh.X[4].z + s.u[3 * node4 + 2], 0.0);  // node 4 went through the plane z = 0 of the shared face
}

TEST(Guards, EnergyGrowthNamesTheElementsWithMostStrainEnergy) {
  const Model<double> model = build_model<double>(make_spec(make_test_cube(), MaterialModel::Corotational));
  Stepper<double> stepper(model);
  State<double> s = stepper.make_state();
  set_random_velocities(s, 0.05, 2);
  Fault f;
  for (int k = 0; k < 2000 && !f; ++k) f = stepper.step(s, 3.0 * model.dt_rest);
  ASSERT_EQ(f.kind, Fault::Kind::EnergyGrowth) << f.message;
  ASSERT_FALSE(f.elements.empty());
  const std::vector<double> energy = stepper.compute_element_energy(s);
  double densest = 0;
  for (size_t e = 0; e < energy.size(); ++e) densest = std::max(densest, energy[e] / model.tet_volume[e]);
  const auto first = size_t(f.elements[0]);
  EXPECT_NEAR(energy[first] / model.tet_volume[first], densest, 1e-12 * densest);
  for (int32_t e : f.elements) EXPECT_TRUE(e >= 0 && e < model.n_tets);
  EXPECT_NE(f.message.find("energy grew"), std::string::npos);
}

TEST(Guards, FaultIsStickyUntilCleared) {
  const Model<double> model = build_model<double>(make_spec(make_test_cube(2), MaterialModel::StVK));
  Stepper<double> stepper(model);
  State<double> s = stepper.make_state();
  s.v[5] = NAN;
  const Fault first = stepper.step(s, 0.5 * model.dt_rest);
  ASSERT_EQ(first.kind, Fault::Kind::NonFinite);
  const State<double> after = s;
  for (int k = 0; k < 3; ++k) {
    const Fault again = stepper.step(s, 0.5 * model.dt_rest);
    EXPECT_EQ(again.kind, first.kind);
    EXPECT_EQ(again.step, first.step);
    EXPECT_EQ(again.elements, first.elements);
  }
  EXPECT_EQ(stepper.advance(s, 0.01).fault.kind, first.kind);
  EXPECT_EQ(s.step, after.step);  // nothing was stepped
  EXPECT_EQ(s.fault.kind, first.kind);
  // Cleared and reset, it runs again.
  stepper.clear_fault(s);
  s = stepper.make_state();
  EXPECT_FALSE(stepper.step(s, 0.5 * model.dt_rest));
  EXPECT_FALSE(s.fault);
  EXPECT_EQ(stepper.step(s, -1.0).kind, Fault::Kind::StepTooLarge);
}

// ---- essential boundary conditions -------------------------------------------

// The top of a column turned by a prescribed rotation (a Ramp of the angle):
// its nodes follow the rigid motion exactly, and the work the BC does on the
// body is what the body holds (kinetic + elastic), up to the scheme's
// O(dt^2) energy error.
double run_prescribed_rotation(double dt_fraction, bool check_kinematics) {
  ModelSpec spec =
      make_spec(make_jittered_box(Vec3(0.0), Vec3(0.2, 0.6, 0.2), {2, 6, 2}, 0.2), MaterialModel::NeoHookean);
  EssentialBc base;
  base.name = "base";
  base.where.kind = NodeSelector::Kind::Plane;
  base.where.point = Vec3(0.0);
  EssentialBc lid;
  lid.name = "lid";
  lid.where.kind = NodeSelector::Kind::Plane;
  lid.where.point = Vec3(0.0, 0.6, 0.0);
  lid.centre = Vec3(0.1, 0.6, 0.1);
  lid.axis = Vec3(0.3, 1.0, -0.2);  // skew, so the lid also tilts
  lid.angle = MotionProfile{MotionProfile::Kind::Ramp, 0.01, 0.2, std::numbers::pi / 2, 0.0};
  spec.essential = {base, lid};
  const Model<double> model = build_model<double>(spec);
  Stepper<double> stepper(model);
  State<double> s = stepper.make_state();
  const double dt = dt_fraction * model.dt_rest;
  const std::vector<int32_t>& lid_nodes = model.essential[1].nodes;
  EXPECT_EQ(lid_nodes.size(), 9u);
  double worst = 0, worst_balance = 0;
  while (s.t < 0.3) {
    const Fault f = stepper.step(s, dt);
    EXPECT_FALSE(f) << f.message;
    if (f) break;
    worst_balance = std::max(worst_balance, std::fabs(s.energy.latest.balance()));
    if (!check_kinematics) continue;
    const ProfileValue th = compute_profile(*lid.angle, s.t);
    const glm::dmat3 R = make_rotation(lid.axis, th.s);
    const Vec3 omega = th.ds * glm::normalize(lid.axis);
    for (int32_t i : lid_nodes) {
      const Vec3 X = model.mesh.X[size_t(i)];
      const Vec3 x = lid.centre + R * (X - lid.centre);
      worst = std::max(worst, glm::length(X + node_vec(s.u, i) - x));
      worst = std::max(worst, glm::length(node_vec(s.v, i) - glm::cross(omega, x - lid.centre)));
    }
    for (int32_t i : model.essential[0].nodes) worst = std::max(worst, glm::length(node_vec(s.u, i)));
  }
  EXPECT_LT(worst, 1e-12);
  const Energy& e = s.energy.latest;
  EXPECT_GT(s.work_essential, 0.1);  // [J]: the twist stores energy
  EXPECT_GT(e.elastic, 0.5 * s.work_essential);
  return worst_balance / s.work_essential;
}

TEST(EssentialBc, PrescribedRotationIsFollowedExactlyAndItsWorkBalances) {
  const double b1 = run_prescribed_rotation(0.8, true);
  const double b2 = run_prescribed_rotation(0.4, false);
  std::printf("[ bc work ] |balance| / work at dt = 0.8, 0.4 dt_rest: %.3e %.3e\n", b1, b2);
  EXPECT_LT(b1, 1e-2);
  EXPECT_LT(b2, 0.5 * b1);
}

// Two parts share the middle of their blocks in chunks (stepper.cpp,
// elastic_part): whichever thread claims which chunk, every element's forces
// are added once, and in the same order, bit for bit.
TEST(Stepper, PairedPartsGiveOneResultWhicheverThreadTakesTheMiddle) {
  ModelSpec spec = make_spec(make_box(Vec3(0.0), Vec3(0.4, 0.1, 0.1), {32, 8, 8}), MaterialModel::StVK);
  spec.integrator.threads = 2;
  const Model<double> model = build_model<double>(spec);
  ASSERT_EQ(model.parts.size(), 2u);
  using Order = OneAfterTheOther::Order;
  OneAfterTheOther forward(Order::Forward), backward(Order::Backward), turns(Order::InTurns);
  Stepper<double> one(model), left(model, &forward), right(model, &backward), both(model, &turns);
  EXPECT_EQ(one.parts(), 1);
  EXPECT_EQ(left.parts(), 2);
  State<double> a = one.make_state();
  set_random_velocities(a, 0.5, 7);
  State<double> b = a, c = a, d = a;
  const double dt = 0.5 * model.dt_rest;
  for (int k = 0; k < 40; ++k) {
    ASSERT_FALSE(one.step(a, dt));
    ASSERT_FALSE(left.step(b, dt));
    ASSERT_FALSE(right.step(c, dt));
    ASSERT_FALSE(both.step(d, dt));
  }
  double worst = 0, scale = 0;
  for (size_t j = 0; j < a.u.size(); ++j) {
    worst = std::max(worst, std::fabs(a.u[j] - b.u[j]));
    scale = std::max(scale, std::fabs(a.u[j]));
  }
  EXPECT_GT(scale, 1e-4);
  EXPECT_LE(worst, 1e-9 * scale);  // against one part, only the order of the force sums differs
  EXPECT_NEAR(b.energy.latest.elastic, a.energy.latest.elastic, 1e-9 * a.energy.latest.elastic);
  EXPECT_EQ(b.u, c.u);  // bit for bit
  EXPECT_EQ(b.u, d.u);
  EXPECT_EQ(b.v, d.v);
  EXPECT_EQ(b.energy.latest.elastic, c.energy.latest.elastic);
  EXPECT_EQ(b.energy.latest.elastic, d.energy.latest.elastic);
}

// With two parts each predicts its own nodes and sets its own essential
// positions inside the element pass; a part no thread has reached is
// predicted by the one that needs it. Run one after the other each way, a
// bar held at one end and twisted at the other (each end in another part)
// moves as with one part, its twisted end exactly as prescribed.
TEST(Stepper, PartsSetTheirEssentialPositionsWhicheverRunsFirst) {
  ModelSpec spec = make_spec(make_box(Vec3(0.0), Vec3(0.4, 0.1, 0.1), {32, 8, 8}), MaterialModel::StVK);
  spec.integrator.threads = 2;
  EssentialBc held, twisted;
  held.where.kind = twisted.where.kind = NodeSelector::Kind::Plane;
  held.where.normal = twisted.where.normal = Vec3(1.0, 0.0, 0.0);
  twisted.where.point = Vec3(0.4, 0.0, 0.0);
  twisted.centre = Vec3(0.4, 0.05, 0.05);
  twisted.axis = Vec3(1.0, 0.0, 0.0);
  spec.essential = {held, twisted};
  // Over 40 rest steps, 0.1 rad: the 60 half steps below turn it by ~0.09.
  twisted.angle = spec.essential[1].angle =
      MotionProfile{MotionProfile::Kind::Ramp, 0.0, 40 * build_model<double>(spec).dt_rest, 0.1, 0.0};
  const Model<double> model = build_model<double>(spec);
  ASSERT_EQ(model.parts.size(), 2u);
  // One set in each part's nodes.
  for (size_t k = 0; k < 2; ++k)
    for (int32_t i : model.essential[k].nodes)
      EXPECT_EQ(i >= model.parts[1].node_begin, k == 1) << "set " << k << " node " << i;
  using Order = OneAfterTheOther::Order;
  OneAfterTheOther forward(Order::Forward), backward(Order::Backward), turns(Order::InTurns);
  Stepper<double> one(model), left(model, &forward), right(model, &backward), both(model, &turns);
  State<double> a = one.make_state();
  State<double> b = a, c = a, d = a;
  const double dt = 0.5 * model.dt_rest;
  for (int k = 0; k < 60; ++k) {
    ASSERT_FALSE(one.step(a, dt));
    ASSERT_FALSE(left.step(b, dt));
    ASSERT_FALSE(right.step(c, dt));
    ASSERT_FALSE(both.step(d, dt));
  }
  double worst = 0, scale = 0, off_path = 0;
  for (size_t j = 0; j < a.u.size(); ++j) {
    worst = std::max(worst, std::fabs(a.u[j] - c.u[j]));
    scale = std::max(scale, std::fabs(a.u[j]));
  }
  // The twisted end where the twist puts it at the time reached.
  const double th = compute_profile(*twisted.angle, c.t).s;
  for (int32_t i : model.essential[1].nodes) {
    const Vec3 r = model.mesh.X[size_t(i)] - twisted.centre;
    const Vec3 want(r.x, r.y * std::cos(th) - r.z * std::sin(th), r.y * std::sin(th) + r.z * std::cos(th));
    off_path = std::max(off_path, glm::length(twisted.centre + want - model.mesh.X[size_t(i)] - node_vec(c.u, i)));
  }
  EXPECT_GT(th, 0.05);
  EXPECT_GT(scale, 1e-3);
  EXPECT_LE(worst, 1e-9 * scale);
  EXPECT_LE(off_path, 1e-12);
  EXPECT_EQ(b.u, c.u);  // bit for bit
  EXPECT_EQ(b.u, d.u);
  EXPECT_EQ(b.v, d.v);
  EXPECT_EQ(b.reaction, c.reaction);
}

// Without loads the parts correct their nodes inside the element pass, each
// once the force arrays that hold them are done, doing any still unclaimed
// itself; with loads, in a pass of their own after the loads are added. With
// 2, 3 and 4 parts (a part's nodes then also take forces from the next pair's
// blocks) run one after the other each way: one result whichever part runs
// first, and the same motion as one part.
TEST(Stepper, PartsCorrectAfterTheLoadsWhicheverRunsFirst) {
  for (int threads : {2, 3, 4})
    for (bool loaded : {false, true}) {
      ModelSpec spec = make_spec(make_box(Vec3(0.0), Vec3(0.4, 0.1, 0.1), {48, 8, 8}), MaterialModel::StVK);
      spec.integrator.threads = threads;
      EssentialBc held;
      held.where.kind = NodeSelector::Kind::Plane;
      held.where.normal = Vec3(1.0, 0.0, 0.0);
      spec.essential = {held};
      if (loaded) {
        NaturalLoad tip;
        tip.where.kind = NodeSelector::Kind::Plane;
        tip.where.point = Vec3(0.4, 0.0, 0.0);
        tip.where.normal = Vec3(1.0, 0.0, 0.0);
        tip.force = Vec3(0.0, -2.0, 1.0);  // [N]
        spec.loads = {tip};
      }
      const Model<double> model = build_model<double>(spec);
      ASSERT_EQ(model.parts.size(), size_t(threads));
      using Order = OneAfterTheOther::Order;
      OneAfterTheOther forward(Order::Forward), backward(Order::Backward);
      Stepper<double> one(model), left(model, &forward), right(model, &backward);
      State<double> a = one.make_state();
      set_random_velocities(a, 0.2, 3);
      State<double> b = a, c = a;
      const double dt = 0.5 * model.dt_rest;
      for (int k = 0; k < 60; ++k) {
        ASSERT_FALSE(one.step(a, dt));
        ASSERT_FALSE(left.step(b, dt));
        ASSERT_FALSE(right.step(c, dt));
      }
      double worst = 0, scale = 0;
      for (size_t j = 0; j < a.u.size(); ++j) {
        worst = std::max(worst, std::fabs(a.u[j] - b.u[j]));
        scale = std::max(scale, std::fabs(a.u[j]));
      }
      EXPECT_GT(scale, 1e-4) << threads << " parts, loaded " << loaded;
      EXPECT_LE(worst, 1e-9 * scale) << threads << " parts, loaded " << loaded;
      EXPECT_EQ(b.u, c.u) << threads << " parts, loaded " << loaded;
      EXPECT_EQ(b.v, c.v) << threads << " parts, loaded " << loaded;
      EXPECT_EQ(b.a, c.a) << threads << " parts, loaded " << loaded;
      EXPECT_NEAR(b.energy.latest.kinetic, a.energy.latest.kinetic, 1e-9 * a.energy.latest.kinetic)
          << threads << " parts, loaded " << loaded;
      EXPECT_NEAR(b.work_loads, a.work_loads, 1e-9 * std::fabs(a.work_loads) + 1e-15)
          << threads << " parts, loaded " << loaded;
      if (loaded) {
        EXPECT_GT(std::fabs(a.work_loads), 1e-6);
      }
    }
}

}  // namespace
}  // namespace tactile
