// material::rotation_of: the rotation R = U V^T of the polar decomposition,
// with the Irving et al. flip of the smallest singular value when det F < 0.
// Every check runs in float and in double, the two precisions the kernels use.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <random>

#include "core/material.hpp"

namespace tactile {
namespace {

using Mat = std::array<double, 9>;  // row-major 3x3, the reference side in double

Mat mul(const Mat& A, const Mat& B) {
  Mat C{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) C[size_t(3 * i + j)] += A[size_t(3 * i + k)] * B[size_t(3 * k + j)];
  return C;
}
Mat transpose(const Mat& A) {
  Mat T;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) T[size_t(3 * i + j)] = A[size_t(3 * j + i)];
  return T;
}
Mat diag(double a, double b, double c) { return {a, 0, 0, 0, b, 0, 0, 0, c}; }
double max_abs_diff(const Mat& A, const Mat& B) {
  double d = 0;
  for (size_t k = 0; k < 9; ++k) d = std::max(d, std::fabs(A[k] - B[k]));
  return d;
}

// Uniformly random rotation, from a normalised Gaussian quaternion.
Mat make_random_rotation(std::mt19937& rng) {
  std::normal_distribution<double> normal;
  double w = normal(rng), x = normal(rng), y = normal(rng), z = normal(rng);
  const double n = std::sqrt(w * w + x * x + y * y + z * z);
  w /= n, x /= n, y /= n, z /= n;
  return {1 - 2 * (y * y + z * z), 2 * (x * y - w * z),     2 * (x * z + w * y),
          2 * (x * y + w * z),     1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
          2 * (x * z - w * y),     2 * (y * z + w * x),     1 - 2 * (x * x + y * y)};
}

// F = Q diag(s) W^T: an SVD by construction, so the expected R is known.
Mat make_F(const Mat& Q, double s0, double s1, double s2, const Mat& W) {
  return mul(mul(Q, diag(s0, s1, s2)), transpose(W));
}

template <class T>
class RotationOf : public ::testing::Test {
 protected:
  // Largest error allowed in an entry of R for a well-conditioned F: a few
  // dozen roundings of the precision.
  static constexpr double kTol = sizeof(T) == 4 ? 5e-6 : 1e-12;

  // R for F, computed in T and returned in double. F is rounded to T first,
  // so the expected values (computed in double) carry that rounding too.
  static Mat rotation(const Mat& F) {
    T Ft[9], Rt[9];
    for (size_t k = 0; k < 9; ++k) Ft[k] = T(F[k]);
    material::rotation_of(Ft, Rt);
    Mat R;
    for (size_t k = 0; k < 9; ++k) R[k] = double(Rt[k]);
    return R;
  }

