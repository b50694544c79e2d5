// The per-ISA kernels against straightforward scalar code in double: element
// forces and energies of every material (from the core/material.hpp
// functions, one tet at a time), the predictor and its padded copy, and the
// corrector, and the critical-step estimate; padding lanes add nothing; the
// ISA copies agree with each other.
#include "core/kernels/kernels.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include <glm/geometric.hpp>
#include <glm/mat3x3.hpp>
#include <glm/matrix.hpp>

#include "core/model.hpp"

namespace tactile {
namespace {

constexpr MaterialModel kModels[] = {MaterialModel::Linear, MaterialModel::StVK, MaterialModel::Corotational,
                                     MaterialModel::NeoHookean, MaterialModel::InvertibleStVK};
constexpr const char* kIsas[] = {"baseline", "v3", "v4"};

// A 3 x 2 x 1 grid of jittered cells, 6 tets each: 36 tets, so that blocks of
// 16 (float) and 8 (double) both end in padding lanes. Two regions with
// different stiffness, so that per-lane material constants matter.
ModelSpec make_random_spec(MaterialModel model, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  TetMesh mesh;
  const int nx = 3, ny = 2, nz = 1;
  auto id = [&](int i, int j, int k) { return int32_t(i + (nx + 1) * (j + (ny + 1) * k)); };
  for (int k = 0; k <= nz; ++k)
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i)
        mesh.X.emplace_back(0.1 * i + 0.02 * unit(rng), 0.1 * j + 0.02 * unit(rng), 0.1 * k + 0.02 * unit(rng));
  static constexpr int kPerm[6][3] = {{0, 1, 2}, {1, 2, 0}, {2, 0, 1}, {0, 2, 1}, {2, 1, 0}, {1, 0, 2}};
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i)
        for (const auto& perm : kPerm) {
          int c[3] = {i, j, k};
          Tet t{};
          t[0] = id(c[0], c[1], c[2]);
          for (int s = 0; s < 3; ++s) {
            ++c[perm[s]];
            t[size_t(s + 1)] = id(c[0], c[1], c[2]);
          }
          const Vec3 &a = mesh.X[size_t(t[0])], &b = mesh.X[size_t(t[1])], &d = mesh.X[size_t(t[2])],
                     &e = mesh.X[size_t(t[3])];
          if (compute_tet_volume(a, b, d, e) < 0) std::swap(t[1], t[2]);
          mesh.tets.push_back(t);
          mesh.region.push_back(int32_t(mesh.tets.size() % 2));
        }
  ModelSpec spec;
  spec.mesh = std::move(mesh);
  spec.materials = {MaterialSpec{model, 1e5, 0.3, 1000}, MaterialSpec{model, 3e5, 0.45, 1200}};
  return spec;
}

// Displacements of up to `amplitude` m per component (n_nodes x 3).
std::vector<double> make_random_u(int32_t n_nodes, double amplitude, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::vector<double> u(3 * size_t(n_nodes));
  for (double& x : u) x = amplitude * unit(rng);
  return u;
}

struct Forces {
  std::vector<double> f;  // (n_nodes x 3) [N]
  double energy = 0;      // [J]
};

