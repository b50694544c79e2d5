// What the quadratic element is for: on a manufactured smooth solution of
// linear elasticity (a chosen cubic displacement, the body force that makes
// it an equilibrium, its values held on the boundary), the static solution's
// L2 error falls as h^3 on quadratic tets and as h^2 on linear ones, over
// three meshes of a cube, each half the last one's size. The elements are
// the scalar references (core/quadratic.hpp; material::stress_linear on a
// linear tet), the solve a matrix-free conjugate gradient.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <functional>
#include <vector>

#include <glm/geometric.hpp>
#include <glm/mat3x3.hpp>
#include <glm/matrix.hpp>

#include "core/material.hpp"
#include "core/quadratic.hpp"
#include "mesh/primitives.hpp"

namespace tactile {
namespace {

constexpr double kLambda = 1.5, kMu = 1.0;

// u_i(X) = sum of cubic terms, smooth and non-polynomial in neither element's space.
Vec3 exact(const Vec3& X) {
  const double x = X.x, y = X.y, z = X.z;
  return {0.1 * x * x * x + 0.2 * x * y * z - 0.1 * y * y * z, 0.15 * y * y * y - 0.1 * x * x * z + 0.05 * z * z * x,
          0.1 * z * z * z + 0.2 * x * y * y - 0.05 * x * x * x};
}

// b = -div sigma(u), by central differences of the exact field's second
// derivatives (a cubic: differences of step 1e-3 are exact to rounding).
Vec3 body_force(const Vec3& X) {
  const double h = 1e-3;
  auto second = [&](int i, int j, int k) {  // d^2 u_i / dX_j dX_k
    Vec3 ej(0.0), ek(0.0);
    ej[j] = h;
    ek[k] = h;
    return (exact(X + ej + ek)[i] - exact(X + ej - ek)[i] - exact(X - ej + ek)[i] + exact(X - ej - ek)[i]) /
           (4 * h * h);
  };
  Vec3 b(0.0);
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) b[i] -= (kLambda + kMu) * second(k, i, k) + kMu * second(i, k, k);
  return b;
}

// The reference tet's points and weights of a collapsed 4 x 4 x 4 Gauss
// product (exact to degree 7 in each variable: the loads and errors below).
struct Point {
  Vec3 xi;
  double w;
};
const std::vector<Point>& duffy_rule() {
  static const std::vector<Point> rule = [] {
    const double g[4] = {-0.8611363115940526, -0.3399810435848563, 0.3399810435848563, 0.8611363115940526};
    const double w[4] = {0.3478548451374538, 0.6521451548625461, 0.6521451548625461, 0.3478548451374538};
    std::vector<Point> r;
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j)
        for (int k = 0; k < 4; ++k) {
          const double u = 0.5 * (g[i] + 1), v = 0.5 * (g[j] + 1), t = 0.5 * (g[k] + 1);
          r.push_back(
              {Vec3(u, v * (1 - u), t * (1 - u) * (1 - v)), 0.125 * w[i] * w[j] * w[k] * (1 - u) * (1 - u) * (1 - v)});
        }
    return r;
  }();
  return rule;
}

// A mesh of the unit cube, linear or quadratic, and its static solution.
struct Problem {
  bool quadratic;
  std::vector<Vec3> X;
  std::vector<std::vector<int32_t>> elements;  // 4 or 10 node ids each
  std::vector<P2Element> p2;                   // quadratic
  std::vector<glm::dmat3> Dinv;                // linear: Dm^-1
  std::vector<double> volume;                  // linear
  std::vector<bool> held;                      // on the boundary: the exact value

