// Closed-form references for a cantilever of length L along x with a square
// section h (clamped at x = 0): Timoshenko's tip deflection under an end
// shear P, with Cowper's shear coefficient kappa = 10 (1 + nu) / (12 + 11 nu),
// and Euler-Bernoulli's first bending mode. The accuracy study
// (study/accuracy.cpp) and the core's physics tests check the FEM against
// this one copy. Header-only: no dependency but <cmath>.
#pragma once

#include <cmath>

namespace tactile {

struct CantileverTheory {
  double L = 1.0, h = 0.1;                                                               // length and section side [m]
  double E = 1e6, nu = 0.3, rho = 1000;                                                  // [Pa], [-], [kg/m^3]
  double I() const { return h * h * h * h / 12; }                                        // second moment of area [m^4]
  double A() const { return h * h; }                                                     // [m^2]
  double omega1() const { return 3.5160 * std::sqrt(E * I() / (rho * A())) / (L * L); }  // first mode [rad/s]
  double f1() const { return 0.55959 * std::sqrt(E * I() / (rho * A())) / (L * L); }     // [Hz]
  // Tip deflection under an end shear P [N]: bending P L^3 / (3 E I) plus shear P L / (kappa G A) [m].
  double deflection(double P) const {
    const double G = E / (2 * (1 + nu)), kappa = 10 * (1 + nu) / (12 + 11 * nu);
    return P * L * L * L / (3 * E * I()) + P * L / (kappa * G * A());
  }
};

}  // namespace tactile