// The reference: one tet at a time in double, F = I + [u1-u0 u2-u0 u3-u0] Dm^-1,
// P and psi from core/material.hpp, f_a = -V P grad N_a.
Forces compute_reference(const ModelSpec& spec, const std::vector<double>& u) {
  const TetMesh& mesh = spec.mesh;
  Forces out;
  out.f.assign(3 * mesh.X.size(), 0.0);
  for (size_t e = 0; e < mesh.tets.size(); ++e) {
    const Tet& t = mesh.tets[e];
    const MaterialSpec& mat = spec.materials[size_t(mesh.region_of(int32_t(e)))];
    const Lame lame = compute_lame(mat.E, mat.nu);
    Vec3 X[4], du[4];
    for (int c = 0; c < 4; ++c) {
      X[c] = mesh.X[size_t(t[size_t(c)])];
      const size_t n = 3 * size_t(t[size_t(c)]);
      du[c] = Vec3(u[n], u[n + 1], u[n + 2]);
    }
    const glm::dmat3 Dm(X[1] - X[0], X[2] - X[0], X[3] - X[0]);
    const glm::dmat3 Du(du[1] - du[0], du[2] - du[0], du[3] - du[0]);
    const glm::dmat3 Dinv = glm::inverse(Dm);
    const glm::dmat3 Fg = glm::dmat3(1.0) + Du * Dinv;
    double F[9], P[9] = {};
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) F[3 * i + j] = Fg[j][i];
    const double V = compute_tet_volume(X[0], X[1], X[2], X[3]);
    out.energy += V * material::stress(mat.model, F, lame.lambda, lame.mu, P);
    // grad N_a (a = 1..3) is row a-1 of Dm^-1; grad N_0 = -(sum of the others).
    for (int a = 1; a < 4; ++a) {
      for (int i = 0; i < 3; ++i) {
        double h = 0;
        for (int j = 0; j < 3; ++j) h -= V * P[3 * i + j] * Dinv[j][a - 1];
        out.f[3 * size_t(t[size_t(a)]) + size_t(i)] += h;
        out.f[3 * size_t(t[0]) + size_t(i)] -= h;
      }
    }
  }
  return out;
}

// The kernel of one ISA over all groups of a model, with u and f in the
// mesh's node numbering (the model's own is translated through node_model).
template <class Real>
Forces compute_kernel(const KernelTable<Real>& k, const Model<Real>& model, const std::vector<double>& u) {
  std::vector<Node4<Real>> u4(size_t(model.n_nodes)), f4(size_t(model.n_nodes));
  for (size_t i = 0; i < u4.size(); ++i)
    u4[size_t(model.node_model[i])] = Node4<Real>{{Real(u[3 * i]), Real(u[3 * i + 1]), Real(u[3 * i + 2]), 0}};
  Forces out;
  for (const ElementGroup& g : model.groups)
    out.energy +=
        k.forces[int(g.model)](model.blocks.data(), g.begin, g.end, Real(g.lambda), Real(g.mu), u4.data(), f4.data())
            .energy;
  out.f.resize(3 * u4.size());
  for (size_t i = 0; i < f4.size(); ++i) {
    const Node4<Real>& fi = f4[size_t(model.node_model[i])];
    for (int c = 0; c < 3; ++c) out.f[3 * i + size_t(c)] = double(fi.v[c]);
    EXPECT_EQ(fi.v[3], Real(0)) << "node " << i << ": the padding entry was written";
  }
  return out;
}

double max_abs(const std::vector<double>& a) {
  double m = 0;
  for (double x : a) m = std::max(m, std::fabs(x));
  return m;
}
double max_abs_diff(const std::vector<double>& a, const std::vector<double>& b) {
  double m = 0;
  for (size_t k = 0; k < a.size(); ++k) m = std::max(m, std::fabs(a[k] - b[k]));
  return m;
}

template <class Real>
constexpr double kRoundOff = sizeof(Real) == 4 ? 2e-5 : 1e-11;  // relative, with the cancellation of F - I

template <class Real>
void check_forces_against_reference() {
  for (MaterialModel model : kModels) {
    const ModelSpec spec = make_random_spec(model, 11);
    const Model<Real> m = build_model<Real>(spec);
    ASSERT_NE(std::count(m.lane_tet.begin(), m.lane_tet.end(), -1), 0) << "the mesh should leave padding lanes";
    // Strains of about 10 %: large enough for the nonlinear terms to count.
    const std::vector<double> u = make_random_u(m.n_nodes, 0.006, 5);
    const Forces ref = compute_reference(spec, u);
    ASSERT_GT(max_abs(ref.f), 0.0);
    for (const char* isa : kIsas) {
      const KernelTable<Real>* k = kernels_for<Real>(isa);
      if (!k) continue;  // not on this CPU
      const Forces got = compute_kernel(*k, m, u);
      const double scale = max_abs(ref.f);
      EXPECT_LE(max_abs_diff(got.f, ref.f), kRoundOff<Real> * scale)
          << to_string(model) << " " << isa << " " << (sizeof(Real) == 4 ? "float" : "double");
      EXPECT_NEAR(got.energy, ref.energy, kRoundOff<Real> * std::fabs(ref.energy)) << to_string(model) << " " << isa;
    }
  }
}