  // R^T R = I and det R = +1.
  static void expect_rotation(const Mat& R, const char* what) {
    const Mat RtR = mul(transpose(R), R);
    EXPECT_LT(max_abs_diff(RtR, diag(1, 1, 1)), 2 * kTol) << what;
    double Rd[9];
    std::copy(R.begin(), R.end(), Rd);
    EXPECT_NEAR(material::det(Rd), 1.0, 2 * kTol) << what;
  }
};
using Precisions = ::testing::Types<float, double>;
TYPED_TEST_SUITE(RotationOf, Precisions);

// Any F at all, inverted or not, well-conditioned or not: R is a proper rotation.
TYPED_TEST(RotationOf, IsAProperRotationForRandomF) {
  std::mt19937 rng(11);
  std::normal_distribution<double> normal;
  for (int trial = 0; trial < 2000; ++trial) {
    Mat F;
    for (double& x : F) x = normal(rng);
    this->expect_rotation(this->rotation(F), "random F");
  }
}

// F a rotation: R = F.
TYPED_TEST(RotationOf, OfARotationIsItself) {
  std::mt19937 rng(12);
  for (int trial = 0; trial < 500; ++trial) {
    const Mat Q = make_random_rotation(rng);
    EXPECT_LT(max_abs_diff(this->rotation(Q), Q), this->kTol) << "trial " << trial;
  }
  EXPECT_LT(max_abs_diff(this->rotation(diag(1, 1, 1)), diag(1, 1, 1)), this->kTol);
}

// F = Q diag(s) W^T with distinct positive s: R = Q W^T, the reference value.
TYPED_TEST(RotationOf, MatchesTheSvdOfAStretchedRotation) {
  std::mt19937 rng(13);
  std::uniform_real_distribution<double> stretch(0.3, 3.0);
  for (int trial = 0; trial < 1000; ++trial) {
    const Mat Q = make_random_rotation(rng), W = make_random_rotation(rng);
    const Mat F = make_F(Q, stretch(rng), stretch(rng), stretch(rng), W);
    EXPECT_LT(max_abs_diff(this->rotation(F), mul(Q, transpose(W))), this->kTol) << "trial " << trial;
  }
}

// det F < 0: the sign goes to the smallest singular value wherever the
// negative stretch was written (Irving et al. 2004). With s = (2, 1.5, 0.5):
// diag(2, 1.5, -0.5) gives R = Q W^T, and diag(-2, 1.5, 0.5) =
// diag(-1, 1, -1) diag(2, 1.5, -0.5) gives R = Q diag(-1, 1, -1) W^T.
TYPED_TEST(RotationOf, FlipsTheSmallestSingularValueWhenInverted) {
  std::mt19937 rng(14);
  for (int trial = 0; trial < 500; ++trial) {
    const Mat Q = make_random_rotation(rng), W = make_random_rotation(rng);
    const Mat QWt = mul(Q, transpose(W));
    const Mat R_small = this->rotation(make_F(Q, 2.0, 1.5, -0.5, W));
    EXPECT_LT(max_abs_diff(R_small, QWt), this->kTol) << "trial " << trial;
    const Mat R_large = this->rotation(make_F(Q, -2.0, 1.5, 0.5, W));
    EXPECT_LT(max_abs_diff(R_large, mul(mul(Q, diag(-1, 1, -1)), transpose(W))), this->kTol) << "trial " << trial;
    this->expect_rotation(R_large, "inverted");
  }
  // A reflection through the z = 0 plane with z squashed: the flip lands on
  // z, the smallest stretch, so R = I.
  EXPECT_LT(max_abs_diff(this->rotation(diag(1, 1, -0.5)), diag(1, 1, 1)), this->kTol);
}

// det F > 0: R^T F = V Sigma V^T is symmetric (what makes the corotational
// stress the derivative of its energy).
TYPED_TEST(RotationOf, LeavesASymmetricStretch) {
  std::mt19937 rng(15);
  std::normal_distribution<double> normal;
  int checked = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    Mat F;
    for (double& x : F) x = normal(rng);
    double Fd[9];
    std::copy(F.begin(), F.end(), Fd);
    if (material::det(Fd) <= 0) continue;
    // The polar factor varies as 1 / (s_i + s_j): skip the nearly flat F
    // where that, not the method, sets the error.
    if (material::det(Fd) < 0.05) continue;
    const Mat S = mul(transpose(this->rotation(F)), F);
    const double asym = std::max({std::fabs(S[1] - S[3]), std::fabs(S[2] - S[6]), std::fabs(S[5] - S[7])});
    double scale = 0;
    for (double x : F) scale += x * x;
    EXPECT_LT(asym, this->kTol * std::sqrt(scale)) << "trial " << trial;
    ++checked;
  }
  EXPECT_GT(checked, 500);
}

// rotation_of(Q F) = Q rotation_of(F) and rotation_of(F Q) = rotation_of(F) Q:
// the polar rotation turns with the frame, on either side.
TYPED_TEST(RotationOf, TurnsWithTheFrame) {
  std::mt19937 rng(16);
  std::uniform_real_distribution<double> large(2.0, 3.0), middle(1.0, 1.5), small(0.3, 0.6);
  for (int trial = 0; trial < 500; ++trial) {
    const Mat Q = make_random_rotation(rng);
    // Odd trials inverted, with the smallest stretch clearly the smallest so
    // that which one flips is well defined.
    const double s2 = trial % 2 ? -small(rng) : small(rng);
    const Mat F = make_F(make_random_rotation(rng), large(rng), middle(rng), s2, make_random_rotation(rng));
    const Mat R = this->rotation(F);
    EXPECT_LT(max_abs_diff(this->rotation(mul(Q, F)), mul(Q, R)), 2 * this->kTol) << "trial " << trial;
    EXPECT_LT(max_abs_diff(this->rotation(mul(F, Q)), mul(R, Q)), 2 * this->kTol) << "trial " << trial;
  }
}

