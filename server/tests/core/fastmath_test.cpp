// material::branchless_log, the vectorisable log of the Neo-Hookean energy,
// against a log of higher precision: relative error below one machine epsilon
// (and so within one ulp) for float and double, over [1, 1e30] where the
// kernels call it and over normal numbers below 1; exact at 1. And the
// Neo-Hookean energy that uses it against its formula with std::log.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <random>
#include <type_traits>

#include "core/material.hpp"

namespace tactile {
namespace {

using material::branchless_log;

// Worst error of branchless_log over the values passed to add().
template <class T>
struct LogError {
  double relative = 0;  // |y - log x| / |log x|
  double ulps = 0;      // |y - log x| in ulps of T at log x
  T worst_x = 0;        // where the relative error was largest
  int64_t count = 0;

  void add(T x) {
    // log in long double is accurate to ~2^-63, far below an ulp of double;
    // std::log(double) is accurate to ~2^-53, far below an ulp of float.
    using Ref = std::conditional_t<sizeof(T) == 4, double, long double>;
    const Ref exact = std::log(static_cast<Ref>(x));
    const Ref err = std::fabs(static_cast<Ref>(branchless_log(x)) - exact);
    ++count;
    if (exact == 0) {  // x = 1
      ulps = err == 0 ? ulps : std::numeric_limits<double>::infinity();
      return;
    }
    int e;
    std::frexp(exact, &e);  // |exact| = m 2^e, m in [1/2, 1)
    const Ref ulp = std::ldexp(Ref(1), e - std::numeric_limits<T>::digits);
    const double rel = static_cast<double>(err / std::fabs(exact));
    if (rel > relative) {
      relative = rel;
      worst_x = x;
    }
    ulps = std::max(ulps, static_cast<double>(err / ulp));
  }
};

// x log-uniform in [lo, hi].
template <class T>
T log_uniform(std::mt19937_64& rng, double lo, double hi) {
  std::uniform_real_distribution<double> d(std::log(lo), std::log(hi));
  const T x = static_cast<T>(std::exp(d(rng)));
  return std::min(std::max(x, static_cast<T>(lo)), static_cast<T>(hi));
}

// Samples the ranges the kernels and the reduction care about: log-uniform
// over [1, 1e30] and over the normal numbers below 1, uniform where I_C + 1
// lies in practice, the neighbours of the reduction's boundaries
// sqrt(2) 2^k and of the powers of two, and the extremes.
template <class T>
LogError<T> measure(int64_t n_random) {
  using Lim = std::numeric_limits<T>;
  LogError<T> err;
  std::mt19937_64 rng(7);
  for (int64_t i = 0; i < n_random; ++i) err.add(log_uniform<T>(rng, 1.0, 1e30));
  for (int64_t i = 0; i < n_random / 8; ++i) err.add(log_uniform<T>(rng, double(Lim::min()), 1.0));
  std::uniform_real_distribution<double> practical(1.0, 20.0);
  for (int64_t i = 0; i < n_random; ++i) err.add(static_cast<T>(practical(rng)));
  for (int k = Lim::min_exponent; k < Lim::max_exponent - 1; ++k) {
    for (T centre : {std::ldexp(T(1), k), static_cast<T>(std::ldexp(std::sqrt(2.0L), k))}) {
      T x = centre;
      for (int j = 0; j < 8; ++j) x = std::nextafter(x, T(0));
      for (int j = 0; j < 16; ++j, x = std::nextafter(x, Lim::infinity())) err.add(x);
    }
  }
  for (T x : {Lim::min(), Lim::max(), T(0.5), T(0.75), T(2), T(3), T(4), T(10)}) err.add(x);
  return err;
}

TEST(BranchlessLog, FloatIsWithinOneUlp) {
  const LogError<float> err = measure<float>(1 << 20);
  std::printf("[ log     ] float : %lld values, max %.3f ulp, max relative %.3g = %.3f eps (at x = %.9g)\n",
              static_cast<long long>(err.count), err.ulps, err.relative,
              err.relative / std::numeric_limits<float>::epsilon(), double(err.worst_x));
  EXPECT_LE(err.relative, std::numeric_limits<float>::epsilon()) << "at x = " << err.worst_x;
  EXPECT_LE(err.ulps, 1.0);
}

TEST(BranchlessLog, DoubleIsWithinOneUlp) {
  const LogError<double> err = measure<double>(1 << 20);
  std::printf("[ log     ] double: %lld values, max %.3f ulp, max relative %.3g = %.3f eps (at x = %.17g)\n",
              static_cast<long long>(err.count), err.ulps, err.relative,
              err.relative / std::numeric_limits<double>::epsilon(), err.worst_x);
  EXPECT_LE(err.relative, std::numeric_limits<double>::epsilon()) << "at x = " << err.worst_x;
  EXPECT_LE(err.ulps, 1.0);
}

// Every float where the log's argument changes octave or reduction interval
// most often in the kernels: all of [1, 4), which holds both sides of sqrt(2)
// and of 2 sqrt(2) (2^24 values).
TEST(BranchlessLog, FloatIsWithinOneUlpOnEveryValueIn1To4) {
  LogError<float> err;
  for (float x = 1.0f; x < 4.0f; x = std::nextafter(x, 4.0f)) err.add(x);
  EXPECT_EQ(err.count, int64_t(1) << 24);
  EXPECT_LE(err.relative, std::numeric_limits<float>::epsilon()) << "at x = " << err.worst_x;
  EXPECT_LE(err.ulps, 1.0);
}

TEST(BranchlessLog, IsExactlyZeroAtOne) {
  EXPECT_EQ(branchless_log(1.0f), 0.0f);
  EXPECT_EQ(branchless_log(1.0), 0.0);
  EXPECT_FALSE(std::signbit(branchless_log(1.0f)));
  EXPECT_FALSE(std::signbit(branchless_log(1.0)));
}

// The log changes sign with its argument across 1, on the smallest steps.
TEST(BranchlessLog, HasTheSignOfItsArgumentAcrossOne) {
  EXPECT_GT(branchless_log(std::nextafter(1.0f, 2.0f)), 0.0f);
  EXPECT_LT(branchless_log(std::nextafter(1.0f, 0.0f)), 0.0f);
  EXPECT_GT(branchless_log(std::nextafter(1.0, 2.0)), 0.0);
  EXPECT_LT(branchless_log(std::nextafter(1.0, 0.0)), 0.0);
}

// psi = mu'/2 (I_C - 3) + lambda'/2 (J - alpha)^2 - mu'/2 log(I_C + 1) - psi(I)
// (Smith et al. 2018, eq. 14) in long double with std::log, against the
// material function, at random F including inverted ones.
TEST(BranchlessLog, NeoHookeanEnergyMatchesItsFormula) {
  const Lame lame = compute_lame(1e5, 0.3);
  using L = long double;
  const L mu_s = L(4) / 3 * lame.mu, lambda_s = lame.lambda + L(5) / 6 * lame.mu;
  const L alpha = 1 + L(0.75) * mu_s / lambda_s;
  const L psi_rest = L(0.5) * lambda_s * (1 - alpha) * (1 - alpha) - L(0.5) * mu_s * std::log(L(4));
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> unit(-0.6, 0.6);
  for (int trial = 0; trial < 200; ++trial) {
    double F[9], P[9];
    for (int k = 0; k < 9; ++k) F[k] = (k % 4 == 0 ? 1.0 : 0.0) + unit(rng);
    const double psi = material::stress_neohookean(F, lame.lambda, lame.mu, P);
    L Ic = 0;
    for (double f : F) Ic += L(f) * L(f);
    const L J = material::det(F);
    const L psi_ref = L(0.5) * mu_s * (Ic - 3) + L(0.5) * lambda_s * (J - alpha) * (J - alpha) -
                      L(0.5) * mu_s * std::log(Ic + 1) - psi_rest;
    // Round-off of double on the terms' magnitudes, a few ulps of each.
    const L scale = mu_s * (Ic + 3 + std::log(Ic + 1) + std::log(L(4))) +
                    lambda_s * ((J - alpha) * (J - alpha) + (1 - alpha) * (1 - alpha));
    EXPECT_NEAR(psi, static_cast<double>(psi_ref), static_cast<double>(8 * scale) * 0x1p-53) << "trial " << trial;
  }
}

// F = I is stress free and energy free in float and double: the log of the
// energy and of its rest value psi(I) are one function and cancel exactly.
TEST(BranchlessLog, NeoHookeanRestEnergyIsExactlyZero) {
  const Lame lame = compute_lame(1e5, 0.3);
  const double Id[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  const float If[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  double P[9];
  float Pf[9];
  EXPECT_EQ(material::stress_neohookean(Id, lame.lambda, lame.mu, P), 0.0);
  EXPECT_EQ(material::stress_neohookean(If, float(lame.lambda), float(lame.mu), Pf), 0.0f);
}

}  // namespace
}  // namespace tactile