TEST(Kernels, ForcesAndEnergyEqualScalarReferenceFloat) { check_forces_against_reference<float>(); }
TEST(Kernels, ForcesAndEnergyEqualScalarReferenceDouble) { check_forces_against_reference<double>(); }

// The SVD's models (invertible StVK, corotational) take the SVD only in
// blocks with a lane near the floor, and only for those lanes, one by one
// for a lane or two and for whole blocks, two at a time, beyond: crushed
// and inverted elements among mildly strained ones (blocks of each kind,
// and blocks that mix them) give the forces and energy of the scalar
// function on every element.
template <class Real>
void check_svd_mixed_blocks(MaterialModel model) {
  const ModelSpec spec = make_random_spec(model, 11);
  const Model<Real> m = build_model<Real>(spec);
  constexpr int W = kLanes<Real>;
  for (double amplitude : {0.02, 0.03, 0.05}) {
    const std::vector<double> u = make_random_u(m.n_nodes, amplitude, 7);
    int near = 0, inverted = 0;
    std::vector<char> flagged(spec.mesh.tets.size(), 0);
    for (const Tet& t : spec.mesh.tets) {  // how many elements the SVD path serves
      Vec3 X[4], x[4];
      for (int c = 0; c < 4; ++c) {
        const size_t n = size_t(t[size_t(c)]);
        X[c] = spec.mesh.X[n];
        x[c] = X[c] + Vec3(u[3 * n], u[3 * n + 1], u[3 * n + 2]);
      }
      const glm::dmat3 Fg = glm::dmat3(x[1] - x[0], x[2] - x[0], x[3] - x[0]) *
                            glm::inverse(glm::dmat3(X[1] - X[0], X[2] - X[0], X[3] - X[0]));
      double F[9];
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) F[3 * i + j] = Fg[j][i];
      near += material::reaches_floor(F);
      inverted += material::det(F) <= 0;
      flagged[size_t(&t - spec.mesh.tets.data())] = material::may_reach_floor(F) != 0;
    }
    // Blocks whose flagged lanes take the SVD as a whole block (more than two).
    int whole_blocks = 0;
    for (size_t b = 0; b * W < m.lane_tet.size(); ++b) {
      int n = 0;
      for (int l = 0; l < W; ++l) {
        const int32_t e = m.lane_tet[b * W + size_t(l)];
        n += e >= 0 && flagged[size_t(e)];
      }
      whole_blocks += n > 2;
    }
    const Forces ref = compute_reference(spec, u);
    for (const char* isa : kIsas) {
      const KernelTable<Real>* k = kernels_for<Real>(isa);
      if (!k) continue;
      const Forces got = compute_kernel(*k, m, u);
      EXPECT_LE(max_abs_diff(got.f, ref.f), kRoundOff<Real> * max_abs(ref.f))
          << to_string(model) << " amplitude " << amplitude << " " << isa << ": " << near << " of "
          << spec.mesh.tets.size() << " elements near the floor, " << inverted << " inverted, " << whole_blocks
          << " whole blocks";
      EXPECT_NEAR(got.energy, ref.energy, kRoundOff<Real> * std::fabs(ref.energy))
          << to_string(model) << " amplitude " << amplitude;
    }
    if (amplitude == 0.05) {
      EXPECT_GT(inverted, 0) << "the test should invert some elements";
      EXPECT_LT(near, int(spec.mesh.tets.size())) << "the test should leave some elements far from the floor";
      EXPECT_GE(whole_blocks, 3) << "the test should pair blocks for the SVD, and leave one to run alone";
    }
  }
}

TEST(Kernels, SvdModelsTakeTheSvdWhereItIsNeededFloat) {
  check_svd_mixed_blocks<float>(MaterialModel::InvertibleStVK);
  check_svd_mixed_blocks<float>(MaterialModel::Corotational);
}
TEST(Kernels, SvdModelsTakeTheSvdWhereItIsNeededDouble) {
  check_svd_mixed_blocks<double>(MaterialModel::InvertibleStVK);
  check_svd_mixed_blocks<double>(MaterialModel::Corotational);
}

