#include "core/fields.hpp"

#include <cmath>
#include <limits>

#include <glm/mat3x3.hpp>
#include <glm/matrix.hpp>

#include "core/material.hpp"

namespace tactile {

TetFields compute_tet_fields(MaterialModel m, const double* F, double lambda, double mu) {
  TetFields f;
  double P[9];
  material::stress(m, F, lambda, mu, P);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      double c = 0;
      for (int k = 0; k < 3; ++k) c += F[3 * k + i] * F[3 * k + j];
      f.green[3 * i + j] = 0.5 * (c - (i == j ? 1.0 : 0.0));
    }
  if (m == MaterialModel::Linear) {
    for (int k = 0; k < 9; ++k) f.cauchy[k] = P[k];
  } else {
    const double J =
        F[0] * (F[4] * F[8] - F[5] * F[7]) - F[1] * (F[3] * F[8] - F[5] * F[6]) + F[2] * (F[3] * F[7] - F[4] * F[6]);
    const double inv_J = J != 0 ? 1.0 / J : std::numeric_limits<double>::quiet_NaN();
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        double c = 0;
        for (int k = 0; k < 3; ++k) c += P[3 * i + k] * F[3 * j + k];
        f.cauchy[3 * i + j] = c * inv_J;
      }
  }
  const double mean = (f.cauchy[0] + f.cauchy[4] + f.cauchy[8]) / 3.0;
  double ss = 0;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      const double d = f.cauchy[3 * i + j] - (i == j ? mean : 0.0);
      ss += d * d;
    }
  f.von_mises = std::sqrt(1.5 * ss);
  return f;
}

template <class Real>
ElementFields compute_element_fields(const Model<Real>& model, const State<Real>& s, const ElementFieldRequest& ask) {
  ElementFields out;
  if (!ask.any()) return out;
  const size_t nt = size_t(model.n_tets);
  if (ask.cauchy_stress) out.cauchy_stress.resize(9 * nt);
  if (ask.green_strain) out.green_strain.resize(9 * nt);
  if (ask.von_mises) out.von_mises.resize(nt);
  const std::vector<Vec3>& X = model.mesh.X;
  for (size_t e = 0; e < nt; ++e) {
    const Tet& t = model.mesh.tets[e];
    // Columns: edges from corner 0 (glm is column-major).
    const glm::dmat3 Dm(X[size_t(t[1])] - X[size_t(t[0])], X[size_t(t[2])] - X[size_t(t[0])],
                        X[size_t(t[3])] - X[size_t(t[0])]);
    // F = I + D_u D_m^-1 from the corners' displacements: exactly I at rest,
    // and no cancellation of positions where the strain is small.
    auto u = [&](int32_t i) {
      const size_t j = 3 * size_t(i);
      return Vec3(double(s.u[j]), double(s.u[j + 1]), double(s.u[j + 2]));
    };
    const Vec3 u0 = u(t[0]);
    const glm::dmat3 Du(u(t[1]) - u0, u(t[2]) - u0, u(t[3]) - u0);
    const glm::dmat3 Fm = glm::dmat3(1.0) + Du * glm::inverse(Dm);
    double F[9];
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) F[3 * i + j] = Fm[j][i];
    const TetFields f = compute_tet_fields(model.tet_model[e], F, model.tet_lambda[e], model.tet_mu[e]);
    for (int k = 0; k < 9; ++k) {
      if (ask.cauchy_stress) out.cauchy_stress[9 * e + size_t(k)] = f.cauchy[k];
      if (ask.green_strain) out.green_strain[9 * e + size_t(k)] = f.green[k];
    }
    if (ask.von_mises) out.von_mises[e] = f.von_mises;
  }
  return out;
}

template ElementFields compute_element_fields(const Model<float>&, const State<float>&, const ElementFieldRequest&);
template ElementFields compute_element_fields(const Model<double>&, const State<double>&, const ElementFieldRequest&);

}  // namespace tactile
