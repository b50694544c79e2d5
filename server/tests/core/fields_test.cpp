// Stress and strain per element for output (core/fields.hpp): the laws they
// must keep, on single deformation gradients and on a whole model.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "core/fields.hpp"
#include "core/material.hpp"
#include "fem_fixtures.hpp"

namespace tactile {
namespace {

constexpr double kE = 1e5, kNu = 0.3;

void to_rows(const glm::dmat3& m, double* F) {
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) F[3 * i + j] = m[j][i];
}

// Turned, not strained: no strain, no stress, for every model that is invariant under rotation.
TEST(ElementFields, RigidRotationHasNoStrainOrStress) {
  const Lame l = compute_lame(kE, kNu);
  double F[9];
  to_rows(test::make_rotation(Vec3(1, 2, 3), 1.1), F);
  for (MaterialModel m : test::kRotationInvariantModels) {
    const TetFields f = compute_tet_fields(m, F, l.lambda, l.mu);
    for (int k = 0; k < 9; ++k) {
      EXPECT_NEAR(f.green[k], 0.0, 1e-14) << to_string(m) << " " << k;
      EXPECT_NEAR(f.cauchy[k], 0.0, 1e-9 * kE) << to_string(m) << " " << k;
    }
    EXPECT_NEAR(f.von_mises, 0.0, 1e-9 * kE) << to_string(m);
  }
}

// StVK stretched along x by s (eqs. 5-6): E_xx = (s^2 - 1)/2, S = lambda tr(E) I
// + 2 mu E, and sigma = F S F^T / J, so sigma_xx = s S_xx and sigma_yy = S_yy / s.
TEST(ElementFields, StVKUniaxialStretchMatchesTheClosedForm) {
  const Lame l = compute_lame(kE, kNu);
  for (double s : {0.8, 1.0, 1.05, 1.3}) {
    const double F[9] = {s, 0, 0, 0, 1, 0, 0, 0, 1};
    const TetFields f = compute_tet_fields(MaterialModel::StVK, F, l.lambda, l.mu);
    const double Exx = 0.5 * (s * s - 1.0);
    const double Sxx = (l.lambda + 2 * l.mu) * Exx, Syy = l.lambda * Exx;
    EXPECT_NEAR(f.green[0], Exx, 1e-15);
    EXPECT_NEAR(f.green[4], 0.0, 1e-15);
    EXPECT_NEAR(f.cauchy[0], s * Sxx, 1e-9 * kE) << s;
    EXPECT_NEAR(f.cauchy[4], Syy / s, 1e-9 * kE) << s;
    EXPECT_NEAR(f.cauchy[8], Syy / s, 1e-9 * kE) << s;
    EXPECT_NEAR(f.von_mises, std::fabs(s * Sxx - Syy / s), 1e-9 * kE) << s;
  }
}

// A uniform dilation loads every direction alike: pressure, no shear, no von Mises.
TEST(ElementFields, DilationIsPurePressure) {
  const Lame l = compute_lame(kE, kNu);
  const double F[9] = {1.1, 0, 0, 0, 1.1, 0, 0, 0, 1.1};
  for (MaterialModel m : test::kAllModels) {
    const TetFields f = compute_tet_fields(m, F, l.lambda, l.mu);
    EXPECT_GT(f.cauchy[0], 0.0) << to_string(m);
    EXPECT_NEAR(f.cauchy[4], f.cauchy[0], 1e-9 * kE) << to_string(m);
    EXPECT_NEAR(f.cauchy[1], 0.0, 1e-9 * kE) << to_string(m);
    EXPECT_NEAR(f.von_mises, 0.0, 1e-8 * kE) << to_string(m);
  }
}

// The Cauchy stress is symmetric (balance of angular momentum) under any deformation.
TEST(ElementFields, CauchyStressIsSymmetric) {
  const Lame l = compute_lame(kE, kNu);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> d(-0.3, 0.3);
  for (int trial = 0; trial < 50; ++trial) {
    double F[9];
    for (int k = 0; k < 9; ++k) F[k] = (k % 4 == 0 ? 1.0 : 0.0) + d(rng);
    for (MaterialModel m : test::kAllModels) {
      const TetFields f = compute_tet_fields(m, F, l.lambda, l.mu);
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < i; ++j)
          EXPECT_NEAR(f.cauchy[3 * i + j], f.cauchy[3 * j + i], 1e-9 * (std::fabs(f.cauchy[3 * i + j]) + kE))
              << to_string(m) << " trial " << trial;
    }
  }
}