template <class Real>
void check_isas_agree() {
  for (MaterialModel model : kModels) {
    const ModelSpec spec = make_random_spec(model, 23);
    const Model<Real> m = build_model<Real>(spec);
    const std::vector<double> u = make_random_u(m.n_nodes, 0.006, 9);
    const KernelTable<Real>* base = kernels_for<Real>("baseline");
    ASSERT_NE(base, nullptr) << "every x86-64 CPU this builds for runs the baseline";
    const Forces a = compute_kernel(*base, m, u);
    for (const char* isa : {"v3", "v4"}) {
      const KernelTable<Real>* k = kernels_for<Real>(isa);
      if (!k) continue;
      const Forces b = compute_kernel(*k, m, u);
      // The same arithmetic up to contraction into FMAs and the order of adds.
      EXPECT_LE(max_abs_diff(a.f, b.f), 0.5 * kRoundOff<Real> * max_abs(a.f)) << to_string(model) << " " << isa;
      EXPECT_NEAR(a.energy, b.energy, 0.5 * kRoundOff<Real> * std::fabs(a.energy)) << to_string(model) << " " << isa;
    }
  }
}

TEST(Kernels, IsaCopiesAgreeFloat) { check_isas_agree<float>(); }
TEST(Kernels, IsaCopiesAgreeDouble) { check_isas_agree<double>(); }

// Padding lanes: no energy, det F = 1, and nothing added to the node they
// point at (one node for all four corners), whatever the displacements.
template <class Real>
void check_padding() {
  for (MaterialModel model : kModels) {
    const ModelSpec spec = make_random_spec(model, 3);
    const Model<Real> m = build_model<Real>(spec);
    std::vector<Real> u(3 * size_t(m.n_nodes));
    for (size_t k = 0; k < u.size(); ++k) u[k] = Real(0.004 * std::sin(double(k)));
    for (const char* isa : kIsas) {
      const KernelTable<Real>* k = kernels_for<Real>(isa);
      if (!k) continue;
      std::vector<double> energy(m.blocks.size() * size_t(kLanes<Real>));
      std::vector<Real> J(energy.size());
      for (const ElementGroup& g : m.groups)
        k->energy[int(g.model)](m.blocks.data(), g.begin, g.end, Real(g.lambda), Real(g.mu), u.data(),
                                energy.data() + size_t(g.begin) * kLanes<Real>,
                                J.data() + size_t(g.begin) * kLanes<Real>);
      int padding = 0;
      for (size_t lane = 0; lane < energy.size(); ++lane) {
        if (m.lane_tet[lane] >= 0) continue;
        ++padding;
        EXPECT_EQ(energy[lane], 0.0) << to_string(model) << " " << isa << " lane " << lane;
        EXPECT_EQ(J[lane], Real(1)) << to_string(model) << " " << isa << " lane " << lane;
      }
      EXPECT_GT(padding, 0);
      // Forces of the padding lanes alone: blocks with every real lane's volume zeroed.
      std::vector<ElementBlock<Real>> only_padding = m.blocks;
      for (size_t b = 0; b < only_padding.size(); ++b)
        for (int l = 0; l < kLanes<Real>; ++l)
          if (m.lane_tet[b * kLanes<Real> + size_t(l)] >= 0) only_padding[b].V[l] = 0;
      std::vector<Node4<Real>> u4(size_t(m.n_nodes)), f4(size_t(m.n_nodes));
      for (size_t i = 0; i < u4.size(); ++i) u4[i] = Node4<Real>{{u[3 * i], u[3 * i + 1], u[3 * i + 2], 0}};
      double e = 0;
      for (const ElementGroup& g : m.groups)
        e += k->forces[int(g.model)](only_padding.data(), g.begin, g.end, Real(g.lambda), Real(g.mu), u4.data(),
                                     f4.data())
                 .energy;
      EXPECT_EQ(e, 0.0);
      for (size_t i = 0; i < f4.size(); ++i)
        for (int c = 0; c < 4; ++c) EXPECT_EQ(f4[i].v[c], Real(0)) << to_string(model) << " " << isa << " node " << i;
    }
  }
}

