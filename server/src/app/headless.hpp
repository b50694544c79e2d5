// Headless runs: a scene for its duration, frame by frame, with its output in
// <out>/<scene name>/<variant or "run">/:
//   frame_000000.vtu ... and series.pvd   ParaView time series (unless disabled)
//   frames.csv                            time, tracked displacements, section areas, energies per frame
//   summary.json                          what ran, how fast, where things ended, the fault if any
// and, for a scene with variants, <out>/<scene name>/comparison.{csv,json}.
// The run stops at the first fault and still writes everything up to it.
#pragma once

#include <cstdint>
#include <iosfwd>
#include <string>
#include <vector>

#include "core/state.hpp"
#include "scene/scene.hpp"

namespace tactile {

struct HeadlessOptions {
  std::string out_dir = "out";
  bool write_vtu = true;
  bool progress = true;           // a bar on stderr, when it is a terminal and the run takes over a second
  std::ostream* log = nullptr;    // one line per thing done, when set
};

struct TrackedResult {
  std::string name;
  int32_t node = -1;
  Vec3 X{0.0};  // rest position [m]
  Vec3 u{0.0};  // final displacement [m]
};

struct SectionResult {
  std::string name;
  double rest_area = 0;  // [m^2]
  double area = 0;       // deformed material section at the end [m^2]
};

struct HeadlessResult {
  std::string scene, variant;
  std::string dir;       // the folder written
  Fault fault;           // kind None when the run finished
  int32_t frames = 0;    // frames completed after frame 0
  int64_t steps = 0;
  double t = 0;          // simulated time reached [s]
  double wall_s = 0;     // stepping time [s]
  Energy energy;         // at the end
  std::vector<TrackedResult> tracked;
  std::vector<SectionResult> sections;
  bool ok() const { return !fault; }
};

// Runs one scene (one variant). Throws ModelError when the core refuses the
// spec, std::runtime_error when output cannot be written.
HeadlessResult run_headless(const Scene& scene, const HeadlessOptions& options);

// <dir>/comparison.csv and comparison.json: final tracked displacements and
// section areas per variant.
void write_comparison(const std::string& dir, const std::vector<HeadlessResult>& results);

// Runs each scene in turn and, when they are variants, writes the comparison
// into <out>/<scene name>/. A fault in one does not stop the others.
std::vector<HeadlessResult> run_headless_all(const std::vector<Scene>& scenes, const HeadlessOptions& options);

}  // namespace tactile