// The principal stretches are F's singular values, largest first: their
// product is |det F|, their squares sum to tr(F^T F) and their squares'
// pairwise products to the second invariant of C; a rotation changes none.
// The energy density is the material's own psi(F).
TEST(ElementFields, PrincipalStretchesAreTheSingularValuesOfF) {
  const Lame l = compute_lame(kE, kNu);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> d(-0.4, 0.4);
  for (int trial = 0; trial < 200; ++trial) {
    double F[9];
    for (int k = 0; k < 9; ++k) F[k] = (k % 4 == 0 ? 1.0 : 0.0) + d(rng);
    if (trial % 4 == 0) F[1] = F[2] = F[3] = F[5] = F[6] = F[7] = 0, F[4] = F[0];  // two equal stretches
    const TetFields f = compute_tet_fields(MaterialModel::NeoHookean, F, l.lambda, l.mu);
    const double* s = f.stretches;
    EXPECT_GE(s[0], s[1]);
    EXPECT_GE(s[1], s[2]);
    double C[9];
    material::mul_tn(F, F, C);
    const double I1 = C[0] + C[4] + C[8];
    const double I2 = C[0] * C[4] + C[4] * C[8] + C[0] * C[8] - C[1] * C[3] - C[2] * C[6] - C[5] * C[7];
    EXPECT_NEAR(s[0] * s[1] * s[2], std::fabs(material::det(F)), 1e-9) << trial;
    EXPECT_NEAR(s[0] * s[0] + s[1] * s[1] + s[2] * s[2], I1, 1e-9) << trial;
    const double a = s[0] * s[0], b = s[1] * s[1], c = s[2] * s[2];
    EXPECT_NEAR(a * b + b * c + a * c, I2, 1e-8) << trial;
    double P[9];
    EXPECT_EQ(f.energy_density, material::stress(MaterialModel::NeoHookean, F, l.lambda, l.mu, P));
  }
  double F[9];
  to_rows(test::make_rotation(Vec3(0, 1, 1), 0.7) * glm::dmat3(1.3, 0, 0, 0, 0.8, 0, 0, 0, 1.1), F);
  const TetFields f = compute_tet_fields(MaterialModel::StVK, F, l.lambda, l.mu);
  EXPECT_NEAR(f.stretches[0], 1.3, 1e-12);
  EXPECT_NEAR(f.stretches[1], 1.1, 1e-12);
  EXPECT_NEAR(f.stretches[2], 0.8, 1e-12);
  const double rest[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  const TetFields r = compute_tet_fields(MaterialModel::StVK, rest, l.lambda, l.mu);
  for (double x : r.stretches) EXPECT_EQ(x, 1.0);
  EXPECT_EQ(r.energy_density, 0.0);
}

// On a model: a homogeneous deformation u = (F - I) X gives every tet that F's
// fields, in float and double, whatever the model's node numbering; only the
// fields asked for are made.
template <class Real>
void check_homogeneous_deformation() {
  ModelSpec spec;
  spec.mesh = test::make_jittered_box(Vec3(0.0), Vec3(0.3, 0.2, 0.1), {4, 3, 2}, 0.2);
  spec.materials = {MaterialSpec{MaterialModel::NeoHookean, kE, kNu, 1000}};
  const Model<Real> model = build_model<Real>(spec);
  State<Real> s;
  s.u.assign(3 * size_t(model.n_nodes), Real(0));
  const glm::dmat3 G =
      test::make_rotation(Vec3(0, 0, 1), 0.4) * glm::dmat3(1.2, 0.05, 0.0, 0.0, 0.9, 0.1, 0.0, 0.0, 1.0);
  for (int32_t i = 0; i < model.n_nodes; ++i) {
    const Vec3 X = model.mesh.X[size_t(i)];
    const Vec3 u = G * X - X;
    for (int c = 0; c < 3; ++c) s.u[3 * size_t(i) + size_t(c)] = Real(u[c]);
  }
  double F[9];
  to_rows(G, F);
  const Lame l = compute_lame(kE, kNu);
  const TetFields want = compute_tet_fields(MaterialModel::NeoHookean, F, l.lambda, l.mu);
  const double tol = sizeof(Real) == 4 ? 2e-4 : 1e-9;  // u rounded to Real over cells of 0.05 m
  const ElementFields all = compute_element_fields(model, s, {true, true, true});
  ASSERT_EQ(all.cauchy_stress.size(), 9 * size_t(model.n_tets));
  for (size_t e = 0; e < size_t(model.n_tets); ++e) {
    for (int k = 0; k < 9; ++k) {
      EXPECT_NEAR(all.green_strain[9 * e + size_t(k)], want.green[k], tol) << e;
      EXPECT_NEAR(all.cauchy_stress[9 * e + size_t(k)], want.cauchy[k], tol * kE) << e;
    }
    EXPECT_NEAR(all.von_mises[e], want.von_mises, tol * kE) << e;
  }
  const ElementFields some = compute_element_fields(model, s, {false, true, false});
  EXPECT_TRUE(some.cauchy_stress.empty());
  EXPECT_TRUE(some.von_mises.empty());
  EXPECT_EQ(some.green_strain, all.green_strain);
  const ElementFields none = compute_element_fields(model, s, {});
  EXPECT_TRUE(none.cauchy_stress.empty() && none.green_strain.empty() && none.von_mises.empty());
  // The tets listed, in their order: the same rows as the whole model's.
  const std::vector<int32_t> listed = {int32_t(model.n_tets) - 1, 0, 3};
  const ElementFields part = compute_element_fields(model, s, {.von_mises = true, .principal_stretches = true}, listed);
  ASSERT_EQ(part.von_mises.size(), listed.size());
  ASSERT_EQ(part.principal_stretches.size(), 3 * listed.size());
  for (size_t i = 0; i < listed.size(); ++i) {
    EXPECT_EQ(part.von_mises[i], all.von_mises[size_t(listed[i])]);
    EXPECT_NEAR(part.principal_stretches[3 * i], want.stretches[0], tol);
    EXPECT_NEAR(part.principal_stretches[3 * i + 2], want.stretches[2], tol);
  }
}

TEST(ElementFields, HomogeneousDeformationGivesEveryTetItsFieldsDouble) { check_homogeneous_deformation<double>(); }
TEST(ElementFields, HomogeneousDeformationGivesEveryTetItsFieldsFloat) { check_homogeneous_deformation<float>(); }

}  // namespace
}  // namespace tactile
