// Per-element fields for output (VTU cell data), computed from a state only
// when an output asks for them: not part of the step.
//
// F = I + D_u D_m^-1 per tet from the rest corner positions and their
// displacements, in double; a quadratic tet's fields are the mean of those
// at its four quadrature points, each weighted by the volume it stands for. The models give the first Piola-Kirchhoff
// stress P (core/material.hpp); the Cauchy stress is sigma = P F^T / det F, the Green strain E = (F^T F - I) / 2 (eq.
// 5), and the von Mises stress sqrt(3/2 s:s) with s = sigma - tr(sigma) I / 3, the strain-energy density psi(F) and the
// principal stretches, the square roots of the eigenvalues of C = F^T F (the singular values of F). The linear model's
// stress is small-strain theory's, where P, sigma and the second Piola-Kirchhoff stress coincide: it is written as it
// is.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/model.hpp"
#include "core/state.hpp"

namespace tactile {

struct ElementFieldRequest {
  bool cauchy_stress = false;
  bool green_strain = false;
  bool von_mises = false;
  bool energy_density = false;
  bool principal_stretches = false;
  bool any() const { return cauchy_stress || green_strain || von_mises || energy_density || principal_stretches; }
};

// Tensors row-major, 9 entries per tet; empty when not asked for.
struct ElementFields {
  std::vector<double> cauchy_stress;        // sigma [Pa] (n_tets x 9)
  std::vector<double> green_strain;         // E [1] (n_tets x 9)
  std::vector<double> von_mises;            // [Pa] (n_tets)
  std::vector<double> energy_density;       // psi [J/m^3] (n_tets)
  std::vector<double> principal_stretches;  // largest first [1] (n_tets x 3)
};

// The fields `ask` names, per tet of the model (tets keep the mesh's ids), or
// with `tets` given, per tet listed, in its order (a viewer's frame needs
// only the tets at its vertices). A tet flattened to det F = 0 has no Cauchy
// stress: NaN there.
template <class Real>
ElementFields compute_element_fields(const Model<Real>& model, const State<Real>& s, const ElementFieldRequest& ask,
                                     std::span<const int32_t> tets = {});

// The per-vertex fields a viewer may ask for in its state frames (protocol
// 1.8, live/frames.hpp): each a per-tet field above, averaged at the nodes.
enum class ViewField : uint8_t { VonMises, EnergyDensity, StretchMax, StretchMin };
inline constexpr int kViewFieldCount = 4;
using ViewFieldMask = uint32_t;  // bit (1 << ViewField)
struct ViewFieldInfo {
  const char* name;  // as the protocol and the scene's "view.fields" name it
  const char* unit;
  const char* description;
};
const ViewFieldInfo& view_field_info(ViewField f);
// The field named `name`, or false; the names are listed by view_field_names().
bool parse_view_field(std::string_view name, ViewField* out);
std::string view_field_names();  // "von_mises, energy_density, ..." for messages
constexpr ViewFieldMask view_field_bit(ViewField f) { return ViewFieldMask(1) << unsigned(f); }
// What the mask's fields need computed per tet.
ElementFieldRequest element_request(ViewFieldMask mask);

// One tet's, from its F (row-major) and material: those `ask` names (null:
// all; energy_density always, as the stress comes with it), the rest zero.
struct TetFields {
  double cauchy[9] = {}, green[9] = {}, von_mises = 0, energy_density = 0, stretches[3] = {};
};
TetFields compute_tet_fields(MaterialModel m, const double* F, double lambda, double mu,
                             const ElementFieldRequest* ask = nullptr);

}  // namespace tactile
