// tactile-sim: runs a scene headless, or checks it.
//
// Exit codes: 0 ok, 1 a fault during a run, 2 bad input (scene, mesh or
// command line; the message on stderr names the field at fault).
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "app/headless.hpp"
#include "app/progress.hpp"
#include "app/simulation.hpp"
#include "live/resim.hpp"
#include "record/mcap.hpp"
#include "core/model.hpp"
#include "mesh/mesh_error.hpp"
#include "scene/scene.hpp"

namespace {

using namespace tactile;

constexpr const char* kUsage =
    "usage:\n"
    "  tactile-sim run SCENE.json [options]   run a scene headless, write VTU frames, frames.csv, summary.json\n"
    "                                         (and forces.csv, devices.csv when it has proxies)\n"
    "  tactile-sim check SCENE.json           load and validate; print mesh quality and the critical step\n"
    "  tactile-sim resim RECORDING.mcap [--scene OTHER.json] [--variant V] [--out RESIM.mcap]\n"
    "                                         feed a recording's device inputs to the simulator again, each\n"
    "                                         before the same step as live; with its own scene the states come\n"
    "                                         out bit for bit as recorded (exit 1 when one differs); with\n"
    "                                         another, compare the two: tactile-recording compare REC RESIM\n"
    "  tactile-sim --help\n"
    "\n"
    "run options:\n"
    "  --out DIR                 output folder (default: out); writes DIR/<scene>/<variant or run>/\n"
    "  --duration S              simulated seconds, instead of the scene's run.duration\n"
    "  --precision float|double  instead of the scene's integrator.precision\n"
    "  --threads N               instead of the scene's integrator.threads\n"
    "  --variant NAME            run only this variant\n"
    "  --no-vtu                  no VTU frames (frames.csv and summary.json only)\n"
    "  --quiet                   no progress bar, no mesh report unless it warns\n"
    "\n"
    "exit status: 0 ok, 1 a fault stopped a run, 2 bad input\n";

struct BadInput {
  std::string message;
};

struct Options {
  std::string command, scene;
  std::string out = "out";
  std::optional<double> duration;
  std::optional<Precision> precision;
  std::optional<int32_t> threads;
  std::optional<std::string> variant;
  std::optional<std::string> other_scene, resim_out;
  bool vtu = true, quiet = false;
};

Options parse_args(int argc, char** argv) {
  Options o;
  std::vector<std::string_view> args(argv + 1, argv + argc);
  auto value = [&](size_t& i) {
    if (i + 1 >= args.size()) throw BadInput{std::string(args[i]) + " needs a value"};
    return std::string(args[++i]);
  };
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string_view a = args[i];
    if (a == "--help" || a == "-h") {
      o.command = "help";
      return o;
    }
    if (a == "--out") {
      o.out = value(i);
    } else if (a == "--duration") {
      const std::string s = value(i);
      char* end = nullptr;
      const double d = std::strtod(s.c_str(), &end);
      if (end == s.c_str() || *end || !(d > 0)) throw BadInput{"--duration must be a number of seconds > 0, got " + s};
      o.duration = d;
    } else if (a == "--precision") {
      const std::string s = value(i);
      if (s != "float" && s != "double") throw BadInput{"--precision must be float or double, got " + s};
      o.precision = s == "float" ? Precision::Float : Precision::Double;
    } else if (a == "--threads") {
      const std::string s = value(i);
      char* end = nullptr;
      const long n = std::strtol(s.c_str(), &end, 10);
      if (end == s.c_str() || *end || n < 1 || n > 256) throw BadInput{"--threads must be an integer in 1..256, got " + s};
      o.threads = int32_t(n);
    } else if (a == "--variant") {
      o.variant = value(i);
    } else if (a == "--scene") {
      o.other_scene = value(i);
    } else if (a == "--no-vtu") {
      o.vtu = false;
    } else if (a == "--quiet") {
      o.quiet = true;
    } else if (a.starts_with("-")) {
      throw BadInput{"unknown option " + std::string(a)};
    } else if (o.command.empty()) {
      o.command = a;
    } else if (o.scene.empty()) {
      o.scene = a;
    } else {
      throw BadInput{"unexpected argument " + std::string(a)};
    }
  }
  if (o.command.empty()) throw BadInput{"no command given"};
  if (o.command != "run" && o.command != "check" && o.command != "resim") throw BadInput{"unknown command " + o.command};
  if (o.scene.empty()) throw BadInput{o.command + (o.command == "resim" ? " needs a recording" : " needs a scene file")};
  if (o.other_scene && o.command != "resim") throw BadInput{"--scene is for resim"};
  return o;
}

std::string label(const Scene& s) { return s.name + (s.variant.empty() ? "" : " [" + s.variant + "]"); }

void print_quality(const Scene& s) {
  std::cout << "mesh of " << label(s) << ": " << s.quality.summary() << "\n";
}

