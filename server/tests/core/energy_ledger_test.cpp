// The energy guard's account (core/energy_ledger.hpp) on states made by hand:
// restating the discrete term for a new step size changes no balance; a
// balance that grows beyond the tolerance is growth, within it is not, and a
// window that passes becomes the next reference; a motion that runs away past
// the critical step is caught though its balance holds.
#include <gtest/gtest.h>

#include "core/energy_ledger.hpp"

namespace tactile {
namespace {

// A state whose account opened at t = 0 with 1 J of kinetic energy and 2 J
// of elastic energy, for steps of 1 ms.
State<double> opened() {
  State<double> s;
  Energy e0;
  e0.kinetic = 1.0;
  e0.elastic = 2.0;
  s.energy.initial_ma2 = 8.0e4;  // sum m |a_0|^2
  open_energy_account(s, e0, 1e-3);
  return s;
}

TEST(EnergyLedger, OpeningTakesTheBalanceAsTheReference) {
  const State<double> s = opened();
  EXPECT_TRUE(s.energy.open);
  EXPECT_DOUBLE_EQ(s.energy.latest.discrete, -0.125 * 1e-6 * 8.0e4);
  EXPECT_DOUBLE_EQ(s.energy.reference, 3.0 + s.energy.latest.discrete);
  EXPECT_DOUBLE_EQ(s.energy.scale, 3.0);
}

TEST(EnergyLedger, ANewStepSizeRestatesTheDiscreteTermAndNotTheBalance) {
  State<double> s = opened();
  const double balance = s.energy.latest.balance(), discrete = s.energy.latest.discrete;
  restate_energy_account(s, 2e-3);
  EXPECT_DOUBLE_EQ(s.energy.latest.discrete, 4.0 * discrete);
  EXPECT_DOUBLE_EQ(s.energy.latest.balance(), balance);
  EXPECT_EQ(s.energy.dt, 2e-3);
  restate_energy_account(s, 2e-3);  // the same step again: nothing to restate
  EXPECT_DOUBLE_EQ(s.energy.latest.discrete, 4.0 * discrete);
}

TEST(EnergyLedger, ClosingTakesTheStepsSumsAndIntegratesDampingByTheTrapezoid) {
  State<double> s = opened();
  StepEnergySums sums;
  sums.elastic = 1.5;
  sums.mv2 = 3.0;  // kinetic 1.5 J
  sums.ma2 = 8.0e4;
  close_energy_account(s, sums, 1e-3, 2.0);
  EXPECT_DOUBLE_EQ(s.energy.latest.kinetic, 1.5);
  EXPECT_DOUBLE_EQ(s.energy.latest.elastic, 1.5);
  EXPECT_DOUBLE_EQ(s.dissipated, 2.0 * 1e-3 * 0.5 * (2.0 * 1.0 + 3.0));  // alpha dt (K_n + K_{n+1})
  EXPECT_DOUBLE_EQ(s.energy.latest.dissipated, s.dissipated);
}

TEST(EnergyLedger, GrowthBeyondTheToleranceIsCaughtAndWithinItIsNot) {
  constexpr double kTolerance = 0.01;
  for (const double gained : {0.005, 0.05}) {  // [J] against 0.01 x 3 J
    State<double> s = opened();
    StepEnergySums sums;
    sums.elastic = 2.0 + gained;
    sums.mv2 = 2.0;
    sums.ma2 = 8.0e4;
    close_energy_account(s, sums, 1e-3, 0.0);
    s.t = 1e-3;
    const EnergyCheck check = check_energy_account(s, kTolerance, 0.0, 1.0);
    EXPECT_NEAR(check.growth, gained, 1e-12);
    EXPECT_EQ(check.verdict, gained > kTolerance * 3.0 ? EnergyCheck::Verdict::Growth : EnergyCheck::Verdict::Ok)
        << gained << " J";
  }
}

TEST(EnergyLedger, AWindowThatPassesBecomesTheNextReference) {
  State<double> s = opened();
  StepEnergySums sums;
  sums.elastic = 2.02;  // within 1 % of 3 J
  sums.mv2 = 2.0;
  sums.ma2 = 8.0e4;
  close_energy_account(s, sums, 1e-3, 0.0);
  s.t = 0.5;
  ASSERT_EQ(check_energy_account(s, 0.01, 0.0, 1.0).verdict, EnergyCheck::Verdict::Ok);
  EXPECT_EQ(s.energy.window_start, 0.0) << "the window is not over yet";
  s.t = 1.0;
  ASSERT_EQ(check_energy_account(s, 0.01, 0.0, 1.0).verdict, EnergyCheck::Verdict::Ok);
  EXPECT_EQ(s.energy.window_start, 1.0);
  EXPECT_DOUBLE_EQ(s.energy.reference, s.energy.latest.balance());
}

TEST(EnergyLedger, AMotionThatRunsAwayIsCaughtThoughItsBalanceHolds) {
  State<double> s = opened();
  // Past the critical step: the kinetic energy grows a hundredfold while
  // the discrete term falls as fast, so the balance stays where it was.
  const double reference = s.energy.reference;
  StepEnergySums sums;
  sums.elastic = 2.0;
  sums.mv2 = 2.0 * 300.0;  // kinetic 300 J
  close_energy_account(s, sums, 1e-3, 0.0);
  s.energy.latest.discrete = reference - s.energy.latest.kinetic - s.energy.latest.elastic;
  const EnergyCheck check = check_energy_account(s, 0.01, 0.0, 1.0);
  EXPECT_NEAR(check.growth, 0.0, 1e-9);
  EXPECT_EQ(check.verdict, EnergyCheck::Verdict::Runaway);
}

}  // namespace
}  // namespace tactile
