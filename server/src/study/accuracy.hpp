// What accuracy costs in time: the error of each choice -- element order
// (linear P1 or quadratic P2 tets), material model, mesh resolution, time
// step (as a fraction of the critical step) and precision -- against
// references, beside what the choice costs to run.
//
// Problems and their references:
//   cantilever_deflection  small tip load, static: Timoshenko beam theory
//   cantilever_frequency   first bending mode, free: Euler-Bernoulli
//   wave_speed             a long pulse along a free bar: the bar velocity sqrt(E / rho)
//   fig3_tip               the paper's Fig. 3 beam sagging under gravity (large deflection): a converged
//                          fine-mesh StVK run in double, on quadratic tets
//   fig2_area              the paper's Fig. 2 column twisted 90 degrees, mid-height section area: likewise
//   rotation               a body turned rigidly by 90 degrees: elastic energy and volume change, which
//                          should be zero (the invariance the paper is about)
//   hertz_radius,          two equal soft spheres pressed together (spheres_press.json), through their
//   hertz_approach         own contact: the contact radius and the approach of their centres at three
//                          loads, against Hertz's two-body solution at the load measured
// and the cost: wall time per step and tet-steps per second on one core, and,
// per material and precision, the largest mesh of the live poke block that
// keeps 1 kHz real time (one 1 ms interval stepped in under 1 ms).
//
// `tactile-accuracy` (cli/) writes the records as JSON; the report
// (server/bench/accuracy_report.py) plots them.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace tactile::study {

struct AccuracyRecord {
  std::string problem;
  std::string material;
  std::string element = "p1";  // "p1" (linear tets) or "p2" (quadratic)
  int32_t level = 0;           // mesh resolution (1 coarsest)
  int32_t tets = 0;
  int32_t nodes = 0;
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
  // fig3_tip and its reference run: the tip's displacement [m], which the error is measured on.
  std::array<double, 3> tip{};
  double load = 0;  // hertz_*: the load the two spheres were pressed together with [N]
};

struct RealtimeRecord {
  std::string material, precision;
  std::string element = "p1";
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

// The whole study, one run after the other.
AccuracyResults run_accuracy_study(const AccuracyOptions& options);

// One run of the study. run_accuracy_study runs them in order; tactile-batch
// runs each as a task on a Dask cluster (server/python/tactile/batch.py).
struct AccuracyCase {
  std::string label;    // what a progress bar shows
  std::string problem;  // a problem above, or "fig3_reference", "fig2_reference", "realtime"
  std::string material;
  std::string element = "p1";
  int32_t level = 0;
  std::string precision;
  double safety = 0;  // the time step's fraction of the critical step; 0: the problem's own
  bool quick = false;
};

// The study's runs for `options` (its scenes and progress aside), in the order it runs them.
std::vector<AccuracyCase> list_accuracy_cases(const AccuracyOptions& options);
// One run's results: its records (a reference run's, problem "fig3_reference" or "fig2_reference", too) or
// its real-time record. Throws std::invalid_argument for a case list_accuracy_cases does not make.
AccuracyResults run_accuracy_case(const AccuracyCase& c, const std::string& scenes);
// The figures' references and errors from their reference runs' records, which it then drops: the runs'
// results, gathered in list order, become the study's.
void finish_accuracy(AccuracyResults& results);

// The results as JSON: {"quick", "records", "realtime"}, tactile-accuracy's file (accuracy.json) that
// server/bench/accuracy_report.py plots; and back (a run's results travel between processes so).
std::string accuracy_json(const AccuracyResults& results, bool quick);
AccuracyResults accuracy_from_json(const std::string& text);

}  // namespace tactile::study
