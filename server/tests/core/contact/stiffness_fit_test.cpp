// The contact stiffness a proxy and a device feel (core/contact/stiffness_fit.hpp),
// fitted to forces made by a known linear spring, and made passive.
#include <gtest/gtest.h>

#include <cmath>

#include <glm/gtc/matrix_transform.hpp>
#include <glm/matrix.hpp>

#include "core/contact/stiffness_fit.hpp"

namespace tactile {
namespace {

double largest_difference(const glm::dmat3& a, const glm::dmat3& b) {
  double d = 0;
  for (int c = 0; c < 3; ++c)
    for (int r = 0; r < 3; ++r) d = std::max(d, std::fabs(a[c][r] - b[c][r]));
  return d;
}

TEST(StiffnessFit, NearestPassiveKeepsTheStiffDirectionsAndDropsThePushingOnes) {
  // diag(-300, +100, -50) turned about (1, 2, 3): the +100 (a contact pulling the proxy in) goes to zero.
  const glm::dmat3 R(glm::rotate(glm::dmat4(1.0), 0.7, glm::normalize(glm::dvec3(1, 2, 3))));
  glm::dmat3 D(0.0);
  D[0][0] = -300;
  D[1][1] = 100;
  D[2][2] = -50;
  glm::dmat3 expected(0.0);
  expected[0][0] = -300;
  expected[2][2] = -50;
  EXPECT_LT(largest_difference(nearest_passive(R * D * glm::transpose(R)), R * expected * glm::transpose(R)), 1e-9);
  // With `stiffest`, no direction stiffer than it.
  expected[0][0] = -120;
  EXPECT_LT(largest_difference(nearest_passive(R * D * glm::transpose(R), 120.0), R * expected * glm::transpose(R)),
            1e-9);
  // An asymmetric part is dropped: the symmetric part is what is kept.
  glm::dmat3 A(0.0);
  A[0][0] = -200;
  A[1][0] = 40;  // column 1, row 0
  glm::dmat3 sym = nearest_passive(A);
  EXPECT_NEAR(sym[1][0], sym[0][1], 1e-12);
}

TEST(StiffnessFit, AProxyMovingOverASpringFindsItsStiffnessInTheDirectionsItMoved) {
  glm::dmat3 K(0.0);  // the body's dF/dx on the proxy: stiff in x, softer in y, coupled; nothing in z
  K[0][0] = -300;
  K[1][1] = -200;
  K[0][1] = K[1][0] = -50;
  StiffnessFit f;
  glm::dmat3 fitted(0.0);
  const double dt = 1e-4;
  for (int step = 0; step < 20000; ++step) {  // a 2 s loop of radius 2 mm in the x-y plane
    const double t = step * dt;
    const Vec3 x(0.002 * std::cos(3.0 * t), 0.002 * std::sin(3.0 * t), 0.0);
    fit_stiffness(f, FitWindow::Proxy, x, K * x, dt, fitted);
  }
  EXPECT_LT(largest_difference(fitted, K), 0.5);  // of 300 N/m
  EXPECT_NEAR(fitted[2][2], 0.0, 1e-6);           // never moved along z: nothing claimed there
}

TEST(StiffnessFit, ADeviceFitFollowsItsMotionNotItsJitter) {
  // The device strokes along x over a 600 N/m contact, while its encoder jitters 2 um in y against a 2000 N/m
  // coupling whose force the proxy never gets to follow: the fit gives the stroke's stiffness.
  StiffnessFit f;
  glm::dmat3 fitted(0.0);
  const double dt = 1e-3;
  for (int step = 0; step < 4000; ++step) {
    const double t = step * dt;
    const double jitter = (step % 2 ? 2e-6 : -2e-6);
    const Vec3 x(0.004 * std::sin(2.0 * t), jitter, 0.0);
    const Vec3 force(-600 * x.x, -2000 * jitter, 0.0);
    fit_stiffness(f, FitWindow::Device, x, force, dt, fitted);
  }
  EXPECT_NEAR(fitted[0][0], -600, 30);
  EXPECT_GT(fitted[1][1], -200);  // the jitter's 2000 N/m is not what the hand feels
}

}  // namespace
}  // namespace tactile
