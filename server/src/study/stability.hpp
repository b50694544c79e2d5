// The hard-case stability suite: the explicit FEM pushed where explicit FEM
// breaks -- large twists and spins, compression past StVK's limit, inverted
// and flattened elements, near-incompressible, very soft and stiff
// materials, time steps above the critical one, fast and pinching proxies,
// sliver meshes, random velocities, a long run of random device input, and
// soft bodies meeting soft bodies (a stack dropped, a ball thrown at a block,
// a beam folded onto itself) -- each case at two mesh resolutions and for
// every material it applies to, and on the coarse meshes made quadratic (P2;
// the quick suite runs the hard ones there: twist, squash past inversion,
// inverted start, strike, slivers, too long a step, random velocities, the
// stack and the fold).
//
// A case passes when
//   - every position and velocity stays finite, at every control interval;
//   - the body's bounding box stays within twice its rest size (its
//     diagonal), unless the case's load says otherwise;
//   - on a conservative run (no damping, contact or moving boundary), the
//     energy balance drifts by at most 10 % of the energy in play;
//   - no surface node tunnels through a proxy (goes deeper than the proxy's
//     trust depth and comes out on the side opposite its way in); how deep
//     nodes sit is reported, the contact's accuracy rather than stability;
//   - in a scene of several bodies, or with self contact, no surface node
//     goes deeper into another body (or into its own, away from its own
//     neighbourhood) than 0.5 mm or 2 % of the smallest surface edge,
//     whichever is smaller, and the momentum body contact gives the bodies
//     sums to zero (1e-9 of what it gives);
//   - what it expects happens: `Runs` ends without a fault; `Caught` has a
//     step above the critical one subdivided or refused, never run. A fault
//     must name its kind and the elements at fault, and the simulation stays
//     stopped after it (no step, no force: the server then stops
//     publishing, and the bridge takes the force to zero).
//
// The suite is plain C++ over the core (Simulation); `tactile-stability`
// (cli/) prints it as a table, and the short version runs in ctest.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace tactile::study {

enum class Expect : uint8_t {
  Runs,    // no fault
  Caught,  // a step above the critical one: subdivided or refused
};
const char* to_string(Expect e);

struct CaseOutcome {
  std::string name;  // "group/material/mesh"
  std::string group, material, mesh;
  Expect expect = Expect::Runs;
  bool pass = false;
  std::string outcome;  // what happened, in words ("ran", "fault: inverted at t = ...", "subdivided x4")
  std::string why;      // the first check that failed; empty on a pass
  int32_t tets = 0;
  int64_t steps = 0;
  double sim_time = 0;        // [s]
  double wall_s = 0;          // [s]
  double size_ratio = 0;      // largest bounding-box diagonal over the rest one
  double size_limit = 2.0;    // what the case allows
  double energy_drift = -1;   // |balance change| / energy in play; -1 when the run is not conservative
  double penetration_mm = 0;  // deepest surface node inside a proxy at a control instant [mm]
  double peak_force_N = -1;   // largest mean force on a device over a control interval; -1 without proxies
  // Scenes of several bodies, or with self contact: the deepest a surface node of one body was inside another
  // (or inside its own body, away from its own neighbourhood) at a control instant [mm], what the case
  // allows, and the largest |sum of the momentum body contact gave the bodies in a step| over the sum of
  // its sizes (0 exactly: it passes between them); -1 where the case has no body contact.
  double body_depth_mm = -1;
  double body_depth_limit_mm = -1;
  double momentum_residual = -1;
  int32_t substeps_max = 0;  // most sub-steps in one control interval
};

struct SuiteOptions {
  bool quick = false;  // the short version: the coarse meshes and shorter runs
  std::string filter;  // run only cases whose name contains this
  uint64_t seed = 1;   // random velocities and device input
};

struct StabilityCase {
  std::string name;
  std::function<CaseOutcome()> run;
};

// The suite's cases, in a fixed order, built lazily (a case builds its mesh
// when run).
std::vector<StabilityCase> stability_cases(const SuiteOptions& options);

// The case named `name` (options.filter aside), run; throws
// std::invalid_argument when the suite has none of that name. tactile-batch
// runs each case so, as a task on a Dask cluster.
CaseOutcome run_stability_case(SuiteOptions options, const std::string& name);

// A case's outcome as a JSON object (tactile-stability --json writes a list of them).
std::string outcome_json(const CaseOutcome& r);

}  // namespace tactile::study