// R does not depend on the size of F, down to values far below any strain.
TYPED_TEST(RotationOf, DoesNotDependOnScale) {
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> stretch(0.3, 3.0);
  const double tiny = sizeof(TypeParam) == 4 ? 1e-15 : 1e-100;
  const double huge = sizeof(TypeParam) == 4 ? 1e15 : 1e100;
  for (int trial = 0; trial < 200; ++trial) {
    const Mat Q = make_random_rotation(rng), W = make_random_rotation(rng);
    const Mat F = make_F(Q, stretch(rng), stretch(rng), stretch(rng), W);
    const Mat QWt = mul(Q, transpose(W));
    for (double a : {tiny, huge}) {
      Mat aF = F;
      for (double& x : aF) x *= a;
      EXPECT_LT(max_abs_diff(this->rotation(aF), QWt), this->kTol) << "scale " << a << " trial " << trial;
    }
  }
}

// Nearly equal and equal singular values, where eigenvectors are ill defined
// but the polar rotation is not: R = Q W^T still.
TYPED_TEST(RotationOf, HandlesNearlyEqualSingularValues) {
  std::mt19937 rng(18);
  for (int trial = 0; trial < 500; ++trial) {
    const Mat Q = make_random_rotation(rng), W = make_random_rotation(rng);
    const Mat QWt = mul(Q, transpose(W));
    for (double d : {0.0, 1e-9, 1e-6, 1e-3}) {
      EXPECT_LT(max_abs_diff(this->rotation(make_F(Q, 1.0, 1.0 + d, 1.0 - d, W)), QWt), this->kTol)
          << "d " << d << " trial " << trial;
      EXPECT_LT(max_abs_diff(this->rotation(make_F(Q, 2.0, 2.0 + d, 0.5, W)), QWt), this->kTol)
          << "pair d " << d << " trial " << trial;
    }
  }
}

// A flat element (rank 2): u3 = u1 x u2, so R = Q W^T with nothing to flip.
// Rank 1 (F = a b^T): R is a rotation taking b to the direction of a.
// Rank 0 (F = 0): any rotation, but a rotation.
TYPED_TEST(RotationOf, StaysARotationForRankDeficientF) {
  std::mt19937 rng(19);
  std::uniform_real_distribution<double> stretch(0.3, 3.0);
  std::normal_distribution<double> normal;
  for (int trial = 0; trial < 500; ++trial) {
    const Mat Q = make_random_rotation(rng), W = make_random_rotation(rng);
    const Mat R2 = this->rotation(make_F(Q, stretch(rng), stretch(rng), 0.0, W));
    this->expect_rotation(R2, "rank 2");
    EXPECT_LT(max_abs_diff(R2, mul(Q, transpose(W))), 10 * this->kTol) << "rank 2, trial " << trial;

    const std::array<double, 3> a{normal(rng), normal(rng), normal(rng)}, b{normal(rng), normal(rng), normal(rng)};
    Mat F1;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) F1[size_t(3 * i + j)] = a[size_t(i)] * b[size_t(j)];
    const Mat R1 = this->rotation(F1);
    this->expect_rotation(R1, "rank 1");
    const double na = std::hypot(a[0], a[1], a[2]), nb = std::hypot(b[0], b[1], b[2]);
    for (int i = 0; i < 3; ++i) {
      const double Rb = R1[size_t(3 * i)] * b[0] + R1[size_t(3 * i + 1)] * b[1] + R1[size_t(3 * i + 2)] * b[2];
      EXPECT_NEAR(Rb / nb, a[size_t(i)] / na, 10 * this->kTol) << "rank 1, trial " << trial;
    }
  }
  const Mat R0 = this->rotation(Mat{});
  this->expect_rotation(R0, "rank 0");
}

}  // namespace
}  // namespace tactile
