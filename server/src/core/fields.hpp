// Per-element fields for output (VTU cell data), computed from a state only
// when an output asks for them: not part of the step.
//
// F = I + D_u D_m^-1 per tet from the rest corner positions and their
// displacements, in double. The models give the first Piola-Kirchhoff stress P
// (core/material.hpp); the Cauchy stress is sigma = P F^T / det F, the Green
// strain E = (F^T F - I) / 2 (eq. 5), and the von Mises stress
// sqrt(3/2 s:s) with s = sigma - tr(sigma) I / 3. The linear model's stress
// is small-strain theory's, where P, sigma and the second Piola-Kirchhoff
// stress coincide: it is written as it is.
#pragma once

#include <cstdint>
#include <vector>

#include "core/model.hpp"
#include "core/state.hpp"

namespace tactile {

struct ElementFieldRequest {
  bool cauchy_stress = false;
  bool green_strain = false;
  bool von_mises = false;
  bool any() const { return cauchy_stress || green_strain || von_mises; }
};

// Tensors row-major, 9 entries per tet; empty when not asked for.
struct ElementFields {
  std::vector<double> cauchy_stress;  // sigma [Pa] (n_tets x 9)
  std::vector<double> green_strain;   // E [1] (n_tets x 9)
  std::vector<double> von_mises;      // [Pa] (n_tets)
};

// The fields `ask` names, per tet of the model (tets keep the mesh's ids). A
// tet flattened to det F = 0 has no Cauchy stress: NaN there.
template <class Real>
ElementFields compute_element_fields(const Model<Real>& model, const State<Real>& s, const ElementFieldRequest& ask);

// One tet's, from its F (row-major) and material; for the tests.
struct TetFields {
  double cauchy[9], green[9], von_mises;
};
TetFields compute_tet_fields(MaterialModel m, const double* F, double lambda, double mu);

}  // namespace tactile