// The critical-step kernel against the scalar estimate in double, from
// positions: the smallest altitude by cross products (not the kernel's
// cofactors), over the rest one, clamped to [0.05, 1], over the square root
// of material::stiffening; the rest step as is for linear elements. Block by
// block, each against the least of its lanes: at small strains, at strains
// that squash and turn some elements inside out, and with a NaN.
double reference_critical_dt(const ModelSpec& spec, const std::vector<double>& tet_dt, double dt_rest,
                             const std::vector<double>& u, int32_t e) {
  const MaterialModel model = spec.materials[size_t(spec.mesh.region_of(e))].model;
  if (model == MaterialModel::Linear) return dt_rest;
  const Tet& t = spec.mesh.tets[size_t(e)];
  Vec3 X[4], x[4];
  for (int c = 0; c < 4; ++c) {
    const size_t i = size_t(t[size_t(c)]);
    X[c] = spec.mesh.X[i];
    x[c] = X[c] + Vec3(u[3 * i], u[3 * i + 1], u[3 * i + 2]);
  }
  auto altitude = [](const Vec3* p) {
    const double V6 = std::fabs(glm::determinant(glm::dmat3(p[1] - p[0], p[2] - p[0], p[3] - p[0])));
    const double amax = std::max(
        {glm::length(glm::cross(p[2] - p[1], p[3] - p[1])), glm::length(glm::cross(p[2] - p[0], p[3] - p[0])),
         glm::length(glm::cross(p[1] - p[0], p[3] - p[0])), glm::length(glm::cross(p[1] - p[0], p[2] - p[0]))});
    return V6 / amax;
  };
  const double ratio = std::clamp(altitude(x) / altitude(X), 0.05, 1.0);
  const glm::dmat3 Fg = glm::dmat3(x[1] - x[0], x[2] - x[0], x[3] - x[0]) *
                        glm::inverse(glm::dmat3(X[1] - X[0], X[2] - X[0], X[3] - X[0]));
  double F[9];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) F[3 * i + j] = Fg[j][i];
  return tet_dt[size_t(e)] * ratio / std::sqrt(material::stiffening(model, F));
}

