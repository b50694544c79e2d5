#include "core/model.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "core/fem_fixtures.hpp"
#include "mesh/primitives.hpp"

namespace tactile {
namespace {

using test::make_jittered_box;
using test::make_regular_tet;
using test::make_spec;

// The message of the ModelError build_model throws, or "" if it builds.
std::string build_error(const ModelSpec& spec) {
  try {
    (void)build_model<double>(spec);
  } catch (const ModelError& e) {
    return e.what();
  }
  return "";
}

TetMesh make_two_region_box() {
  TetMesh mesh = make_box(Vec3(0.0), Vec3(1.0, 0.5, 0.5), {4, 2, 2});
  mesh.region.resize(mesh.tets.size());
  for (size_t e = 0; e < mesh.tets.size(); ++e) {
    const Tet& t = mesh.tets[e];
    const double cx =
        0.25 * (mesh.X[size_t(t[0])].x + mesh.X[size_t(t[1])].x + mesh.X[size_t(t[2])].x + mesh.X[size_t(t[3])].x);
    mesh.region[e] = cx < 0.5 ? 0 : 1;
  }
  return mesh;
}

TEST(BuildModel, RefusesInvertedAndDegenerateTetsNamingThem) {
  {
    ModelSpec spec = make_spec(make_box(Vec3(0.0), Vec3(1.0), {2, 2, 2}), MaterialModel::StVK);
    std::swap(spec.mesh.tets[5][1], spec.mesh.tets[5][2]);
    std::swap(spec.mesh.tets[17][0], spec.mesh.tets[17][3]);
    const std::string err = build_error(spec);
    EXPECT_NE(err.find("2 inverted"), std::string::npos) << err;
    EXPECT_NE(err.find("5, 17"), std::string::npos) << err;
  }
  {
    ModelSpec spec = make_spec(make_regular_tet(), MaterialModel::Linear);
    spec.mesh.X.push_back(Vec3(0.5, 0.5, 0.0));  // in the plane of nodes 0, 1 and a 4th at (1, 0, 0)
    spec.mesh.X.push_back(Vec3(1.0, 0.0, 0.0));
    spec.mesh.tets.push_back({0, 1, 4, 5});
    const std::string err = build_error(spec);
    EXPECT_NE(err.find("degenerate"), std::string::npos) << err;
    EXPECT_NE(err.find("ids 1)"), std::string::npos) << err;
  }
}

TEST(BuildModel, RefusesBadMaterialsNamingTheField) {
  struct Case {
    double E, nu, rho;
    const char* field;
  };
  const Case cases[] = {{0.0, 0.3, 1000, "materials[1].E"},  {-1e5, 0.3, 1000, "materials[1].E"},
                        {NAN, 0.3, 1000, "materials[1].E"},  {1e5, 0.5, 1000, "materials[1].nu"},
                        {1e5, 0.7, 1000, "materials[1].nu"}, {1e5, -1.0, 1000, "materials[1].nu"},
                        {1e5, 0.3, 0.0, "materials[1].rho"}, {1e5, 0.3, INFINITY, "materials[1].rho"}};
  for (const Case& c : cases) {
    ModelSpec spec = make_spec(make_two_region_box(), MaterialModel::StVK);
    spec.materials.push_back(MaterialSpec{MaterialModel::StVK, c.E, c.nu, c.rho});
    const std::string err = build_error(spec);
    EXPECT_NE(err.find(c.field), std::string::npos) << "expected " << c.field << ", got: " << err;
  }
  ModelSpec spec = make_spec(make_two_region_box(), MaterialModel::StVK);  // one material for two regions
  EXPECT_NE(build_error(spec).find("region 1"), std::string::npos) << build_error(spec);
  spec.materials.push_back(spec.materials[0]);
  EXPECT_EQ(build_error(spec), "");
}

TEST(BuildModel, RefusesSelectionsOfNoNodeNamingThem) {
  ModelSpec spec = make_spec(make_box(Vec3(0.0), Vec3(1.0), {2, 2, 2}), MaterialModel::StVK);
  EssentialBc bc;
  bc.name = "clamp";
  bc.where.kind = NodeSelector::Kind::Plane;
  bc.where.point = Vec3(0, 1.5, 0);  // above the box
  spec.essential = {bc};
  std::string err = build_error(spec);
  EXPECT_NE(err.find("'clamp'"), std::string::npos) << err;
  EXPECT_NE(err.find("selects no node"), std::string::npos) << err;

  spec.essential[0].where.point = Vec3(0, 1.0, 0);  // the top face
  EXPECT_EQ(build_error(spec), "");
  NaturalLoad load;
  load.name = "push";
  load.where.kind = NodeSelector::Kind::Box;
  load.where.lo = Vec3(2.0);
  load.where.hi = Vec3(3.0);
  spec.loads = {load};
  err = build_error(spec);
  EXPECT_NE(err.find("'push'"), std::string::npos) << err;

  spec.loads.clear();
  EssentialBc overlap = spec.essential[0];
  overlap.name = "again";
  spec.essential.push_back(overlap);
  EXPECT_NE(build_error(spec).find("overlap"), std::string::npos);
}

// Section 4.1: each tet gives a quarter of its mass to each corner, so the
// masses sum to rho V, region by region.
TEST(BuildModel, LumpedMassesSumToTheTotalMass) {
  ModelSpec spec = make_spec(make_two_region_box(), MaterialModel::StVK, 1e5, 0.3, 1000);
  spec.materials.push_back(MaterialSpec{MaterialModel::NeoHookean, 2e5, 0.4, 3000});
  const Model<double> model = build_model<double>(spec);
  const double expected = 1000 * 0.5 * 0.25 + 3000 * 0.5 * 0.25;  // two halves of 1 x 0.5 x 0.5
  EXPECT_NEAR(model.total_mass, expected, 1e-12 * expected);
  double sum = 0;
  for (double m : model.m) sum += m;
  EXPECT_NEAR(sum, expected, 1e-12 * expected);
  // Node by node, against an independent accumulation.
  std::vector<double> m(model.m.size(), 0.0);
  for (size_t e = 0; e < spec.mesh.tets.size(); ++e) {
    const Tet& t = spec.mesh.tets[e];
    const double rho = spec.materials[size_t(spec.mesh.region[e])].rho;
    const double V = compute_tet_volume(spec.mesh.X[size_t(t[0])], spec.mesh.X[size_t(t[1])], spec.mesh.X[size_t(t[2])],
                                        spec.mesh.X[size_t(t[3])]);
    for (int32_t i : t) m[size_t(i)] += rho * V / 4;
  }
  for (size_t i = 0; i < m.size(); ++i) {  // i as the mesh numbers it
    const auto k = size_t(model.node_model[i]);
    EXPECT_NEAR(model.m[k], m[i], 1e-12 * m[i]);
    EXPECT_NEAR(model.inv_m[k] * m[i], 1.0, 1e-12);
  }
  // Float models carry the same masses, rounded.
  const Model<float> mf = build_model<float>(spec);
  EXPECT_NEAR(mf.total_mass, expected, 1e-12 * expected);
  for (size_t i = 0; i < m.size(); ++i) EXPECT_NEAR(double(mf.m[size_t(mf.node_model[i])]), m[i], 1e-6 * m[i]);
}

// Groups hold one material each, model and Lame parameters: two models, or
// one model at two stiffnesses, make two groups.
TEST(BuildModel, EveryTetIsInOneLaneOfItsMaterialsGroup) {
  for (const MaterialSpec& second : {MaterialSpec{MaterialModel::Corotational, 1e5, 0.3, 1000},
                                     MaterialSpec{MaterialModel::StVK, 4e5, 0.45, 1000}}) {
    ModelSpec spec = make_spec(make_two_region_box(), MaterialModel::StVK);
    spec.materials.push_back(second);
    const Model<float> model = build_model<float>(spec);
    EXPECT_EQ(model.groups.size(), 2u);
    std::vector<int> seen(size_t(model.n_tets), 0);
    for (const ElementGroup& g : model.groups)
      for (int32_t b = g.begin; b < g.end; ++b)
        for (int l = 0; l < Model<float>::W; ++l) {
          const int32_t e = model.lane_tet[size_t(b) * Model<float>::W + size_t(l)];
          if (e < 0) {
            EXPECT_EQ(model.blocks[size_t(b)].V[l], 0.0f);  // padding: no volume, no force
            continue;
          }
          ++seen[size_t(e)];
          const MaterialSpec& mat = spec.materials[size_t(spec.mesh.region[size_t(e)])];
          const Lame lame = compute_lame(mat.E, mat.nu);
          EXPECT_EQ(g.model, mat.model);
          EXPECT_EQ(g.lambda, lame.lambda);
          EXPECT_EQ(g.mu, lame.mu);
          EXPECT_EQ(model.blocks[size_t(b)].V[l], float(model.tet_volume[size_t(e)]));
        }
    for (int count : seen) EXPECT_EQ(count, 1);
  }
}

// The model numbers nodes in the order its blocks first touch them (part by
// part): a permutation of the mesh's, applied to everything it holds, with
// each part's node-pass range starting where its blocks start numbering
// (rounded to 16 nodes) and the boundary conditions on the same nodes.
template <class Real>
void check_node_numbering() {
  ModelSpec spec = make_spec(make_box(Vec3(0.0), Vec3(0.3, 0.1, 0.1), {30, 8, 8}), MaterialModel::StVK);
  spec.integrator.threads = 2;
  EssentialBc bc;
  bc.where.kind = NodeSelector::Kind::Nodes;
  bc.where.nodes = {5, 77, 400};
  spec.essential = {bc};
  const Model<Real> m = build_model<Real>(spec);
  ASSERT_EQ(m.parts.size(), 2u);
  const auto nn = size_t(m.n_nodes);
  ASSERT_EQ(m.node_model.size(), nn);
  ASSERT_EQ(m.node_given.size(), nn);
  for (size_t i = 0; i < nn; ++i) {
    ASSERT_EQ(size_t(m.node_given[size_t(m.node_model[i])]), i);
    EXPECT_EQ(m.mesh.X[size_t(m.node_model[i])], spec.mesh.X[i]);
  }
  for (size_t e = 0; e < spec.mesh.tets.size(); ++e)
    for (size_t c = 0; c < 4; ++c) EXPECT_EQ(m.mesh.tets[e][c], m.node_model[size_t(spec.mesh.tets[e][c])]);
  std::vector<int32_t> held{m.node_model[5], m.node_model[77], m.node_model[400]};
  std::sort(held.begin(), held.end());
  EXPECT_EQ(m.essential.at(0).nodes, held);
  int32_t next = 0;  // the next number a first touch must give
  for (size_t p = 0; p < m.parts.size(); ++p) {
    const ModelPart& part = m.parts[p];
    EXPECT_EQ(part.node_begin, p == 0 ? 0 : (next + 8) / 16 * 16) << "part " << p;
    for (int32_t b = part.block_begin; b < part.block_end; ++b)
      for (int c = 0; c < 4; ++c)
        for (int l = 0; l < kLanes<Real>; ++l) {
          ASSERT_EQ(m.blocks[size_t(b)].node4[c][l] % 4, 0) << "block " << b;  // 4 x the node's id
          const int32_t id = m.blocks[size_t(b)].node4[c][l] / 4;
          ASSERT_LE(id, next) << "block " << b;
          if (id == next) ++next;
        }
  }
  EXPECT_EQ(size_t(next), nn);
  EXPECT_EQ(m.parts.back().node_end, m.n_nodes);
  EXPECT_EQ(m.parts[0].node_end, m.parts[1].node_begin);
}

TEST(BuildModel, NumbersNodesInTheOrderTheBlocksFirstTouchThemFloat) { check_node_numbering<float>(); }
TEST(BuildModel, NumbersNodesInTheOrderTheBlocksFirstTouchThemDouble) { check_node_numbering<double>(); }

// ---- critical step -----------------------------------------------------------

// The 12 x 12 linear-elastic stiffness of one tet, written from the weak form
// K_(ai)(bj) = V (lambda dN_a/dX_i dN_b/dX_j + mu (dN_a/dX_j dN_b/dX_i + delta_ij grad N_a . grad N_b)),
// independently of the model's Voigt form.
std::array<double, 144> make_tet_stiffness(const std::array<Vec3, 4>& X, double lambda, double mu) {
  const glm::dmat3 Dm(X[1] - X[0], X[2] - X[0], X[3] - X[0]);
  const glm::dmat3 G = glm::transpose(glm::inverse(Dm));  // columns: grad N_1..3
  const double V = std::fabs(glm::determinant(Dm)) / 6;
  std::array<Vec3, 4> g{Vec3(0.0), G[0], G[1], G[2]};
  g[0] = -(g[1] + g[2] + g[3]);
  std::array<double, 144> K{};
  for (int a = 0; a < 4; ++a)
    for (int b = 0; b < 4; ++b)
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
          K[size_t(12 * (3 * a + i) + 3 * b + j)] =
              V * (lambda * g[size_t(a)][i] * g[size_t(b)][j] +
                   mu * (g[size_t(a)][j] * g[size_t(b)][i] + (i == j ? glm::dot(g[size_t(a)], g[size_t(b)]) : 0.0)));
  return K;
}

// Largest eigenvalue of a symmetric positive semi-definite matrix by power
// iteration, run until the residual |K x - lambda x| is at round-off level.
double compute_max_eigenvalue(const std::array<double, 144>& K) {
  std::array<double, 12> x{}, y{};
  for (size_t k = 0; k < 12; ++k) x[k] = (1.0 + 0.1 * double(k)) * (k % 2 ? -1 : 1) / std::sqrt(12.0);
  for (int it = 0; it < 200000; ++it) {
    double lambda = 0, norm = 0;
    for (size_t r = 0; r < 12; ++r) {
      y[r] = 0;
      for (size_t c = 0; c < 12; ++c) y[r] += K[12 * r + c] * x[c];
      lambda += x[r] * y[r];  // Rayleigh quotient, |x| = 1
      norm += y[r] * y[r];
    }
    double residual = 0;
    for (size_t r = 0; r < 12; ++r) residual += (y[r] - lambda * x[r]) * (y[r] - lambda * x[r]);
    if (std::sqrt(residual) <= 1e-11 * lambda) return lambda;
    norm = std::sqrt(norm);
    for (size_t r = 0; r < 12; ++r) x[r] = y[r] / norm;
  }
  ADD_FAILURE() << "power iteration did not converge";
  return 0;
}

TEST(CriticalStep, ElementEstimateMatchesPowerIterationOnTheElementMatrices) {
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> unit(-0.3, 0.3);
  const TetMesh regular = make_regular_tet(0.1);
  for (int trial = 0; trial < 6; ++trial) {
    std::array<Vec3, 4> X{regular.X[0], regular.X[1], regular.X[2], regular.X[3]};
    if (trial > 0)  // irregular tets, still positive
      for (Vec3& p : X) p += 0.1 * Vec3(unit(rng), unit(rng), unit(rng));
    if (compute_tet_volume(X[0], X[1], X[2], X[3]) < 0) std::swap(X[1], X[2]);
    const double E = 2e5, nu = trial % 2 ? 0.45 : 0.3, rho = 1100;
    const Lame l = compute_lame(E, nu);
    const double V = compute_tet_volume(X[0], X[1], X[2], X[3]);
    const double m_node = rho * V / 4;  // lumped: M = m_node I
    const double k_max = compute_max_eigenvalue(make_tet_stiffness(X, l.lambda, l.mu));
    const double expected = 2.0 / std::sqrt(k_max / m_node);
    const double dt = compute_element_critical_dt(X[0], X[1], X[2], X[3], l.lambda, l.mu, rho);
    EXPECT_NEAR(dt, expected, 1e-9 * expected) << "trial " << trial;
  }
}

// The weak-form stiffness above is the Jacobian of the kernels' linear
// forces (so the comparison above is about the model's own elements).
TEST(CriticalStep, ElementStiffnessIsTheJacobianOfTheKernelForces) {
  ModelSpec spec = make_spec(make_regular_tet(0.1), MaterialModel::Linear, 2e5, 0.3, 1100);
  spec.mesh.X[2] += Vec3(0.01, -0.02, 0.015);
  const Model<double> model = build_model<double>(spec);
  std::array<Vec3, 4> X;
  for (size_t a = 0; a < 4; ++a) X[a] = spec.mesh.X[size_t(spec.mesh.tets[0][a])];
  const Lame l = compute_lame(2e5, 0.3);
  const std::array<double, 144> K = make_tet_stiffness(X, l.lambda, l.mu);
  for (size_t c = 0; c < 12; ++c) {
    std::vector<double> u(12, 0.0);
    const size_t node = size_t(spec.mesh.tets[0][c / 3]);
    u[3 * node + c % 3] = 1e-3;  // linear material: forces are exactly linear in u
    const std::vector<double> f = test::compute_elastic_forces(model, u);
    for (size_t r = 0; r < 12; ++r) {
      const size_t rn = size_t(spec.mesh.tets[0][r / 3]);
      EXPECT_NEAR(-f[3 * rn + r % 3] / 1e-3, K[12 * r + c], 1e-9 * K[0]) << r << "," << c;
    }
  }
}

TEST(CriticalStep, ModelRestStepIsTheSmallestElementStep) {
  const Model<double> model =
      build_model<double>(make_spec(make_jittered_box(Vec3(0.0), Vec3(1.0), {3, 3, 3}, 0.2), MaterialModel::StVK));
  double smallest = INFINITY;
  for (size_t e = 0; e < size_t(model.n_tets); ++e) {
    const Tet& t = model.mesh.tets[e];
    const double dt =
        compute_element_critical_dt(model.mesh.X[size_t(t[0])], model.mesh.X[size_t(t[1])], model.mesh.X[size_t(t[2])],
                                    model.mesh.X[size_t(t[3])], model.tet_lambda[e], model.tet_mu[e], 1000);
    EXPECT_NEAR(model.tet_dt[e], dt, 1e-12 * dt);
    smallest = std::min(smallest, dt);
  }
  EXPECT_EQ(model.dt_rest, smallest);
  // The dilatational wave crosses the smallest altitude in about dt: the estimate has the right scale.
  const double c = std::sqrt((model.tet_lambda[0] + 2 * model.tet_mu[0]) / 1000);
  double h_min = INFINITY;
  for (double h : model.tet_altitude) h_min = std::min(h_min, h);
  EXPECT_GT(model.dt_rest, 0.1 * h_min / c);
  EXPECT_LT(model.dt_rest, 2.0 * h_min / c);
}

TEST(BuildModel, RefusesBadIntegratorAndDampingSettings) {
  ModelSpec spec = make_spec(make_regular_tet(), MaterialModel::StVK);
  spec.integrator.safety = 1.5;
  EXPECT_NE(build_error(spec).find("integrator.safety"), std::string::npos);
  spec.integrator.safety = 0.9;
  spec.integrator.dt = -1;
  EXPECT_NE(build_error(spec).find("integrator.dt"), std::string::npos);
  spec.integrator.dt = 0;
  spec.effects.damping = true;
  spec.effects.alpha = -2;
  EXPECT_NE(build_error(spec).find("alpha"), std::string::npos);
  spec.effects.alpha = 2;
  EXPECT_EQ(build_error(spec), "");
}

}  // namespace
}  // namespace tactile
