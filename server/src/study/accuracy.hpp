// What accuracy costs in time: the error of each choice -- material model,
// mesh resolution, time step (as a fraction of the critical step) and
// precision -- against references, beside what the choice costs to run.
//
// Problems and their references:
//   cantilever_deflection  small tip load, static: Timoshenko beam theory
//   cantilever_frequency   first bending mode, free: Euler-Bernoulli
//   wave_speed             a long pulse along a free bar: the bar velocity sqrt(E / rho)
//   fig3_tip               the paper's Fig. 3 beam sagging under gravity (large deflection): a converged
//                          fine-mesh StVK run in double
//   fig2_area              the paper's Fig. 2 column twisted 90 degrees, mid-height section area: likewise
//   rotation               a body turned rigidly by 90 degrees: elastic energy and volume change, which
//                          should be zero (the invariance the paper is about)
// and the cost: wall time per step and tet-steps per second on one core, and,
// per material and precision, the largest mesh of the live poke block that
// keeps 1 kHz real time (one 1 ms interval stepped in under 1 ms).
//
// `tactile-accuracy` (cli/) writes the records as JSON; the report
// (server/bench/accuracy_report.py) plots them.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace tactile::study {

struct AccuracyRecord {
  std::string problem;
  std::string material;
  int32_t level = 0;  // mesh resolution (1 coarsest)
  int32_t tets = 0;
  double safety = 0.9;    // time step as a fraction of the critical step
  std::string precision;  // "float" or "double"
  double value = 0;       // what was measured (the problem's own unit)
  double reference = 0;   // what it should be
  double error = 0;       // relative to the reference's scale (signed where it has a sign)
  std::string unit;       // of value and reference
  int64_t steps = 0;
  double sim_time = 0;  // [s]
  double wall_s = 0;    // stepping only [s]
  double us_per_step = 0;
  double tet_steps_per_s = 0;
  std::string fault;  // a fault that stopped the run, if any
};

struct RealtimeRecord {
  std::string material, precision;
  // Per mesh tried, smallest first: tets, the median wall time of a 1 ms interval [ms], its sub-steps.
  std::vector<int32_t> tets;
  std::vector<double> interval_ms;
  std::vector<int32_t> substeps;
  int32_t largest_realtime_tets = 0;  // the largest tried whose interval took under 1 ms
  double estimated_max_tets = 0;      // interpolated (log-log) to 1 ms between the sizes bracketing it
};

struct AccuracyOptions {
  bool quick = false;                    // coarser levels and fewer variations: seconds, for the test suite
  std::string scenes = "server/scenes";  // where fig2_twist.json and fig3_cantilever.json are
  std::string only;                      // a problem name, or empty for all
  // Told before each run: how many done, how many in all, what runs next.
  std::function<void(size_t done, size_t total, const std::string& what)> progress;
};

struct AccuracyResults {
  std::vector<AccuracyRecord> records;
  std::vector<RealtimeRecord> realtime;
};

AccuracyResults run_accuracy_study(const AccuracyOptions& options);

}  // namespace tactile::study
