// The state of a body: everything a step carries to the next, as plain data
// the stepper writes (MuJoCo's mjData to the Model's mjModel). Copy it and
// the copy goes on bit for bit as the original would under the same inputs:
// re-simulation, checkpoints and carrying a body into a rebuilt model copy
// this one object. Arrays are in the model's node numbering (core/model.hpp);
// the Simulation (sim/simulation.hpp) speaks the mesh's.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/contact/contact_state.hpp"

namespace tactile {

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
  double kinetic = 0;         // 1/2 sum m |v|^2 [J]
  double elastic = 0;         // sum V psi(F) [J]
  double gravity = 0;         // -sum m g.u [J]
  double work_loads = 0;      // [J]
  double work_essential = 0;  // [J]
  double work_contact = 0;    // [J]
  double dissipated = 0;      // [J]
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

// The energy guard's account (core/energy_ledger.hpp): the energies of the
// latest step and what the balance is checked against.
struct EnergyLedger {
  Energy latest;            // as of the latest step
  bool open = false;        // a reference is taken (false before the first step and after a fault)
  double reference = 0;     // balance at the start of the current window [J]
  double window_start = 0;  // simulated time the current window started [s]
  double scale = 0;         // running max of the energy magnitudes [J]
  double dt = 0;            // the step the latest energies were measured with [s]
  double initial_ma2 = 0;   // sum m |a_0|^2 of the starting state
  // Energy the moving proxies gave since the start (sum of |F.v_proxy| dt): a
  // contact kick raises the kinetic energy at once, while its work on the
  // body (trapezoid) shows in the balance a step later.
  double proxy_given = 0;        // [J]
  std::vector<Vec3> load_force;  // load force at t_n per loaded node, flattened over loads [N]
};

// The critical step's refresh (core/critical_step.hpp): a sixteenth of the
// body each advance(), and the elements around the nodes contact pushed.
struct CriticalStepSweep {
  double dt = 0;                // estimate for the current configuration [s]
  int64_t refreshed_at = -1;    // step of the last complete sweep, -1 before the first
  double last = 0;              // estimate of the last complete sweep [s]
  double min = 0;               // of the sweep under way, so far [s]
  int32_t next = 0;             // first lane block the next call examines
  double collapsed_since = -1;  // when dt fell under kCollapsedStep of the rest step [s]; -1 while above
};

template <class Real>
struct State {
  std::vector<Real> u;  // displacement from rest [m] (n_nodes x 3)
  std::vector<Real> v;  // velocity [m/s] (n_nodes x 3)
  std::vector<Real> a;  // acceleration [m/s^2] (n_nodes x 3)
  double t = 0;         // simulated time [s]
  int64_t step = 0;     // steps taken

  // Energy accounting, accumulated by the stepper [J].
  double work_loads = 0;       // work of natural loads (gravity is a potential, not here)
  double work_essential = 0;   // work of essential BCs (prescribed motions) on the body
  double work_contact = 0;     // work of contact on the bodies (proxies, and between bodies)
  double dissipated = 0;       // energy removed by Rayleigh damping
  std::vector<Real> reaction;  // force the essential BCs exert on each constrained node [N] (n_constrained x 3)

  ContactState contact;        // proxies, coupled bodies and contact memory
  EnergyLedger energy;         // the guard's account; energy.latest is the latest step's
  CriticalStepSweep critical;  // the critical step's refresh
  Fault fault;                 // set by the step that found it; steps refuse until cleared
};

}  // namespace tactile