int check(const Options& o) {
  tactile::MeshingProgress meshing(stderr, true);
  tactile::set_meshing_watch(&meshing);
  const std::vector<Scene> scenes = load_scene(o.scene);
  tactile::set_meshing_watch(nullptr);
  std::cout << o.scene << ": " << scenes.size() << " run(s)\n";
  for (const Scene& s : scenes) {
    print_quality(s);
    std::optional<Simulation> built;
    try {
      built.emplace(s.spec);  // builds the model: what the core refuses shows here
    } catch (const ModelError& e) {
      throw SceneError(o.scene + ": " + e.what());
    }
    const Simulation& sim = *built;
    const IntegratorSpec& in = s.spec.integrator;
    const double dt_rest = sim.dt_rest();
    const bool too_large = in.dt > dt_rest;
    // The step at rest: the fixed one where it is stable, else safety x critical (auto or subdivided).
    const double dt = in.dt > 0 && !too_large ? in.dt : in.safety * dt_rest;
    std::cout << "  critical step at rest " << dt_rest << " s; ";
    if (in.dt > 0 && too_large && in.unstable == UnstablePolicy::Refuse) {
      std::cout << "fixed step " << in.dt << " s is above it: a run will be refused\n";
      continue;
    }
    std::cout << (in.dt > 0 ? (too_large ? "fixed step above it, subdivided to " : "fixed step ") : "auto step ") << dt
              << " s: " << static_cast<long long>(std::ceil(1.0 / (s.run.frame_rate * dt))) << " sub-steps per frame, about "
              << std::llround(s.run.duration / dt) << " steps for " << s.run.duration
              << " s (more if the body is squashed or stiffened)\n";
  }
  std::cout << "ok\n";
  return 0;
}

int resim(const Options& o) {
  ResimOptions r;
  r.recording = o.scene;
  r.scene = o.other_scene.value_or("");
  r.variant = o.variant.value_or("");
  if (o.out != "out") r.out = o.out;  // (--out names the re-simulation's recording here)
  const ResimReport rep = resimulate(r);
  std::cout << "resim " << o.scene << " on scene " << rep.scene_name << ": " << rep.steps << " steps, " << rep.inputs
            << " inputs applied\n";
  if (!r.out.empty()) std::cout << "  wrote " << r.out << "\n";
  if (!rep.note.empty()) std::cout << "  note: " << rep.note << "\n";
  if (r.scene.empty()) {
    std::cout << "  states: " << rep.states_identical << " of " << rep.states_matched << " identical bit for bit; "
              << "haptic frames: " << rep.haptic_identical << " of " << rep.haptic_matched << "\n";
    const bool identical = rep.states_matched > 0 && rep.states_identical == rep.states_matched &&
                           rep.haptic_identical == rep.haptic_matched;
    if (!identical) {
      std::cout << "  first difference at t = " << rep.first_difference_time << " s; largest: position "
                << rep.max_position_difference << " m, force " << rep.max_force_difference << " N\n";
      return 1;
    }
    std::cout << "  identical\n";
  } else {
    std::cout << "  " << rep.states_matched << " states and " << rep.haptic_matched
              << " haptic frames at the recorded times; largest differences: position " << rep.max_position_difference
              << " m, force " << rep.max_force_difference << " N\n";
  }
  return 0;
}

int run(const Options& o) {
  tactile::MeshingProgress meshing(stderr, !o.quiet);
  tactile::set_meshing_watch(&meshing);
  std::vector<Scene> scenes = load_scene(o.scene);
  tactile::set_meshing_watch(nullptr);
  if (o.variant) {
    std::vector<Scene> picked;
    std::string names;
    for (Scene& s : scenes) {
      names += (names.empty() ? "" : ", ") + (s.variant.empty() ? std::string("(none)") : s.variant);
      if (s.variant == *o.variant) picked.push_back(std::move(s));
    }
    if (picked.empty()) throw SceneError(o.scene + ": no variant '" + *o.variant + "' (the scene has: " + names + ")");
    scenes = std::move(picked);
  }
  for (Scene& s : scenes) {
    if (o.duration) s.run.duration = *o.duration;
    if (o.precision) s.spec.integrator.precision = *o.precision;
    if (o.threads) s.spec.integrator.threads = *o.threads;
    if (!o.quiet || !s.quality.poor.empty()) print_quality(s);  // warnings about poor tets even when quiet
  }
  HeadlessOptions h;
  h.out_dir = o.out;
  h.write_vtu = o.vtu;
  h.progress = !o.quiet;
  h.log = &std::cout;
  std::vector<HeadlessResult> results;
  try {
    results = run_headless_all(scenes, h);
  } catch (const ModelError& e) {
    throw SceneError(o.scene + ": " + e.what());
  }
  int faults = 0;
  for (const HeadlessResult& r : results) faults += r.fault ? 1 : 0;
  if (faults) {
    std::cerr << "tactile-sim: " << faults << " run(s) stopped by a fault; see summary.json\n";
    return 1;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const Options o = parse_args(argc, argv);
    if (o.command == "help") {
      std::cout << kUsage;
      return 0;
    }
    if (o.command == "resim") return resim(o);
    return o.command == "check" ? check(o) : run(o);
  } catch (const BadInput& e) {
    std::cerr << "tactile-sim: " << e.message << "\n\n" << kUsage;
    return 2;
  } catch (const SceneError& e) {
    std::cerr << "tactile-sim: " << e.what() << "\n";
    return 2;
  } catch (const ModelError& e) {
    std::cerr << "tactile-sim: " << e.what() << "\n";
    return 2;
  } catch (const MeshError& e) {
    std::cerr << "tactile-sim: " << e.what() << "\n";
    return 2;
  } catch (const ResimError& e) {
    std::cerr << "tactile-sim: " << e.what() << "\n";
    return 2;
  } catch (const mcap::McapError& e) {
    std::cerr << "tactile-sim: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "tactile-sim: " << e.what() << "\n";
    return 2;
  }
}
