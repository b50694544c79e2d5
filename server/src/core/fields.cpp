#include "core/fields.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <limits>

#include <glm/mat3x3.hpp>
#include <glm/matrix.hpp>

#include "core/material.hpp"
#include "core/quadratic.hpp"

namespace tactile {

namespace {

// Eigenvalues of a symmetric 3x3 matrix, largest first, by the closed form of
// the characteristic cubic (Smith 1961): A = q I + p B with det B = 2 cos 3phi.
// Accurate to about 1e-8 of |A| where two eigenvalues nearly meet, which a
// field for viewing and output does not see.
void symmetric_eigenvalues(const double* A, double* out) {
  const double p1 = A[1] * A[1] + A[2] * A[2] + A[5] * A[5];
  const double q = (A[0] + A[4] + A[8]) / 3.0;
  const double d0 = A[0] - q, d1 = A[4] - q, d2 = A[8] - q;
  const double p2 = d0 * d0 + d1 * d1 + d2 * d2 + 2.0 * p1;
  const double p = std::sqrt(p2 / 6.0);
  if (p == 0) {  // a multiple of I
    out[0] = out[1] = out[2] = q;
    return;
  }
  const double B[9] = {d0 / p, A[1] / p, A[2] / p, A[3] / p, d1 / p, A[5] / p, A[6] / p, A[7] / p, d2 / p};
  const double r = std::clamp(0.5 * material::det(B), -1.0, 1.0);
  const double phi = std::acos(r) / 3.0;
  constexpr double kThird = 2.0943951023931954923;  // 2 pi / 3
  out[0] = q + 2.0 * p * std::cos(phi);
  out[2] = q + 2.0 * p * std::cos(phi + kThird);
  out[1] = 3.0 * q - out[0] - out[2];
  std::sort(out, out + 3, std::greater<>());  // the middle one by difference may round past a neighbour
}

constexpr ViewFieldInfo kViewFields[kViewFieldCount] = {
    {"von_mises", "Pa", "von Mises stress of the Cauchy stress"},
    {"energy_density", "J/m^3", "strain-energy density psi(F) per rest volume"},
    {"stretch_max", "1", "largest principal stretch (1 at rest)"},
    {"stretch_min", "1", "smallest principal stretch (1 at rest)"},
};

}  // namespace

const ViewFieldInfo& view_field_info(ViewField f) { return kViewFields[int(f)]; }

bool parse_view_field(std::string_view name, ViewField* out) {
  for (int k = 0; k < kViewFieldCount; ++k)
    if (name == kViewFields[k].name) {
      *out = ViewField(k);
      return true;
    }
  return false;
}

std::string view_field_names() {
  std::string s;
  for (int k = 0; k < kViewFieldCount; ++k) s += std::string(k ? ", " : "") + kViewFields[k].name;
  return s;
}

ElementFieldRequest element_request(ViewFieldMask mask) {
  ElementFieldRequest r;
  r.von_mises = mask & view_field_bit(ViewField::VonMises);
  r.energy_density = mask & view_field_bit(ViewField::EnergyDensity);
  r.principal_stretches = mask & (view_field_bit(ViewField::StretchMax) | view_field_bit(ViewField::StretchMin));
  return r;
}

TetFields compute_tet_fields(MaterialModel m, const double* F, double lambda, double mu,
                             const ElementFieldRequest* ask) {
  TetFields f;
  double P[9];
  f.energy_density = material::stress(m, F, lambda, mu, P);
  // Only what was asked: the eigenvalues (two trigonometric calls a tet) are
  // the dearest part (embedding_bench's fields table guards this).
  const bool strain = !ask || ask->green_strain, stretches = !ask || ask->principal_stretches;
  const bool stress = !ask || ask->cauchy_stress || ask->von_mises;
  if (strain || stretches) {
    double C[9];
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        double c = 0;
        for (int k = 0; k < 3; ++k) c += F[3 * k + i] * F[3 * k + j];
        C[3 * i + j] = c;
        f.green[3 * i + j] = 0.5 * (c - (i == j ? 1.0 : 0.0));
      }
    if (stretches) {
      double eig[3];
      symmetric_eigenvalues(C, eig);
      for (int k = 0; k < 3; ++k) f.stretches[k] = std::sqrt(std::max(eig[k], 0.0));
    }
  }
  if (!stress) return f;
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
ElementFields compute_element_fields(const Model<Real>& model, const State<Real>& s, const ElementFieldRequest& ask,
                                     std::span<const int32_t> tets) {
  ElementFields out;
  if (!ask.any()) return out;
  const size_t nt = tets.empty() ? size_t(model.n_tets) : tets.size();
  if (ask.cauchy_stress) out.cauchy_stress.resize(9 * nt);
  if (ask.green_strain) out.green_strain.resize(9 * nt);
  if (ask.von_mises) out.von_mises.resize(nt);
  if (ask.energy_density) out.energy_density.resize(nt);
  if (ask.principal_stretches) out.principal_stretches.resize(3 * nt);
  const std::vector<Vec3>& X = model.mesh.X;
  auto u = [&](int32_t i) {
    const size_t j = 3 * size_t(i);
    return Vec3(double(s.u[j]), double(s.u[j + 1]), double(s.u[j + 2]));
  };
  for (size_t e = 0; e < nt; ++e) {
    const size_t id = tets.empty() ? e : size_t(tets[e]);
    // F at the element's points, each with the share of its volume it
    // stands for: a linear tet's one (constant strain), a quadratic tet's
    // four quadrature points (core/quadratic.hpp).
    std::array<glm::dmat3, 4> Fq;
    std::array<double, 4> share{1.0, 0.0, 0.0, 0.0};
    int points = 1;
    if (model.mesh.quadratic()) {
      // F = I + sum_a u_a (d N_a / d X)^T: exactly I at rest, as below.
      const P2Element el = make_p2_element(p2_rest_nodes(model.mesh, id));
      const double V = el.volume[0] + el.volume[1] + el.volume[2] + el.volume[3];
      points = 4;
      for (size_t q = 0; q < 4; ++q) {
        glm::dmat3 Du(0.0);  // Du[j][i] = d u_i / d X_j (glm column-major)
        for (int a = 0; a < kP2Nodes; ++a) {
          const Vec3 ua = u(model.mesh.node(id, a));
          for (int j = 0; j < 3; ++j) Du[j] += ua * el.grad[q][size_t(a)][j];
        }
        Fq[q] = glm::dmat3(1.0) + Du;
        share[q] = el.volume[q] / V;
      }
    } else {
      const Tet& t = model.mesh.tets[id];
      // Columns: edges from corner 0 (glm is column-major).
      const glm::dmat3 Dm(X[size_t(t[1])] - X[size_t(t[0])], X[size_t(t[2])] - X[size_t(t[0])],
                          X[size_t(t[3])] - X[size_t(t[0])]);
      // F = I + D_u D_m^-1 from the corners' displacements: exactly I at rest,
      // and no cancellation of positions where the strain is small.
      const Vec3 u0 = u(t[0]);
      const glm::dmat3 Du(u(t[1]) - u0, u(t[2]) - u0, u(t[3]) - u0);
      Fq[0] = glm::dmat3(1.0) + Du * glm::inverse(Dm);
    }
    if (ask.cauchy_stress) std::fill_n(out.cauchy_stress.begin() + long(9 * e), 9, 0.0);
    if (ask.green_strain) std::fill_n(out.green_strain.begin() + long(9 * e), 9, 0.0);
    if (ask.principal_stretches) std::fill_n(out.principal_stretches.begin() + long(3 * e), 3, 0.0);
    if (ask.von_mises) out.von_mises[e] = 0;
    if (ask.energy_density) out.energy_density[e] = 0;
    // A quadratic tet's value: the mean over its points, by their volume.
    for (size_t q = 0; q < size_t(points); ++q) {
      double F[9];
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) F[3 * i + j] = Fq[q][j][i];
      const TetFields f = compute_tet_fields(model.tet_model[id], F, model.tet_lambda[id], model.tet_mu[id], &ask);
      const double w = share[q];
      for (int k = 0; k < 9; ++k) {
        if (ask.cauchy_stress) out.cauchy_stress[9 * e + size_t(k)] += w * f.cauchy[k];
        if (ask.green_strain) out.green_strain[9 * e + size_t(k)] += w * f.green[k];
      }
      if (ask.von_mises) out.von_mises[e] += w * f.von_mises;
      if (ask.energy_density) out.energy_density[e] += w * f.energy_density;
      if (ask.principal_stretches)
        for (int k = 0; k < 3; ++k) out.principal_stretches[3 * e + size_t(k)] += w * f.stretches[k];
    }
  }
  return out;
}

template ElementFields compute_element_fields(const Model<float>&, const State<float>&, const ElementFieldRequest&,
                                              std::span<const int32_t>);
template ElementFields compute_element_fields(const Model<double>&, const State<double>&, const ElementFieldRequest&,
                                              std::span<const int32_t>);

}  // namespace tactile