template <class Real>
void check_critical_dt() {
  for (MaterialModel model : kModels) {
    const ModelSpec spec = make_random_spec(model, 17);
    const Model<Real> m = build_model<Real>(spec);
    const Model<double> ref = build_model<double>(spec);  // the rest steps in double (tets keep their ids)
    int squashed = 0, inverted = 0;
    for (double amplitude : {0.002, 0.05}) {
      const std::vector<double> u = make_random_u(m.n_nodes, amplitude, 23);  // the mesh's numbering
      std::vector<Real> u_real(u.size());                                     // the model's
      for (size_t i = 0; i < size_t(m.n_nodes); ++i)
        for (size_t c = 0; c < 3; ++c) u_real[3 * size_t(m.node_model[i]) + c] = Real(u[3 * i + c]);
      for (const char* isa : kIsas) {
        const KernelTable<Real>* k = kernels_for<Real>(isa);
        if (!k) continue;
        for (const ElementGroup& g : m.groups)
          for (int32_t b = g.begin; b < g.end; ++b) {
            double want = std::numeric_limits<double>::infinity();
            for (int l = 0; l < kLanes<Real>; ++l) {
              const int32_t e = m.lane_tet[size_t(b) * kLanes<Real> + size_t(l)];
              if (e < 0) continue;
              want = std::min(want, reference_critical_dt(spec, ref.tet_dt, ref.dt_rest, u, e));
            }
            double got = k->critical[int(g.model)](m.blocks.data(), b, b + 1, u_real.data(), m.lane_dt.data());
            if (model == MaterialModel::Linear) {
              EXPECT_EQ(got, std::numeric_limits<double>::infinity()) << isa << " block " << b;
              continue;
            }
            EXPECT_NEAR(got, want, (sizeof(Real) == 4 ? 2e-6 : 1e-12) * want)
                << to_string(model) << " " << isa << " block " << b << " amplitude " << amplitude;
            if (std::string(isa) == "baseline") squashed += want < 0.9 * m.dt_rest;
          }
      }
      if (amplitude > 0.01) {
        std::vector<Real> J(m.blocks.size() * kLanes<Real>);
        std::vector<double> energy(J.size());
        for (const ElementGroup& g : m.groups)
          kernels<Real>().energy[int(g.model)](m.blocks.data(), g.begin, g.end, Real(g.lambda), Real(g.mu),
                                               u_real.data(), energy.data() + size_t(g.begin) * kLanes<Real>,
                                               J.data() + size_t(g.begin) * kLanes<Real>);
        for (size_t l = 0; l < J.size(); ++l) inverted += m.lane_tet[l] >= 0 && J[l] <= 0;
      }
    }
    if (model != MaterialModel::Linear) {
      EXPECT_GT(squashed, 0) << to_string(model) << ": no block's step fell below 0.9 of the rest one";
      EXPECT_GT(inverted, 0) << to_string(model) << ": the large strains turned no element inside out";
    }
    // A NaN displacement is the guards' to report: its lanes drop out of the least.
    std::vector<Real> u_nan(3 * size_t(m.n_nodes), Real(0));
    u_nan[0] = std::numeric_limits<Real>::quiet_NaN();
    for (const ElementGroup& g : m.groups) {
      const double got =
          kernels<Real>().critical[int(g.model)](m.blocks.data(), g.begin, g.end, u_nan.data(), m.lane_dt.data());
      EXPECT_FALSE(std::isnan(got)) << to_string(model);
      if (model != MaterialModel::Linear) {
        EXPECT_GT(got, 0.0) << to_string(model);
      }
    }
  }
}
TEST(Kernels, CriticalStepEqualsScalarReferenceFloat) { check_critical_dt<float>(); }
TEST(Kernels, CriticalStepEqualsScalarReferenceDouble) { check_critical_dt<double>(); }

TEST(Kernels, PaddingLanesContributeNothingFloat) { check_padding<float>(); }
TEST(Kernels, PaddingLanesContributeNothingDouble) { check_padding<double>(); }

