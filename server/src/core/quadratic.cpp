#include "core/quadratic.hpp"

#include <algorithm>
#include <limits>
#include <map>

#include <glm/mat3x3.hpp>
#include <glm/matrix.hpp>

#include "core/symmetric_eigen.hpp"

namespace tactile {

namespace {

std::array<double, 4> barycentric(const Vec3& xi) { return {1.0 - xi.x - xi.y - xi.z, xi.x, xi.y, xi.z}; }

// d L_i / d xi.
const std::array<Vec3, 4> kDL = {Vec3(-1, -1, -1), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1)};

}  // namespace

std::array<double, kP2Nodes> p2_shape(const Vec3& xi) {
  const std::array<double, 4> L = barycentric(xi);
  std::array<double, kP2Nodes> N{};
  for (int i = 0; i < 4; ++i) N[size_t(i)] = L[size_t(i)] * (2 * L[size_t(i)] - 1);
  for (int k = 0; k < 6; ++k) N[size_t(4 + k)] = 4 * L[size_t(kTetEdges[k][0])] * L[size_t(kTetEdges[k][1])];
  return N;
}

std::array<Vec3, kP2Nodes> p2_shape_gradients(const Vec3& xi) {
  const std::array<double, 4> L = barycentric(xi);
  std::array<Vec3, kP2Nodes> G{};
  for (int i = 0; i < 4; ++i) G[size_t(i)] = (4 * L[size_t(i)] - 1) * kDL[size_t(i)];
  for (int k = 0; k < 6; ++k) {
    const auto i = size_t(kTetEdges[k][0]), j = size_t(kTetEdges[k][1]);
    G[size_t(4 + k)] = 4.0 * (L[j] * kDL[i] + L[i] * kDL[j]);
  }
  return G;
}

Vec3 p2_node_xi(int a) {
  static const std::array<Vec3, 4> corner = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1)};
  if (a < 4) return corner[size_t(a)];
  return 0.5 * (corner[size_t(kTetEdges[a - 4][0])] + corner[size_t(kTetEdges[a - 4][1])]);
}

const std::array<QuadraturePoint, 4>& tet_quadrature_4() {
  // Barycentric (a, b, b, b) and its permutations.
  static const std::array<QuadraturePoint, 4> rule = [] {
    const double a = kTetQuadratureA, b = kTetQuadratureB;
    std::array<QuadraturePoint, 4> r{};
    r[0] = {Vec3(b, b, b), 1.0 / 24};  // L0 = a
    r[1] = {Vec3(a, b, b), 1.0 / 24};
    r[2] = {Vec3(b, a, b), 1.0 / 24};
    r[3] = {Vec3(b, b, a), 1.0 / 24};
    return r;
  }();
  return rule;
}

const std::array<double, kP2Nodes>& p2_lumped_mass_fractions() {
  // The consistent mass of a straight T10 is rho V / 420 times a matrix
  // whose diagonal is 6 at the corners and 32 at the edges (sum 216).
  static const std::array<double, kP2Nodes> f = {6.0 / 216,  6.0 / 216,  6.0 / 216,  6.0 / 216,  32.0 / 216,
                                                 32.0 / 216, 32.0 / 216, 32.0 / 216, 32.0 / 216, 32.0 / 216};
  return f;
}

TetMesh make_quadratic_mesh(const TetMesh& linear) {
  TetMesh out = linear;
  out.edges.resize(linear.tets.size());
  std::map<std::array<int32_t, 2>, int32_t> made;
  for (size_t e = 0; e < linear.tets.size(); ++e) {
    const Tet& t = linear.tets[e];
    for (int k = 0; k < 6; ++k) {
      const int32_t a = t[size_t(kTetEdges[k][0])], b = t[size_t(kTetEdges[k][1])];
      const std::array<int32_t, 2> key{std::min(a, b), std::max(a, b)};
      auto [it, inserted] = made.try_emplace(key, int32_t(out.X.size()));
      if (inserted) out.X.push_back(0.5 * (linear.X[size_t(a)] + linear.X[size_t(b)]));
      out.edges[e][size_t(k)] = it->second;
    }
  }
  return out;
}

std::array<Vec3, kP2Nodes> p2_rest_nodes(const TetMesh& mesh, size_t e) {
  std::array<Vec3, kP2Nodes> X;
  for (int a = 0; a < kP2Nodes; ++a) X[size_t(a)] = mesh.X[size_t(mesh.node(e, a))];
  return X;
}

