#include "core/material.hpp"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <numbers>
#include <random>

#include "core/fem_fixtures.hpp"

namespace tactile {
namespace {

using test::kAllModels;
using test::kRotationInvariantModels;
using test::make_rotation;

using Mat = std::array<double, 9>;  // row-major 3x3

constexpr double kE = 1e5, kNu = 0.3;
const Lame kLame = compute_lame(kE, kNu);

Mat from_glm(const glm::dmat3& A) {
  Mat M;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) M[size_t(3 * i + j)] = A[j][i];
  return M;
}
Mat mul(const Mat& A, const Mat& B) {
  Mat C{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) C[size_t(3 * i + j)] += A[size_t(3 * i + k)] * B[size_t(3 * k + j)];
  return C;
}
Mat diag(double a, double b, double c) { return {a, 0, 0, 0, b, 0, 0, 0, c}; }
double norm(const Mat& A) {
  double s = 0;
  for (double x : A) s += x * x;
  return std::sqrt(s);
}

double psi_of(MaterialModel m, const Mat& F, Mat* P = nullptr) {
  Mat scratch;
  return material::stress(m, F.data(), kLame.lambda, kLame.mu, P ? P->data() : scratch.data());
}

// F = R1 diag(s) R2 with random rotations and stretches s in [lo, hi];
// `flip` negates the smallest stretch (an inverted element).
Mat make_random_F(std::mt19937& rng, double lo, double hi, bool flip) {
  std::uniform_real_distribution<double> unit(-1.0, 1.0), stretch(lo, hi), angle(-std::numbers::pi, std::numbers::pi);
  auto random_rotation = [&] {
    Vec3 axis(unit(rng), unit(rng), unit(rng));
    if (glm::length(axis) < 1e-3) axis = Vec3(1, 2, 3);
    return from_glm(make_rotation(axis, angle(rng)));
  };
  std::array<double, 3> s{stretch(rng), stretch(rng), stretch(rng)};
  // Stretches at least 0.05 apart: with one flipped, the rotation of the
  // polar decomposition varies as 1 / (s_i - s_j), and near s_i = s_j central
  // differences would need a much smaller step than their round-off allows.
  while (std::fabs(s[0] - s[1]) < 0.05 || std::fabs(s[1] - s[2]) < 0.05 || std::fabs(s[0] - s[2]) < 0.05)
    s = {stretch(rng), stretch(rng), stretch(rng)};
  if (flip) {
    size_t k = 0;
    for (size_t i = 1; i < 3; ++i)
      if (s[i] < s[k]) k = i;
    s[k] = -s[k];
  }
  return mul(mul(random_rotation(), diag(s[0], s[1], s[2])), random_rotation());
}

// Central differences of psi, one entry of F at a time: the P every model must return.
Mat compute_stress_by_differences(MaterialModel m, const Mat& F, double h) {
  Mat P{};
  for (size_t k = 0; k < 9; ++k) {
    Mat Fp = F, Fm = F;
    Fp[k] += h;
    Fm[k] -= h;
    P[k] = (psi_of(m, Fp) - psi_of(m, Fm)) / (2 * h);
  }
  return P;
}

TEST(Material, NamesRoundTripAndUnknownNamesAreRefused) {
  for (MaterialModel m : kAllModels) {
    MaterialModel parsed = m == MaterialModel::Linear ? MaterialModel::StVK : MaterialModel::Linear;
    ASSERT_TRUE(parse_material_model(to_string(m), &parsed)) << to_string(m);
    EXPECT_EQ(parsed, m);
  }
  MaterialModel out = MaterialModel::StVK;
  EXPECT_FALSE(parse_material_model("neo-hookean", &out));
  EXPECT_FALSE(parse_material_model("", &out));
  EXPECT_EQ(out, MaterialModel::StVK);  // untouched
  EXPECT_FALSE(can_invert(MaterialModel::StVK));
  EXPECT_TRUE(can_invert(MaterialModel::NeoHookean));
}

TEST(Material, LameParametersReproduceYoungsModulusAndPoissonsRatio) {
  for (double nu : {-0.5, 0.0, 0.25, 0.3, 0.45, 0.49}) {
    const Lame l = compute_lame(kE, nu);
    EXPECT_NEAR(l.mu * (3 * l.lambda + 2 * l.mu) / (l.lambda + l.mu), kE, 1e-9 * kE) << nu;
    EXPECT_NEAR(l.lambda / (2 * (l.lambda + l.mu)), nu, 1e-12) << nu;
  }
}

// Uniaxial stress: a bar stretched by a small e along x and free to contract
// by nu e sideways carries P_xx = E e and no lateral stress, for every model.
TEST(Material, SmallUniaxialStretchGivesYoungsModulus) {
  const double e = 1e-6;
  for (MaterialModel m : kAllModels) {
    Mat P;
    psi_of(m, diag(1 + e, 1 - kNu * e, 1 - kNu * e), &P);
    EXPECT_NEAR(P[0], kE * e, 1e-4 * kE * e) << to_string(m);
    EXPECT_NEAR(P[4], 0.0, 1e-4 * kE * e) << to_string(m);
    EXPECT_NEAR(P[8], 0.0, 1e-4 * kE * e) << to_string(m);
  }
}

// The paper's central claim (section 3): a rigid rotation is no strain. The
// Green strain (eqs. 5-6) and the models built on invariants see none; the
// small strain (eqs. 2-3) sees cos(theta) - 1 in the plane of rotation.
TEST(Material, RigidRotationIsStressFreeExceptForLinearStrain) {
  const Vec3 axes[] = {Vec3(1, 2, 3), Vec3(-1, 0.5, 2), Vec3(0, 0, 1), Vec3(0.3, -1, -0.2)};
  const double degrees[] = {90, 180, 270, 37, 135, 359};
  for (const Vec3& axis : axes) {
    for (double deg : degrees) {
      const Mat R = from_glm(make_rotation(axis, deg * std::numbers::pi / 180));
      for (MaterialModel m : kRotationInvariantModels) {
        Mat P;
        const double psi = psi_of(m, R, &P);
        EXPECT_NEAR(psi, 0.0, 1e-11 * kE) << to_string(m) << " " << deg << " deg";
        EXPECT_LT(norm(P), 1e-10 * kE) << to_string(m) << " " << deg << " deg";
      }
      Mat P;
      const double psi = psi_of(MaterialModel::Linear, R, &P);
      // Only the rotation's symmetric part counts: sym(R) - I, whose trace is 2 (cos - 1).
      const double c = std::cos(deg * std::numbers::pi / 180);
      EXPECT_GT(psi, 0.1 * kLame.mu * 2 * (1 - c) * (1 - c)) << deg << " deg";
      EXPECT_GT(norm(P), 0.1 * kE * (1 - c)) << deg << " deg";
    }
  }
}

// A rotated state has the rotated stress: P(R F) = R P(F), psi(R F) = psi(F).
TEST(Material, StressIsObjective) {
  std::mt19937 rng(11);
  for (MaterialModel m : kRotationInvariantModels) {
    for (int trial = 0; trial < 20; ++trial) {
      const Mat F = make_random_F(rng, 0.7, 1.4, false);
      const Mat R = from_glm(make_rotation(Vec3(0.2, -1, 0.7), 0.3 + trial));
      Mat P, PR;
      const double psi = psi_of(m, F, &P);
      const double psiR = psi_of(m, mul(R, F), &PR);
      EXPECT_NEAR(psiR, psi, 1e-10 * kE) << to_string(m);
      const Mat RP = mul(R, P);
      for (size_t k = 0; k < 9; ++k) EXPECT_NEAR(PR[k], RP[k], 1e-9 * kE) << to_string(m) << " k=" << k;
    }
  }
}

// P = d psi / dF by central differences, at random F with large rotations;
// corotational and Neo-Hookean also at inverted F (det F < 0).
TEST(Material, StressIsTheDerivativeOfEnergy) {
  std::mt19937 rng(3);
  for (MaterialModel m : kAllModels) {
    for (bool flip : {false, true}) {
      if (flip && !can_invert(m)) continue;
      for (int trial = 0; trial < 25; ++trial) {
        const Mat F = make_random_F(rng, 0.5, 1.6, flip);
        ASSERT_EQ(material::det(F.data()) < 0, flip);
        Mat P;
        psi_of(m, F, &P);
        const Mat P_fd = compute_stress_by_differences(m, F, 1e-6);
        // Differences of psi ~ E carry round-off ~ 1e-16 E / 1e-6 = 1e-10 E.
        for (size_t k = 0; k < 9; ++k)
          EXPECT_NEAR(P[k], P_fd[k], 1e-7 * kE)
              << to_string(m) << (flip ? " inverted" : "") << " trial " << trial << " k=" << k;
      }
    }
  }
}

// Invertible StVK is StVK wherever no singular value is under its floor: the same
// stress and energy to round-off, at random F with large rotations.
TEST(Material, InvertibleStvkIsStvkAboveItsFloor) {
  std::mt19937 rng(29);
  for (int trial = 0; trial < 200; ++trial) {
    const Mat F = make_random_F(rng, material::kInversionFloor + 0.01, 1.6, false);
    EXPECT_FALSE(material::reaches_floor(F.data())) << "trial " << trial;
    Mat P, P_inv;
    const double psi = psi_of(MaterialModel::StVK, F, &P);
    const double psi_inv = psi_of(MaterialModel::InvertibleStVK, F, &P_inv);
    EXPECT_NEAR(psi_inv, psi, 1e-12 * kE) << "trial " << trial;
    for (size_t k = 0; k < 9; ++k) EXPECT_NEAR(P_inv[k], P[k], 1e-10 * kE) << "trial " << trial << " k=" << k;
  }
}

// The kernels' test of whether F reaches the floor, without the SVD, agrees
// with the SVD's smallest singular value (inverted F always reach it).
TEST(Material, TheFloorTestAgreesWithTheSingularValues) {
  std::mt19937 rng(37);
  int reaching = 0, trials = 0;
  for (bool flip : {false, true}) {
    for (int trial = 0; trial < 2000; ++trial) {
      const Mat F = make_random_F(rng, 0.2, 1.6, flip);
      double U[3][3], V[3][3], s[3];
      material::svd_of(F.data(), U, s, V);
      const double smallest = s[2];  // signed: negative when inverted
      if (std::fabs(smallest - material::kInversionFloor) < 1e-9) continue;
      ++trials;
      const bool reaches = smallest < material::kInversionFloor;
      reaching += reaches;
      EXPECT_EQ(material::reaches_floor(F.data()), reaches)
          << "sigma_min " << smallest << (flip ? " (inverted)" : "") << " trial " << trial;
    }
  }
  EXPECT_GT(reaching, trials / 5);
  EXPECT_LT(reaching, trials);
}

// Below the floor and through inversion its stress is still the derivative of its
// energy, and the kernels' cheap test never misses an F that reaches the floor.
TEST(Material, InvertibleStvkStressIsTheDerivativeOfItsEnergyPastTheFloor) {
  std::mt19937 rng(31);
  for (bool flip : {false, true}) {
    for (int trial = 0; trial < 50; ++trial) {
      const Mat F = make_random_F(rng, 0.1, 1.4, flip);
      Mat P;
      psi_of(MaterialModel::InvertibleStVK, F, &P);
      const Mat P_fd = compute_stress_by_differences(MaterialModel::InvertibleStVK, F, 1e-6);
      for (size_t k = 0; k < 9; ++k)
        EXPECT_NEAR(P[k], P_fd[k], 1e-7 * kE) << (flip ? "inverted" : "") << " trial " << trial << " k=" << k;
      if (flip) {
        EXPECT_TRUE(material::reaches_floor(F.data()));
      }
    }
  }
}

// Past the floor, compressed along one axis, invertible StVK resists at least
// as much as at the floor, and more the further it goes, where plain StVK's
// resistance falls to zero at full compression and vanishes inverted.
TEST(Material, InvertibleStvkResistsCompressionPastTheFloor) {
  double at_floor = 0;
  for (double s : {material::kInversionFloor, 0.4, 0.2, 0.0, -0.3}) {
    Mat P, P_plain;
    psi_of(MaterialModel::InvertibleStVK, diag(1, 1, s), &P);
    psi_of(MaterialModel::StVK, diag(1, 1, s), &P_plain);
    if (s == material::kInversionFloor) at_floor = P[8];
    EXPECT_LT(P[8], 0.0) << s;
    EXPECT_LE(P[8], at_floor * (1 - 1e-12)) << s;
    if (s < material::kInversionFloor) {
      EXPECT_LT(P[8], P_plain[8]) << s;
    }
  }
  Mat P0;
  psi_of(MaterialModel::StVK, diag(1, 1, 0.0), &P0);
  EXPECT_EQ(P0[8], 0.0) << "plain StVK offers nothing at full compression";
}

// A check of the check: a stress that is not the derivative fails it.
TEST(Material, DifferenceCheckDetectsAWrongStress) {
  std::mt19937 rng(5);
  const Mat F = make_random_F(rng, 0.8, 1.3, false);
  Mat P_svk, P_lin;
  psi_of(MaterialModel::StVK, F, &P_svk);
  psi_of(MaterialModel::Linear, F, &P_lin);
  const Mat P_fd = compute_stress_by_differences(MaterialModel::StVK, F, 1e-6);
  double err_svk = 0, err_lin = 0;
  for (size_t k = 0; k < 9; ++k) {
    err_svk = std::max(err_svk, std::fabs(P_svk[k] - P_fd[k]));
    err_lin = std::max(err_lin, std::fabs(P_lin[k] - P_fd[k]));
  }
  EXPECT_LT(err_svk, 1e-7 * kE);
  EXPECT_GT(err_lin, 1e-2 * kE);
}

// Neo-Hookean (through its reparametrised mu', lambda'), corotational and
// StVK linearise to (lambda, mu): for F = I + H with a small H, their stress
// differs from the linear one by O(|H|^2), so the relative difference halves
// when H halves.
TEST(Material, NonlinearModelsLineariseToTheLameParameters) {
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  Mat H;
  for (double& x : H) x = unit(rng);
  const double scale = norm(H);
  for (double& x : H) x /= scale;
  for (MaterialModel m : kRotationInvariantModels) {
    double previous = 0;
    for (double eps : {1e-2, 1e-3, 1e-4}) {
      Mat F = diag(1, 1, 1);
      for (size_t k = 0; k < 9; ++k) F[k] += eps * H[k];
      Mat P, P_lin;
      psi_of(m, F, &P);
      psi_of(MaterialModel::Linear, F, &P_lin);
      Mat d;
      for (size_t k = 0; k < 9; ++k) d[k] = P[k] - P_lin[k];
      const double rel = norm(d) / norm(P_lin);
      EXPECT_LT(rel, 10 * eps) << to_string(m) << " eps " << eps;
      if (previous > 0) {
        EXPECT_NEAR(rel / previous, 0.1, 0.03) << to_string(m) << " eps " << eps;
      }
      previous = rel;
    }
  }
}

// Corotational, Neo-Hookean and invertible StVK push an inverted element back: at F = diag(1, 1, -s)
// the stress along the flipped axis opposes further flattening.
TEST(Material, InvertibleModelsPushAnInvertedElementBack) {
  for (MaterialModel m : {MaterialModel::Corotational, MaterialModel::NeoHookean, MaterialModel::InvertibleStVK}) {
    for (double s : {0.1, 0.5, 0.9}) {
      const Mat F = diag(1, 1, -s);
      Mat P;
      const double psi = psi_of(m, F, &P);
      EXPECT_GT(psi, 0.0) << to_string(m);
      // psi decreases as F_zz rises towards +1: d psi / d F_zz = P_zz < 0.
      EXPECT_LT(P[8], 0.0) << to_string(m) << " s=" << s;
    }
  }
}

// The stepper refreshes the critical step with this bound; for StVK under a
// uniaxial stretch s it is exact: d P_xx / d F_xx = (lambda + 2 mu)(3 s^2 - 1) / 2.
TEST(Material, StiffeningMatchesStvkUniaxialTangent) {
  for (double s : {1.0, 1.2, 1.5, 2.0}) {
    const double h = 1e-6;
    Mat Pp, Pm;
    psi_of(MaterialModel::StVK, diag(s + h, 1, 1), &Pp);
    psi_of(MaterialModel::StVK, diag(s - h, 1, 1), &Pm);
    const double tangent = (Pp[0] - Pm[0]) / (2 * h) / (kLame.lambda + 2 * kLame.mu);
    const Mat F = diag(s, 1, 1);
    EXPECT_NEAR(material::stiffening(MaterialModel::StVK, F.data()), tangent, 1e-6 * tangent) << s;
    EXPECT_EQ(material::stiffening(MaterialModel::Linear, F.data()), 1.0);
    // Neo-Hookean's tangent along the stretch stays under its bound.
    psi_of(MaterialModel::NeoHookean, diag(s + h, 1, 1), &Pp);
    psi_of(MaterialModel::NeoHookean, diag(s - h, 1, 1), &Pm);
    const double nh = (Pp[0] - Pm[0]) / (2 * h) / (kLame.lambda + 2 * kLame.mu);
    EXPECT_LE(nh, material::stiffening(MaterialModel::NeoHookean, F.data()) * (1 + 1e-6)) << s;
  }
}

// The float kernels run the same functions: in float, rigid rotation stays
// stress-free to float round-off and P matches the double evaluation.
TEST(Material, FloatMatchesDouble) {
  std::mt19937 rng(23);
  for (MaterialModel m : kAllModels) {
    for (int trial = 0; trial < 10; ++trial) {
      const Mat F = make_random_F(rng, 0.7, 1.4, false);
      Mat P;
      psi_of(m, F, &P);
      float Ff[9], Pf[9];
      for (size_t k = 0; k < 9; ++k) Ff[k] = float(F[k]);
      material::stress(m, Ff, float(kLame.lambda), float(kLame.mu), Pf);
      for (size_t k = 0; k < 9; ++k) EXPECT_NEAR(double(Pf[k]), P[k], 1e-4 * kE) << to_string(m) << " k=" << k;
    }
  }
}

}  // namespace
}  // namespace tactile
