// tactile-sim: runs a scene headless, or checks it.
//
// Exit codes: 0 ok, 1 a fault during a run, 2 bad input (scene, mesh or
// command line; the message on stderr names the field at fault).
#include <cmath>
#include <cstdio>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

#include "app/command_line.hpp"
#include "app/headless.hpp"
#include "app/progress.hpp"
#include "core/model.hpp"
#include "live/resim.hpp"
#include "mesh/mesh_error.hpp"
#include "record/mcap.hpp"
#include "scene/scene.hpp"
#include "sim/simulation.hpp"

namespace {

using namespace tactile;

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

// The command line's options, bound to `o`; a command sets o.command when it is given.
void add_options(CLI::App& app, Options& o, std::string& precision) {
  app.description("tactile-sim: runs a scene headless, or checks it.");
  app.footer("exit status: 0 ok, 1 a fault stopped a run, 2 bad input");
  app.require_subcommand(1);

  CLI::App* run = app.add_subcommand("run",
                                     "run a scene headless, write VTU frames, frames.csv, summary.json\n"
                                     "(and forces.csv, devices.csv when it has proxies)");
  run->add_option("SCENE.json", o.scene, "the scene file")->required()->type_name("");
  run->add_option("--out", o.out, "output folder; writes DIR/<scene>/<variant or run>/")
      ->type_name("DIR")
      ->capture_default_str();
  run->add_option("--duration", o.duration, "simulated seconds (> 0), instead of the scene's run.duration")
      ->type_name("S")
      ->check(positive_number());
  run->add_option("--precision", precision, "instead of the scene's integrator.precision")
      ->type_name("float|double")
      ->check(one_of({"float", "double"}));
  run->add_option("--threads", o.threads, "instead of the scene's integrator.threads (1 to 256)")
      ->type_name("N")
      ->check(CLI::Range(1, 256).description(""));
  run->add_option("--variant", o.variant, "run only this variant")->type_name("NAME");
  run->add_flag_callback(
      "--no-vtu", [&o] { o.vtu = false; }, "no VTU frames (frames.csv and summary.json only)");
  run->add_flag("--quiet", o.quiet, "no progress bar, no mesh report unless it warns");
  run->callback([&o] { o.command = "run"; });

  CLI::App* check = app.add_subcommand("check", "load and validate; print mesh quality and the critical step");
  check->add_option("SCENE.json", o.scene, "the scene file")->required()->type_name("");
  check->callback([&o] { o.command = "check"; });

  CLI::App* resim =
      app.add_subcommand("resim",
                         "feed a recording's device inputs to the simulator again, each before the same step as live;\n"
                         "with its own scene the states come out bit for bit as recorded (exit 1 when one differs);\n"
                         "with another, compare the two: tactile-recording compare REC RESIM");
  resim->add_option("RECORDING.mcap", o.scene, "the recording")->required()->type_name("");
  resim->add_option("--scene", o.other_scene, "simulate this scene instead of the recorded one")
      ->type_name("OTHER.json");
  resim->add_option("--variant", o.variant, "the variant to run (default: the recorded one, or the first)")
      ->type_name("V");
  resim->add_option("--out", o.resim_out, "write the re-simulation as a recording")->type_name("RESIM.mcap");
  resim->callback([&o] { o.command = "resim"; });
}

std::string label(const Scene& s) { return s.name + (s.variant.empty() ? "" : " [" + s.variant + "]"); }

void print_quality(const Scene& s) { std::cout << "mesh of " << label(s) << ": " << s.quality.summary() << "\n"; }

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
    if (sim.mass_scaled_tets() > 0)
      std::cout << "  mass scaling to " << in.mass_scaling_dt << " s: " << sim.mass_scaled_tets()
                << " tet(s) made denser, " << sim.added_mass() << " kg added ("
                << 100.0 * sim.added_mass() / (sim.total_mass() - sim.added_mass()) << " % of "
                << sim.total_mass() - sim.added_mass() << " kg)\n";
    std::cout << "  critical step at rest " << dt_rest << " s; ";
    if (in.dt > 0 && too_large && in.unstable == UnstablePolicy::Refuse) {
      std::cout << "fixed step " << in.dt << " s is above it: a run will be refused\n";
      continue;
    }
    std::cout << (in.dt > 0 ? (too_large ? "fixed step above it, subdivided to " : "fixed step ") : "auto step ") << dt
              << " s: " << static_cast<long long>(std::ceil(1.0 / (s.run.frame_rate * dt)))
              << " sub-steps per frame, about " << std::llround(s.run.duration / dt) << " steps for " << s.run.duration
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
  r.out = o.resim_out.value_or("");
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
    std::cout << "  peak proxy force " << rep.peak_force << " N (recorded: " << rep.recorded_peak_force << " N)\n";
  }
  return 0;
}

int run(const Options& o) {
  tactile::MeshingProgress meshing(stderr, !o.quiet);
  tactile::set_meshing_watch(&meshing);
  std::vector<Scene> scenes = load_scene(o.scene);
  tactile::set_meshing_watch(nullptr);
  if (o.variant) scenes = {pick_variant(std::move(scenes), *o.variant, o.scene)};
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
  Options o;
  std::string precision;
  CLI::App app("", "tactile-sim");
  configure_command_line(app);
  add_options(app, o, precision);
  if (const std::optional<int> status = parse_command_line(app, argc, argv)) return *status;
  if (!precision.empty()) o.precision = precision == "float" ? Precision::Float : Precision::Double;
  try {
    if (o.command == "resim") return resim(o);
    return o.command == "check" ? check(o) : run(o);
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