std::vector<double> compute_quadratic_lumped_masses(const TetMesh& mesh, const std::vector<double>& rho,
                                                    const std::vector<double>& volume) {
  const auto& share = p2_lumped_mass_fractions();
  std::vector<double> mass(mesh.X.size(), 0.0);
  for (size_t e = 0; e < mesh.tets.size(); ++e) {
    const double m = rho[e] * volume[e];
    for (int a = 0; a < kP2Nodes; ++a) mass[size_t(mesh.node(e, a))] += share[size_t(a)] * m;
  }
  return mass;
}

P2Element make_p2_element(const std::array<Vec3, kP2Nodes>& X) {
  P2Element out;
  out.min_det = std::numeric_limits<double>::infinity();
  const auto& rule = tet_quadrature_4();
  for (size_t q = 0; q < rule.size(); ++q) {
    const std::array<Vec3, kP2Nodes> G = p2_shape_gradients(rule[q].xi);
    // J = dX / dxi (column k: d X / d xi_k), glm column-major.
    glm::dmat3 J(0.0);
    for (int a = 0; a < kP2Nodes; ++a)
      for (int k = 0; k < 3; ++k) J[k] += X[size_t(a)] * G[size_t(a)][k];
    const double det = glm::determinant(J);
    out.min_det = std::min(out.min_det, det);
    out.volume[q] = rule[q].weight * det;
    // d N / d X = J^-T d N / d xi.
    const glm::dmat3 Jinv_t = glm::transpose(glm::inverse(J));
    for (int a = 0; a < kP2Nodes; ++a) out.grad[q][size_t(a)] = Jinv_t * G[size_t(a)];
  }
  return out;
}

double compute_p2_forces(const P2Element& element, const std::array<Vec3, kP2Nodes>& x, MaterialModel model,
                         double lambda, double mu, std::array<Vec3, kP2Nodes>* f) {
  double energy = 0;
  if (f) f->fill(Vec3(0.0));
  for (size_t q = 0; q < element.volume.size(); ++q) {
    const std::array<Vec3, kP2Nodes>& g = element.grad[q];
    double F[9] = {};
    for (int a = 0; a < kP2Nodes; ++a)
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) F[3 * i + j] += x[size_t(a)][i] * g[size_t(a)][j];
    double P[9] = {};  // (the run-time dispatch's default case writes none)
    energy += element.volume[q] * material::stress(model, F, lambda, mu, P);
    if (!f) continue;
    for (int a = 0; a < kP2Nodes; ++a)
      for (int i = 0; i < 3; ++i)
        (*f)[size_t(a)][i] -= element.volume[q] * (P[3 * i] * g[size_t(a)].x + P[3 * i + 1] * g[size_t(a)].y +
                                                   P[3 * i + 2] * g[size_t(a)].z);
  }
  return energy;
}

double compute_p2_critical_dt(const std::array<Vec3, kP2Nodes>& X, double lambda, double mu, double rho) {
  constexpr int n = 3 * kP2Nodes;
  const P2Element el = make_p2_element(X);
  double volume = 0;
  for (double v : el.volume) volume += v;
  if (!(el.min_det > 0) || !(volume > 0) || !(rho > 0)) return 0.0;
  // K_(a i)(b k) = sum_q w_q [lambda g_ai g_bk + mu (delta_ik g_a . g_b + g_ak g_bi)].
  std::array<double, n * n> K{};
  for (size_t q = 0; q < el.volume.size(); ++q) {
    const auto& g = el.grad[q];
    for (int a = 0; a < kP2Nodes; ++a)
      for (int b = 0; b < kP2Nodes; ++b) {
        const Vec3 &ga = g[size_t(a)], &gb = g[size_t(b)];
        const double dot = ga.x * gb.x + ga.y * gb.y + ga.z * gb.z;
        for (int i = 0; i < 3; ++i)
          for (int k = 0; k < 3; ++k)
            K[size_t((3 * a + i) * n + 3 * b + k)] +=
                el.volume[q] * (lambda * ga[i] * gb[k] + mu * ((i == k ? dot : 0.0) + ga[k] * gb[i]));
      }
  }
  // M^-1/2 K M^-1/2, M the lumped masses.
  const auto& share = p2_lumped_mass_fractions();
  for (int r = 0; r < n; ++r)
    for (int c = 0; c < n; ++c)
      K[size_t(r * n + c)] /= std::sqrt(rho * volume * share[size_t(r / 3)] * rho * volume * share[size_t(c / 3)]);
  const double omega2 = compute_max_eigenvalue_symmetric(K.data(), n);
  return omega2 > 0 ? 2.0 / std::sqrt(omega2) : 0.0;
}

}  // namespace tactile