  Problem(int cells, bool q) : quadratic(q) {
    const TetMesh mesh = make_box(Vec3(0.0), Vec3(1.0), {cells, cells, cells});
    if (q) {
      const TetMesh nodes = make_quadratic_mesh(mesh);
      X = nodes.X;
      for (size_t e = 0; e < mesh.tets.size(); ++e) {
        std::vector<int32_t> ids(mesh.tets[e].begin(), mesh.tets[e].end());
        ids.insert(ids.end(), nodes.edges[e].begin(), nodes.edges[e].end());
        std::array<Vec3, kP2Nodes> Xe;
        for (int a = 0; a < kP2Nodes; ++a) Xe[size_t(a)] = X[size_t(ids[size_t(a)])];
        p2.push_back(make_p2_element(Xe));
        elements.push_back(ids);
      }
    } else {
      X = mesh.X;
      for (const Tet& t : mesh.tets) {
        elements.push_back({t[0], t[1], t[2], t[3]});
        const Vec3& X0 = X[size_t(t[0])];
        const glm::dmat3 Dm(X[size_t(t[1])] - X0, X[size_t(t[2])] - X0, X[size_t(t[3])] - X0);
        Dinv.push_back(glm::inverse(Dm));
        volume.push_back(glm::determinant(Dm) / 6);
      }
    }
    held.resize(X.size());
    for (size_t n = 0; n < X.size(); ++n) {
      const Vec3& p = X[n];
      held[n] = std::min({p.x, p.y, p.z}) < 1e-12 || std::max({p.x, p.y, p.z}) > 1 - 1e-12;
    }
  }