// The node passes on 37 nodes (a remainder after whole vectors), every ISA.
template <class Real>
void check_node_passes() {
  constexpr int32_t n = 37;
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::vector<Real> u0(3 * n), v0(3 * n), a0(3 * n), m(n), inv_m(n);
  for (auto* arr : {&u0, &v0, &a0})
    for (Real& x : *arr) x = Real(unit(rng));
  for (int32_t i = 0; i < n; ++i) {
    m[size_t(i)] = Real(1.5 + unit(rng));
    inv_m[size_t(i)] = Real(1) / m[size_t(i)];
  }
  const Real dt = Real(1e-3);
  const double tol = sizeof(Real) == 4 ? 1e-6 : 1e-14;
  for (const char* isa : kIsas) {
    const KernelTable<Real>* k = kernels_for<Real>(isa);
    if (!k) continue;
    // Predictor, eq. (7), over nodes [3, n): nodes before 3 untouched.
    std::vector<Real> u = u0, v = v0;
    std::vector<Node4<Real>> u4(n, Node4<Real>{{-7, -7, -7, -7}});
    k->predict(3, n, dt, u.data(), v.data(), a0.data(), u4.data());
    for (size_t j = 0; j < 3 * size_t(n); ++j) {
      const bool moved = j >= 9;
      const double du = moved ? double(dt) * v0[j] + 0.5 * double(dt) * double(dt) * a0[j] : 0.0;
      const double dv = moved ? 0.5 * double(dt) * a0[j] : 0.0;
      EXPECT_NEAR(u[j], double(u0[j]) + du, tol) << isa << " u " << j;
      EXPECT_NEAR(v[j], double(v0[j]) + dv, tol) << isa << " v " << j;
    }
    for (int32_t i = 0; i < n; ++i)
      for (int c = 0; c < 4; ++c) {
        const Real want = i < 3 ? Real(-7) : c < 3 ? u[3 * size_t(i) + size_t(c)] : Real(0);
        EXPECT_EQ(u4[size_t(i)].v[c], want) << isa << " u4 " << i << "." << c;
      }
    // Corrector, eqs. (8)-(10), two parts, each of the four effect combinations.
    for (int gravity = 0; gravity < 2; ++gravity)
      for (int damping = 0; damping < 2; ++damping) {
        const int64_t stride = n + 3;
        std::vector<Node4<Real>> f(2 * size_t(stride));  // the 3 nodes past n in each part stay 0
        for (int p = 0; p < 2; ++p)
          for (int32_t i = 0; i < n; ++i)
            f[size_t(p * stride + i)] = Node4<Real>{{Real(unit(rng)), Real(unit(rng)), Real(unit(rng)), 0}};
        const std::vector<Node4<Real>> f_in = f;
        CorrectArgs<Real> args{};
        args.begin = 0;
        args.end = n;
        args.dt = dt;
        // Array 1 holds nodes [16, 48) only: its entries below 16 are not forces.
        const int32_t group_begin[4] = {0, 1, 3, 5};  // per 16 nodes
        const int64_t group_offset[5] = {0, 0, stride, 0, stride};
        args.f = f.data();
        args.group_begin = group_begin;
        args.group_offset = group_offset;
        args.inv_m = inv_m.data();
        args.m = m.data();
        args.g[0] = Real(0.5);
        args.g[1] = Real(-9.81);
        args.g[2] = Real(0.25);
        args.alpha = Real(3);
        std::vector<Real> vc = v0, ac = a0;
        args.u = u0.data();
        args.v = vc.data();
        args.a = ac.data();
        const CorrectSums sums = k->correct[gravity][damping](args);
        double abs_a = 0, mv2 = 0, mgu = 0, ma2 = 0;
        const double alpha = damping ? 3.0 : 0.0, q = 1.0 + 0.5 * alpha * double(dt);
        for (int32_t i = 0; i < n; ++i)
          for (int c = 0; c < 3; ++c) {
            const size_t j = 3 * size_t(i) + size_t(c);
            const double fj = double(f_in[size_t(i)].v[c]) + (i >= 16 ? double(f_in[size_t(i + stride)].v[c]) : 0.0);
            const double g = gravity ? double(args.g[c]) : 0.0;
            const double acc = (fj / double(m[size_t(i)]) + g - alpha * double(v0[j])) / q;
            const double vn = double(v0[j]) + 0.5 * double(dt) * acc;
            EXPECT_NEAR(ac[j], acc, tol * 20 * (1 + std::fabs(acc))) << isa << " a " << j;
            EXPECT_NEAR(vc[j], vn, tol * (1 + std::fabs(vn))) << isa << " v " << j;
            abs_a += std::fabs(acc);
            mv2 += double(m[size_t(i)]) * vn * vn;
            ma2 += double(m[size_t(i)]) * acc * acc;
            mgu += double(m[size_t(i)]) * g * double(u0[j]);
          }
        EXPECT_NEAR(sums.abs_a, abs_a, 1e3 * tol * abs_a) << isa;
        EXPECT_NEAR(sums.mv2, mv2, 1e3 * tol * mv2) << isa;
        EXPECT_NEAR(sums.ma2, ma2, 1e3 * tol * ma2) << isa;
        EXPECT_NEAR(sums.mgu, mgu, 1e3 * tol * (1 + std::fabs(mgu))) << isa;
        // Every entry read is cleared (part 0's over [0, n), part 1's over
        // [16, n)); the rest is left as it was.
        for (size_t j = 0; j < f.size(); ++j) {
          const int64_t i = int64_t(j) % stride;  // node
          const bool read = i < n && (int64_t(j) < stride || i >= 16);
          for (int c = 0; c < 4; ++c)
            EXPECT_EQ(f[j].v[c], read ? Real(0) : f_in[j].v[c]) << isa << ": entry " << j << " of the force arrays";
        }
      }
  }
}

TEST(Kernels, NodePassesEqualScalarReferenceFloat) { check_node_passes<float>(); }
TEST(Kernels, NodePassesEqualScalarReferenceDouble) { check_node_passes<double>(); }

}  // namespace
}  // namespace tactile
