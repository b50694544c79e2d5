// The 10-node tetrahedron (core/quadratic.hpp): its shape functions against
// their defining properties, its quadrature against exact integrals, its
// lumped mass against the consistent mass integrated independently, and the
// edge nodes a linear mesh gains.
#include "core/quadratic.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <map>
#include <random>
#include <vector>

#include <glm/geometric.hpp>

#include "core/fem_fixtures.hpp"
#include "core/model.hpp"
#include "mesh/primitives.hpp"

namespace tactile {
namespace {

// The reference tet's integral of f, by an 8 x 8 x 8 Gauss-Legendre product
// on the unit cube collapsed onto the tet (Duffy): r = u, s = v (1 - u),
// t = w (1 - u) (1 - v), dV = (1 - u)^2 (1 - v) du dv dw. Exact for the
// polynomials of degree 8 and less that these tests integrate, and
// independent of the rule under test.
double integrate(const std::function<double(const Vec3&)>& f) {
  static const double x[8] = {-0.9602898564975363, -0.7966664774136267, -0.5255324099163290, -0.1834346424956498,
                              0.1834346424956498,  0.5255324099163290,  0.7966664774136267,  0.9602898564975363};
  static const double w[8] = {0.1012285362903763, 0.2223810344533745, 0.3137066458778873, 0.3626837833783620,
                              0.3626837833783620, 0.3137066458778873, 0.2223810344533745, 0.1012285362903763};
  double sum = 0;
  for (int i = 0; i < 8; ++i)
    for (int j = 0; j < 8; ++j)
      for (int k = 0; k < 8; ++k) {
        const double u = 0.5 * (x[i] + 1), v = 0.5 * (x[j] + 1), t = 0.5 * (x[k] + 1);
        const Vec3 xi(u, v * (1 - u), t * (1 - u) * (1 - v));
        sum += 0.125 * w[i] * w[j] * w[k] * (1 - u) * (1 - u) * (1 - v) * f(xi);
      }
  return sum;
}

std::vector<Vec3> random_points(int n) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> unit(0, 1);
  std::vector<Vec3> out;
  while (int(out.size()) < n) {
    const Vec3 p(unit(rng), unit(rng), unit(rng));
    if (p.x + p.y + p.z <= 1) out.push_back(p);
  }
  return out;
}

TEST(P2Shape, APartitionOfUnityWhoseGradientsSumToZero) {
  for (const Vec3& xi : random_points(50)) {
    const auto N = p2_shape(xi);
    const auto G = p2_shape_gradients(xi);
    double sum = 0;
    Vec3 grad(0.0);
    for (int a = 0; a < kP2Nodes; ++a) sum += N[size_t(a)], grad += G[size_t(a)];
    EXPECT_NEAR(sum, 1.0, 1e-14);
    EXPECT_NEAR(glm::length(grad), 0.0, 1e-13);
  }
}

TEST(P2Shape, EachIsOneAtItsNodeAndZeroAtTheOthers) {
  for (int b = 0; b < kP2Nodes; ++b) {
    const auto N = p2_shape(p2_node_xi(b));
    for (int a = 0; a < kP2Nodes; ++a) EXPECT_NEAR(N[size_t(a)], a == b ? 1.0 : 0.0, 1e-15) << a << " at " << b;
  }
}

TEST(P2Shape, GradientsAreTheFunctionsDerivatives) {
  const double h = 1e-6;
  for (const Vec3& xi : random_points(20)) {
    const auto G = p2_shape_gradients(xi);
    for (int k = 0; k < 3; ++k) {
      Vec3 d(0.0);
      d[k] = h;
      const auto Np = p2_shape(xi + d), Nm = p2_shape(xi - d);
      for (int a = 0; a < kP2Nodes; ++a)
        EXPECT_NEAR((Np[size_t(a)] - Nm[size_t(a)]) / (2 * h), G[size_t(a)][k], 1e-8) << a << " along " << k;
    }
  }
}

// Quadratic fields are reproduced exactly: the interpolant of x(xi) = q(xi)
// through the ten nodes is q itself, for any quadratic q.
TEST(P2Shape, InterpolatesEveryQuadraticExactly) {
  auto q = [](const Vec3& p) { return 0.3 + p.x - 2 * p.y + 0.5 * p.z + p.x * p.y - 3 * p.z * p.z + 2 * p.x * p.z; };
  for (const Vec3& xi : random_points(20)) {
    const auto N = p2_shape(xi);
    double v = 0;
    for (int a = 0; a < kP2Nodes; ++a) v += N[size_t(a)] * q(p2_node_xi(a));
    EXPECT_NEAR(v, q(xi), 1e-14);
  }
}

// The constants the lane kernel folds are the gradients at the rule's points.
TEST(P2Shape, TheKernelsConstantsAreTheGradientsAtTheQuadraturePoints) {
  for (size_t q = 0; q < 4; ++q) {
    const auto G = p2_shape_gradients(tet_quadrature_4()[q].xi);
    for (int a = 0; a < kP2Nodes; ++a)
      for (int k = 0; k < 3; ++k) EXPECT_NEAR(kP2PointGradients.g[q][a][k], G[size_t(a)][k], 1e-15) << q << a << k;
  }
}

TEST(TetQuadrature4, IntegratesEveryPolynomialOfDegreeTwoExactly) {
  const auto& rule = tet_quadrature_4();
  for (int i = 0; i <= 2; ++i)
    for (int j = 0; i + j <= 2; ++j)
      for (int k = 0; i + j + k <= 2; ++k) {
        auto f = [&](const Vec3& p) { return std::pow(p.x, i) * std::pow(p.y, j) * std::pow(p.z, k); };
        double sum = 0;
        for (const QuadraturePoint& qp : rule) sum += qp.weight * f(qp.xi);
        // Exact: i! j! k! / (i + j + k + 3)!
        const double exact = std::tgamma(i + 1) * std::tgamma(j + 1) * std::tgamma(k + 1) / std::tgamma(i + j + k + 4);
        EXPECT_NEAR(sum, exact, 1e-15) << i << j << k;
        EXPECT_NEAR(integrate(f), exact, 1e-15) << "the reference integrator, " << i << j << k;
      }
}

TEST(P2LumpedMass, TheConsistentDiagonalScaledToTheMassAndEveryNodePositive) {
  const auto& f = p2_lumped_mass_fractions();
  double diagonal = 0, sum = 0;
  std::array<double, kP2Nodes> m{};
  for (int a = 0; a < kP2Nodes; ++a) {
    m[size_t(a)] = integrate([a](const Vec3& xi) { return std::pow(p2_shape(xi)[size_t(a)], 2); });
    diagonal += m[size_t(a)];
  }
  for (int a = 0; a < kP2Nodes; ++a) {
    EXPECT_NEAR(f[size_t(a)], m[size_t(a)] / diagonal, 1e-13) << a;
    EXPECT_GT(f[size_t(a)], 0.0) << a;
    sum += f[size_t(a)];
  }
  EXPECT_NEAR(sum, 1.0, 1e-15);
  // What the scheme avoids: summing rows gives each corner int N_a dV = -V / 20.
  EXPECT_NEAR(integrate([](const Vec3& xi) { return p2_shape(xi)[0]; }) * 6, -1.0 / 20, 1e-14);
}

TEST(MakeQuadraticMesh, OneSharedNodeAtTheMidpointOfEachEdge) {
  const TetMesh mesh = make_box(Vec3(0.0), Vec3(0.2, 0.1, 0.1), {2, 1, 1});
  const TetMesh q = make_quadratic_mesh(mesh);
  std::map<std::array<int32_t, 2>, int> edges;
  for (const Tet& t : mesh.tets)
    for (const auto& e : kTetEdges) {
      const int32_t a = t[size_t(e[0])], b = t[size_t(e[1])];
      edges[{std::min(a, b), std::max(a, b)}] = 1;
    }
  ASSERT_EQ(q.X.size(), mesh.X.size() + edges.size());
  for (size_t i = 0; i < mesh.X.size(); ++i) EXPECT_EQ(q.X[i], mesh.X[i]) << "corners keep their ids";
  for (size_t e = 0; e < mesh.tets.size(); ++e)
    for (int k = 0; k < 6; ++k) {
      const int32_t a = mesh.tets[e][size_t(kTetEdges[k][0])], b = mesh.tets[e][size_t(kTetEdges[k][1])];
      const int32_t m = q.edges[e][size_t(k)];
      EXPECT_EQ(q.X[size_t(m)], 0.5 * (mesh.X[size_t(a)] + mesh.X[size_t(b)]));
      EXPECT_GE(m, mesh.n_nodes()) << "edge nodes come after the corners";
    }
  EXPECT_EQ(q.tets, mesh.tets);
  EXPECT_EQ(check_mesh_structure(q), "") << "one node per edge, shared by the tets around it";
}

TEST(QuadraticLumpedMasses, EveryNodePositiveAndTheTotalExact) {
  const TetMesh mesh = test::make_jittered_box(Vec3(0.0), Vec3(0.2, 0.1, 0.1), {4, 2, 2}, 0.2);
  const TetMesh nodes = make_quadratic_mesh(mesh);
  std::vector<double> rho, volume;
  double total = 0;
  for (size_t e = 0; e < mesh.tets.size(); ++e) {
    const Tet& t = mesh.tets[e];
    volume.push_back(
        compute_tet_volume(mesh.X[size_t(t[0])], mesh.X[size_t(t[1])], mesh.X[size_t(t[2])], mesh.X[size_t(t[3])]));
    rho.push_back(e % 2 ? 1000 : 3000);
    total += rho.back() * volume.back();
  }
  const std::vector<double> m = compute_quadratic_lumped_masses(nodes, rho, volume);
  ASSERT_EQ(m.size(), nodes.X.size());
  double sum = 0;
  for (double mi : m) {
    EXPECT_GT(mi, 0.0);
    sum += mi;
  }
  EXPECT_NEAR(sum, total, 1e-12 * total);
  // The box's corner at the origin: 1/36 of the mass of each tet around it.
  double expected = 0;
  for (size_t e = 0; e < mesh.tets.size(); ++e)
    for (int32_t n : mesh.tets[e])
      if (n == 0) expected += rho[e] * volume[e] / 36;
  EXPECT_NEAR(m[0], expected, 1e-15);
}

TEST(QuadraticBoundaryFaces, FourOutwardTrianglesPerFaceCoveringTheSameArea) {
  const TetMesh mesh = test::make_jittered_box(Vec3(0.0), Vec3(0.2, 0.1, 0.1), {4, 2, 2}, 0.2);
  const TetMesh nodes = make_quadratic_mesh(mesh);
  const std::vector<Tri> corner_faces = compute_boundary_faces(mesh);
  const std::vector<Tri> faces = compute_boundary_faces(nodes);
  ASSERT_EQ(faces.size(), 4 * corner_faces.size());
  auto area_vector = [&](const Tri& t) {
    const Vec3 &a = nodes.X[size_t(t[0])], &b = nodes.X[size_t(t[1])], &c = nodes.X[size_t(t[2])];
    return 0.5 * glm::cross(b - a, c - a);
  };
  for (size_t f = 0; f < corner_faces.size(); ++f) {
    const Vec3 whole = area_vector(corner_faces[f]);
    Vec3 parts(0.0);
    for (int k = 0; k < 4; ++k) {
      const Vec3 part = area_vector(faces[4 * f + size_t(k)]);
      EXPECT_GT(glm::dot(part, whole), 0.0) << "wound as the face";
      parts += part;
    }
    EXPECT_NEAR(glm::length(parts - whole), 0.0, 1e-15);
  }
  // Every node on the box's faces is a vertex of some triangle, and no other node is.
  std::vector<int> used(nodes.X.size(), 0);
  for (const Tri& t : faces)
    for (int32_t n : t) used[size_t(n)] = 1;
  for (size_t n = 0; n < nodes.X.size(); ++n) {
    const Vec3& X = nodes.X[n];
    const bool on_box =
        std::min({X.x, X.y, X.z}) < 1e-12 || X.x > 0.2 - 1e-12 || X.y > 0.1 - 1e-12 || X.z > 0.1 - 1e-12;
    EXPECT_EQ(used[n] == 1, on_box) << "node " << n;
  }
}

// ---- one element (compute_p2_forces) ----

// A straight T10 on four corners: its ten rest positions.
std::array<Vec3, kP2Nodes> straight(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) {
  const Vec3 corner[4] = {a, b, c, d};
  std::array<Vec3, kP2Nodes> X{};
  for (int i = 0; i < 4; ++i) X[size_t(i)] = corner[i];
  for (int k = 0; k < 6; ++k) X[size_t(4 + k)] = 0.5 * (corner[kTetEdges[k][0]] + corner[kTetEdges[k][1]]);
  return X;
}

const std::array<Vec3, kP2Nodes> kRest =
    straight(Vec3(0.01, 0.0, 0.002), Vec3(0.05, 0.01, 0.0), Vec3(0.02, 0.045, 0.01), Vec3(0.015, 0.01, 0.04));

TEST(P2Element, ItsPointsShareTheVolumeAndRestIsStressFree) {
  const P2Element el = make_p2_element(kRest);
  const double V = compute_tet_volume(kRest[0], kRest[1], kRest[2], kRest[3]);
  double sum = 0;
  for (double v : el.volume) sum += v;
  EXPECT_NEAR(sum, V, 1e-15);
  EXPECT_NEAR(el.min_det, 6 * V, 1e-14);
  for (MaterialModel m : test::kAllModels) {
    std::array<Vec3, kP2Nodes> f;
    EXPECT_NEAR(compute_p2_forces(el, kRest, m, 1e5, 4e4, &f), 0.0, 1e-15) << to_string(m);
    for (const Vec3& fa : f) EXPECT_LT(glm::length(fa), 1e-12) << to_string(m);
  }
}

// A deformed state: every node moved by its own smooth-ish offset, an edge
// node off its midpoint (a bent edge).
std::array<Vec3, kP2Nodes> deformed(double scale) {
  std::array<Vec3, kP2Nodes> x = kRest;
  for (size_t a = 0; a < x.size(); ++a)
    x[a] += scale * Vec3(std::sin(3.0 * double(a)), std::cos(2.0 * double(a) + 1), std::sin(double(a) * double(a)));
  return x;
}

TEST(P2Element, ForcesAreMinusTheEnergysGradient) {
  const P2Element el = make_p2_element(kRest);
  const std::array<Vec3, kP2Nodes> x = deformed(0.003);
  const double h = 1e-8;
  for (MaterialModel m : test::kAllModels) {
    std::array<Vec3, kP2Nodes> f;
    compute_p2_forces(el, x, m, 1e5, 4e4, &f);
    double largest = 0;
    for (const Vec3& fa : f) largest = std::max(largest, glm::length(fa));
    ASSERT_GT(largest, 1e-3) << to_string(m) << ": the state is deformed";
    for (size_t a = 0; a < x.size(); ++a)
      for (int i = 0; i < 3; ++i) {
        std::array<Vec3, kP2Nodes> xp = x, xm = x;
        xp[a][i] += h;
        xm[a][i] -= h;
        const double dE =
            (compute_p2_forces(el, xp, m, 1e5, 4e4, nullptr) - compute_p2_forces(el, xm, m, 1e5, 4e4, nullptr)) /
            (2 * h);
        EXPECT_NEAR(f[a][i], -dE, 1e-5 * largest) << to_string(m) << " node " << a << " axis " << i;
      }
  }
}

TEST(P2Element, ARigidMotionStoresNoEnergyUnlessTheModelIsLinear) {
  const P2Element el = make_p2_element(kRest);
  const glm::dmat3 R = test::make_rotation(Vec3(1, 2, 3), 0.7);
  std::array<Vec3, kP2Nodes> x;
  for (size_t a = 0; a < x.size(); ++a) x[a] = R * kRest[a] + Vec3(0.3, -0.1, 0.2);
  const std::array<Vec3, kP2Nodes> stretched = deformed(0.003);
  for (MaterialModel m : test::kAllModels) {
    std::array<Vec3, kP2Nodes> f;
    const double E = compute_p2_forces(el, x, m, 1e5, 4e4, &f);
    const double E_deformed = compute_p2_forces(el, stretched, m, 1e5, 4e4, nullptr);
    if (m == MaterialModel::Linear) {
      EXPECT_GT(E, 1e-3 * E_deformed) << "small strain distorts under rotation, the paper's point";
      continue;
    }
    EXPECT_LT(std::fabs(E), 1e-9 * E_deformed) << to_string(m);
    for (const Vec3& fa : f) EXPECT_LT(glm::length(fa), 1e-6) << to_string(m);
  }
}

// The critical step is the stability limit of the explicit step (v += dt a,
// x += dt v) on one free element: a little under it, a random start stays
// bounded; a little over it, the highest mode grows without bound. A linear
// tet of the same corners allows a longer step.
TEST(P2CriticalStep, TheExplicitStepIsStableJustUnderItAndNotJustOver) {
  const double lambda = 5e4, mu = 3e4, rho = 1000;
  const double dt_crit = compute_p2_critical_dt(kRest, lambda, mu, rho);
  ASSERT_GT(dt_crit, 0.0);
  EXPECT_LT(dt_crit, compute_element_critical_dt(kRest[0], kRest[1], kRest[2], kRest[3], lambda, mu, rho));
  const P2Element el = make_p2_element(kRest);
  double volume = 0;
  for (double v : el.volume) volume += v;
  auto run = [&](double dt) {
    std::array<Vec3, kP2Nodes> x = deformed(1e-5), v{}, f;
    double largest = 0;
    for (int step = 0; step < 20000; ++step) {
      compute_p2_forces(el, x, MaterialModel::Linear, lambda, mu, &f);
      for (size_t a = 0; a < x.size(); ++a) {
        v[a] += dt * f[a] / (rho * volume * p2_lumped_mass_fractions()[a]);
        x[a] += dt * v[a];
      }
      for (size_t a = 0; a < x.size(); ++a) largest = std::max(largest, glm::length(x[a] - kRest[a]));
    }
    return largest;
  };
  const double start = 1e-5 * std::sqrt(3.0);
  EXPECT_LT(run(0.98 * dt_crit), 100 * start) << "bounded under the critical step";
  EXPECT_GT(run(1.02 * dt_crit), 1e4 * start) << "unbounded over it";
}

// The patch test of the quadratic element (linear elasticity): a quadratic
// displacement field is in the element space, so at every node inside the
// body the elements' forces balance the body force b = -div sigma that makes
// the field an equilibrium, exactly, on an irregular mesh.
TEST(P2Patch, AQuadraticFieldBalancesItsBodyForceAtEveryInnerNode) {
  const Vec3 lo(0.0), hi(0.1, 0.06, 0.08);
  const TetMesh mesh = test::make_jittered_box(lo, hi, {3, 2, 3}, 0.25);
  const TetMesh nodes = make_quadratic_mesh(mesh);
  const double lambda = 5e4, mu = 3e4;
  // u_i = c_i + B_ij X_j + A_ijk X_j X_k, small.
  const Vec3 c(1e-4, -2e-4, 5e-5);
  const double B[3][3] = {{1e-3, 2e-3, -1e-3}, {0, -2e-3, 1e-3}, {3e-3, 1e-3, 2e-3}};
  double A[3][3][3];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) A[i][j][k] = 0.01 * std::sin(1.0 + i + 2.0 * j * k + 0.5 * (j + k));
  auto u = [&](const Vec3& X) {
    Vec3 out = c;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        out[i] += B[i][j] * X[j];
        for (int k = 0; k < 3; ++k) out[i] += A[i][j][k] * X[j] * X[k];
      }
    return out;
  };
  // H_ijk = d^2 u_i / dX_j dX_k; div sigma_i = lambda d_i (div u) + mu (lap u_i + d_i div u).
  Vec3 b(0.0);
  for (int i = 0; i < 3; ++i) {
    auto H = [&](int p, int q, int r) { return A[p][q][r] + A[p][r][q]; };
    double div_sigma = 0;
    for (int k = 0; k < 3; ++k) div_sigma += (lambda + mu) * H(k, i, k) + mu * H(i, k, k);
    b[i] = -div_sigma;
  }
  std::vector<Vec3> force(nodes.X.size(), Vec3(0.0));
  double largest = 0;
  for (size_t e = 0; e < mesh.tets.size(); ++e) {
    std::array<int32_t, kP2Nodes> id{};
    for (int a = 0; a < 4; ++a) id[size_t(a)] = mesh.tets[e][size_t(a)];
    for (int k = 0; k < 6; ++k) id[size_t(4 + k)] = nodes.edges[e][size_t(k)];
    std::array<Vec3, kP2Nodes> X, x, f;
    for (int a = 0; a < kP2Nodes; ++a) X[size_t(a)] = nodes.X[size_t(id[size_t(a)])];
    for (int a = 0; a < kP2Nodes; ++a) x[size_t(a)] = X[size_t(a)] + u(X[size_t(a)]);
    const P2Element el = make_p2_element(X);
    compute_p2_forces(el, x, MaterialModel::Linear, lambda, mu, &f);
    for (int a = 0; a < kP2Nodes; ++a) {
      largest = std::max(largest, glm::length(f[size_t(a)]));
      force[size_t(id[size_t(a)])] += f[size_t(a)];
      for (size_t q = 0; q < 4; ++q)  // the body force's share, int N_a b dV (degree 2: exact)
        force[size_t(id[size_t(a)])] += el.volume[q] * p2_shape(tet_quadrature_4()[q].xi)[size_t(a)] * b;
    }
  }
  int inner = 0;
  const double eps = 1e-9;
  for (size_t n = 0; n < nodes.X.size(); ++n) {
    const Vec3& X = nodes.X[n];
    if (!(X.x > lo.x + eps && X.x < hi.x - eps && X.y > lo.y + eps && X.y < hi.y - eps && X.z > lo.z + eps &&
          X.z < hi.z - eps))
      continue;
    ++inner;
    EXPECT_LT(glm::length(force[n]), 1e-10 * largest) << "node " << n;
  }
  EXPECT_GT(inner, 20);
}

}  // namespace
}  // namespace tactile