  // K u: minus the elements' forces at X + u (linear elasticity: exact).
  std::vector<Vec3> apply(const std::vector<Vec3>& u) const {
    std::vector<Vec3> out(X.size(), Vec3(0.0));
    for (size_t e = 0; e < elements.size(); ++e) {
      const std::vector<int32_t>& ids = elements[e];
      if (quadratic) {
        std::array<Vec3, kP2Nodes> x, f;
        for (int a = 0; a < kP2Nodes; ++a) x[size_t(a)] = X[size_t(ids[size_t(a)])] + u[size_t(ids[size_t(a)])];
        compute_p2_forces(p2[e], x, MaterialModel::Linear, kLambda, kMu, &f);
        for (int a = 0; a < kP2Nodes; ++a) out[size_t(ids[size_t(a)])] -= f[size_t(a)];
      } else {
        const glm::dmat3 Ds(u[size_t(ids[1])] - u[size_t(ids[0])], u[size_t(ids[2])] - u[size_t(ids[0])],
                            u[size_t(ids[3])] - u[size_t(ids[0])]);
        const glm::dmat3 G = Ds * Dinv[e] + glm::dmat3(1.0);  // F, column-major
        double F[9], P[9];
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) F[3 * i + j] = G[j][i];
        material::stress_linear(F, kLambda, kMu, P);
        // Forces on corners 1..3: -V P Dm^-T; corner 0 their negative sum.
        Vec3 sum(0.0);
        for (int a = 0; a < 3; ++a) {
          const Vec3 g(Dinv[e][0][a], Dinv[e][1][a], Dinv[e][2][a]);  // row a of Dm^-1
          const Vec3 f = -volume[e] * Vec3(P[0] * g.x + P[1] * g.y + P[2] * g.z, P[3] * g.x + P[4] * g.y + P[5] * g.z,
                                           P[6] * g.x + P[7] * g.y + P[8] * g.z);
          out[size_t(ids[size_t(a + 1)])] -= f;
          sum += f;
        }
        out[size_t(ids[0])] += sum;
      }
    }
    return out;
  }

  std::array<double, kP2Nodes> shape(const Vec3& xi) const {
    if (quadratic) return p2_shape(xi);
    return {1 - xi.x - xi.y - xi.z, xi.x, xi.y, xi.z, 0, 0, 0, 0, 0, 0};
  }
  Vec3 position(size_t e, const Vec3& xi) const {  // X(xi): straight elements, affine in the corners
    const std::vector<int32_t>& ids = elements[e];
    const Vec3 &X0 = X[size_t(ids[0])], &X1 = X[size_t(ids[1])], &X2 = X[size_t(ids[2])], &X3 = X[size_t(ids[3])];
    return X0 + xi.x * (X1 - X0) + xi.y * (X2 - X0) + xi.z * (X3 - X0);
  }
  double element_volume(size_t e) const {
    const std::vector<int32_t>& ids = elements[e];
    return compute_tet_volume(X[size_t(ids[0])], X[size_t(ids[1])], X[size_t(ids[2])], X[size_t(ids[3])]);
  }

  // The static solution by conjugate gradients on the free nodes, and its L2 error.
  double solve_and_error() const {
    const size_t n = X.size();
    std::vector<Vec3> load(n, Vec3(0.0));
    for (size_t e = 0; e < elements.size(); ++e) {
      const double V6 = 6 * element_volume(e);
      for (const Point& p : duffy_rule()) {
        const auto N = shape(p.xi);
        const Vec3 b = body_force(position(e, p.xi));
        for (size_t a = 0; a < elements[e].size(); ++a) load[size_t(elements[e][a])] += p.w * V6 * N[a] * b;
      }
    }
    std::vector<Vec3> u(n, Vec3(0.0));
    for (size_t i = 0; i < n; ++i)
      if (held[i]) u[i] = exact(X[i]);
    const std::vector<Vec3> Ku = apply(u);
    std::vector<Vec3> r(n, Vec3(0.0)), p(n, Vec3(0.0));
    for (size_t i = 0; i < n; ++i)
      if (!held[i]) r[i] = load[i] - Ku[i];
    p = r;
    auto dot = [&](const std::vector<Vec3>& a, const std::vector<Vec3>& b) {
      double s = 0;
      for (size_t i = 0; i < n; ++i) s += glm::dot(a[i], b[i]);
      return s;
    };
    double rr = dot(r, r);
    const double r0 = rr;
    for (int it = 0; it < 5000 && rr > 1e-26 * r0; ++it) {
      std::vector<Vec3> Ap = apply(p);
      for (size_t i = 0; i < n; ++i)
        if (held[i]) Ap[i] = Vec3(0.0);
      const double alpha = rr / dot(p, Ap);
      for (size_t i = 0; i < n; ++i) u[i] += alpha * p[i], r[i] -= alpha * Ap[i];
      const double next = dot(r, r);
      for (size_t i = 0; i < n; ++i) p[i] = r[i] + (next / rr) * p[i];
      rr = next;
    }
    double err2 = 0;
    for (size_t e = 0; e < elements.size(); ++e) {
      const double V6 = 6 * element_volume(e);
      for (const Point& q : duffy_rule()) {
        const auto N = shape(q.xi);
        Vec3 uh(0.0);
        for (size_t a = 0; a < elements[e].size(); ++a) uh += N[a] * u[size_t(elements[e][a])];
        const Vec3 d = uh - exact(position(e, q.xi));
        err2 += q.w * V6 * glm::dot(d, d);
      }
    }
    return std::sqrt(err2);
  }
};

TEST(ManufacturedSolution, QuadraticTetsConvergeAtThirdOrderAndLinearOnesAtSecond) {
  double order[2] = {0, 0};
  for (int quadratic = 0; quadratic < 2; ++quadratic) {
    double e[3];
    const int cells[3] = {2, 4, 8};
    for (int level = 0; level < 3; ++level) e[level] = Problem(cells[level], quadratic != 0).solve_and_error();
    order[quadratic] = std::log2(e[1] / e[2]);
    std::printf("%s: L2 error %.3e, %.3e, %.3e at 2, 4, 8 cells a side; orders %.2f, %.2f\n", quadratic ? "P2" : "P1",
                e[0], e[1], e[2], std::log2(e[0] / e[1]), order[quadratic]);
    EXPECT_LT(e[2], e[1]);
    EXPECT_LT(e[1], e[0]);
  }
  EXPECT_GE(order[1], 2.8) << "quadratic tets";
  EXPECT_GT(order[0], 1.7) << "linear tets";
  EXPECT_LT(order[0], 2.3) << "linear tets";
}

}  // namespace
}  // namespace tactile
