// The 10-node quadratic tetrahedron (P2, "T10"): its shape functions, the
// quadrature its element pass integrates with, its lumped mass, and the edge
// nodes a linear mesh gains to become one. Pure functions of plain data.
//
// Node order, VTK's (VTK_QUADRATIC_TETRA, so a VTU shows it as it is): the
// corners 0-3, then the edge midpoints 4 (0-1), 5 (1-2), 6 (0-2), 7 (0-3),
// 8 (1-3), 9 (2-3). In reference coordinates xi = (r, s, t), the barycentric
// coordinates are L0 = 1 - r - s - t, L1 = r, L2 = s, L3 = t; a corner's
// shape function is L_i (2 L_i - 1), an edge's 4 L_i L_j.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "core/material.hpp"
#include "core/mesh.hpp"

namespace tactile {

inline constexpr int kP2Nodes = 10;

// The ten shape functions at reference point xi.
std::array<double, kP2Nodes> p2_shape(const Vec3& xi);
// Their gradients in reference coordinates (d N_a / d xi).
std::array<Vec3, kP2Nodes> p2_shape_gradients(const Vec3& xi);
// The reference coordinates of node a (corners at the unit tet's vertices).
Vec3 p2_node_xi(int a);

// A quadrature point in reference coordinates and its weight: the weights sum
// to 1/6, the reference tet's volume, so that a physical integral is
// sum w_q f(xi_q) det J.
struct QuadraturePoint {
  Vec3 xi;
  double weight;
};
// The barycentric coordinates of tet_quadrature_4's points: point q has a at
// corner q and b at the other three, a = (5 + 3 sqrt 5) / 20, b = (5 - sqrt 5) / 20.
inline constexpr double kTetQuadratureA = 0.58541019662496845446, kTetQuadratureB = 0.13819660112501051518;

// Four points, exact for polynomials of degree 2: the stiffness of linear
// elasticity on an affine P2 tet (gradients of degree 1, their products of
// degree 2) exactly, and the nonlinear models' stress at the points a
// degree-2 rule needs (Keast's rule 2; Zienkiewicz, Taylor & Zhu, table 6.3).
const std::array<QuadraturePoint, 4>& tet_quadrature_4();

// d N_a / d xi at the four points of tet_quadrature_4 ([q][a][k]), as
// constants the lane kernel folds (core/kernels/kernels_impl.hpp): the
// values p2_shape_gradients gives there.
struct P2PointGradients {
  double g[4][kP2Nodes][3];
};
constexpr P2PointGradients make_p2_point_gradients() {
  constexpr double dL[4][3] = {{-1, -1, -1}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};  // d L_i / d xi
  P2PointGradients out{};
  for (int q = 0; q < 4; ++q) {
    double L[4] = {kTetQuadratureB, kTetQuadratureB, kTetQuadratureB, kTetQuadratureB};
    L[q] = kTetQuadratureA;
    for (int i = 0; i < 4; ++i)
      for (int k = 0; k < 3; ++k) out.g[q][i][k] = (4 * L[i] - 1) * dL[i][k];
    for (int e = 0; e < 6; ++e) {
      const int i = kTetEdges[e][0], j = kTetEdges[e][1];
      for (int k = 0; k < 3; ++k) out.g[q][4 + e][k] = 4 * (L[j] * dL[i][k] + L[i] * dL[j][k]);
    }
  }
  return out;
}
inline constexpr P2PointGradients kP2PointGradients = make_p2_point_gradients();

// The HRZ lumped mass of a straight-sided T10 as fractions of its mass
// (Hinton, Rock & Zienkiewicz 1976): each node's diagonal of the consistent
// mass matrix, scaled so the ten sum to the element's mass. Corners get
// 1/36 and edges 4/27, every one positive; row-sum lumping would give the
// corners -1/20, a negative mass no explicit step survives.
const std::array<double, kP2Nodes>& p2_lumped_mass_fractions();

// A linear mesh made quadratic (TetMesh::edges): one node at the midpoint
// of each edge, shared by every tet around the edge, appended after the
// corners (which keep their ids) in the order the tets first meet them.
TetMesh make_quadratic_mesh(const TetMesh& linear);

// The ten rest positions of quadratic tet e [m].
std::array<Vec3, kP2Nodes> p2_rest_nodes(const TetMesh& mesh, size_t e);

// The HRZ lumped mass of each node of a straight quadratic mesh [kg]
// (n_nodes): each tet gives 1/36 of its mass to each corner and 4/27 to
// each edge node. rho per tet [kg/m^3], volume per tet [m^3].
std::vector<double> compute_quadratic_lumped_masses(const TetMesh& mesh, const std::vector<double>& rho,
                                                    const std::vector<double>& volume);

// ---- one element, scalar: the reference the lane kernels are checked against ----

// The rest constants of one T10 (isoparametric: its edge nodes may sit off
// the midpoints, on a curved boundary): per quadrature point, the shape
// functions' gradients in rest coordinates, d N_a / d X, and the rest volume
// the point stands for, w_q det J_q.
struct P2Element {
  std::array<std::array<Vec3, kP2Nodes>, 4> grad;  // [q][a]
  std::array<double, 4> volume;                    // [m^3] per point
  double min_det = 0;                              // the least det J_q: > 0 for a valid element
};
P2Element make_p2_element(const std::array<Vec3, kP2Nodes>& X);

// The element's elastic energy sum_q w_q det J_q psi(F_q) [J] at positions
// x, and each node's elastic force f_a = -dE/dx_a [N]:
// F_q = sum_a x_a (d N_a / d X)^T, f_a = -sum_q w_q det J_q P(F_q) d N_a / d X.
double compute_p2_forces(const P2Element& element, const std::array<Vec3, kP2Nodes>& x, MaterialModel model,
                         double lambda, double mu, std::array<Vec3, kP2Nodes>* f);

// The critical step of one straight-sided T10 at rest [s]: 2 / omega_max of
// its stiffness (linear elasticity, the tangent every model has at rest)
// against its HRZ-lumped mass, the 30 x 30 element eigenproblem solved
// exactly. By Irons' element eigenvalue theorem the assembled body's step is
// at least the least of these, as for the linear tet
// (compute_element_critical_dt in core/model.hpp).
double compute_p2_critical_dt(const std::array<Vec3, kP2Nodes>& X, double lambda, double mu, double rho);

}  // namespace tactile
