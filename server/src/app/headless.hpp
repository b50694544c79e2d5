// Headless runs: a scene for its duration, frame by frame, with its output in
// <out>/<scene name>/<variant or "run">/:
//   frame_000000.vtu ... and series.pvd   ParaView time series (unless disabled)
//   frames.csv                            time, tracked displacements, section areas, energies per frame
//   summary.json                          what ran, how fast, where things ended, the fault if any
//   forces.csv                            (scenes with proxies) per proxy per control interval: mean force
//                                         and torque on the proxy, contacts, its position
//   devices.csv                           (scenes with proxies) the same per device channel
// and, for a scene with variants, <out>/<scene name>/comparison.{csv,json}.
// The run stops at the first fault and still writes everything up to it.
//
// A scene with proxies advances in control intervals of about 1 ms, as a
// haptic device's loop would (never longer than a frame, a whole number of
// them per frame): before each, every scripted proxy and hand is given its
// motion over the interval from its script, the others hold their pose, and
// after it the mean force over the interval (impulse / elapsed) is recorded.
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
  bool progress = true;            // a bar on stderr, when it is a terminal and the run takes over a second
  std::ostream* log = nullptr;     // one line per thing done, when set
  double control_interval = 1e-3;  // longest control interval of a scene with proxies [s]
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

// What a proxy or a device channel felt: means over the last control interval.
struct ContactResult {
  std::string name;
  std::string device;     // for a proxy: its device channel
  Vec3 force{0.0};        // on the proxy (or the device's proxies) [N]
  Vec3 torque{0.0};       // about the proxy's (or device's reference) position [N m]
  int32_t contacts = 0;   // surface nodes inside, at the end
  Vec3 position{0.0};     // proxy position at the end [m] (proxies only)
  double peak_force = 0;  // largest interval-mean |force| of the run [N]
};

struct HeadlessResult {
  std::string scene, variant;
  std::string dir;     // the folder written
  Fault fault;         // kind None when the run finished
  int32_t frames = 0;  // frames completed after frame 0
  int64_t steps = 0;
  double t = 0;       // simulated time reached [s]
  double wall_s = 0;  // stepping time [s]
  Energy energy;      // at the end
  std::vector<TrackedResult> tracked;
  std::vector<SectionResult> sections;
  std::vector<ContactResult> proxies;  // (n_proxies)
  std::vector<ContactResult> devices;  // (n_devices)
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
