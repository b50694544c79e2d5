// The state of a body: plain arrays the stepper writes. Copyable, comparable.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace tactile {

template <class Real>
struct State {
  std::vector<Real> u;  // displacement from rest [m] (n_nodes x 3)
  std::vector<Real> v;  // velocity [m/s] (n_nodes x 3)
  std::vector<Real> a;  // acceleration [m/s^2] (n_nodes x 3)
  double t = 0;         // simulated time [s]
  int64_t step = 0;     // steps taken

  // Energy accounting, accumulated by the stepper [J].
  double work_loads = 0;      // work of natural loads (gravity is a potential, not here)
  double work_essential = 0;  // work of essential BCs (prescribed motions) on the body
  double work_contact = 0;    // work of proxy contacts on the body
  double dissipated = 0;      // energy removed by Rayleigh damping
  std::vector<Real> reaction; // force the essential BCs exert on each constrained node [N] (n_constrained x 3)
};

template <class Real>
State<Real> make_rest_state(int32_t n_nodes, int32_t n_constrained) {
  State<Real> s;
  s.u.assign(3 * static_cast<size_t>(n_nodes), Real(0));
  s.v = s.u;
  s.a = s.u;
  s.reaction.assign(3 * static_cast<size_t>(n_constrained), Real(0));
  return s;
}

// What went wrong in a step: detected within that step, reported, and the
// stepper refuses to go on until the state is reset.
struct Fault {
  enum class Kind : uint8_t { None, NonFinite, Inverted, EnergyGrowth, StepTooLarge };
  Kind kind = Kind::None;
  int64_t step = 0;
  double t = 0;
  std::string message;
  std::vector<int32_t> elements;  // tets at fault (at most a few dozen)
  explicit operator bool() const { return kind != Kind::None; }
};
const char* to_string(Fault::Kind k);

struct Energy {
  double kinetic = 0;      // 1/2 sum m |v|^2 [J]
  double elastic = 0;      // sum V psi(F) [J]
  double gravity = 0;      // -sum m g.u [J]
  double work_loads = 0;   // [J]
  double work_essential = 0;  // [J]
  double work_contact = 0;    // [J]
  double dissipated = 0;   // [J]
  // Central differences conserve 1/2 m v_{n-1/2}.v_{n+1/2} rather than
  // 1/2 m |v_n|^2; the difference is -dt^2/8 sum m |a|^2 [J].
  double discrete = 0;
  // The sum of the changes of `discrete` made by restating it with a new
  // step size (not energy the body gained or lost) [J].
  double restated = 0;
  // Conserved: kinetic + elastic + gravity - work_loads - work_essential - work_contact + dissipated.
  double balance() const {
    return kinetic + discrete - restated + elastic + gravity - work_loads - work_essential - work_contact + dissipated;
  }
};

}  // namespace tactile
