// What an embedded surface and per-vertex fields cost (issue 27): the organ
// scene's step with its fine surface (contact on the surface's vertices,
// their impulses spread to their tets' nodes) against the same body touched
// on its own boundary nodes and faces, with its proxy waiting above and
// pressed 5 mm in; and the state frame's encoding with no field, each field
// and all of them. Prints figures, passes and fails nothing.
//
//   build/release/embedding_bench [--scene server/scenes/organ.json] [--rounds 5]
//
// Times are medians over alternated rounds (the variants take turns, so that
// the machine's load shifts them alike), per step or per frame.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <optional>
#include <string>
#include <vector>

#include "app/command_line.hpp"
#include "core/fields.hpp"
#include "live/frames.hpp"
#include "scene/scene.hpp"
#include "sim/simulation.hpp"

namespace tactile {
namespace {

using Clock = std::chrono::steady_clock;

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

// A simulation of the scene, its first proxy brought to `depth` [m] below
// where it waits (0: left there) over 0.5 s and held for 0.2 s.
struct Body {
  Simulation sim;
  Body(const ModelSpec& spec, double drop) : sim(spec) {
    if (sim.proxies().empty()) return;
    ProxyMotion m;
    m.t0 = 0.0;
    m.t1 = 0.5;
    m.from = sim.proxy_pose(0);
    m.to = m.from;
    m.to.position.y -= drop;
    sim.set_proxy_motion(0, m);
    while (sim.time() < 0.7) {
      sim.advance(1e-3);
      sim.clear_impulses();
    }
  }
  // Wall time per step over `steps` steps in 1 ms advances.
  double time_steps(int64_t steps) {
    const int64_t first = sim.steps();
    const Clock::time_point t0 = Clock::now();
    while (sim.steps() - first < steps) {
      sim.advance(1e-3);
      sim.clear_impulses();
    }
    return std::chrono::duration<double>(Clock::now() - t0).count() / double(sim.steps() - first);
  }
  // The mean force on the first proxy over the next 10 ms [N].
  double mean_force() {
    sim.clear_impulses();
    sim.advance(1e-2);
    const ProxyReport& r = sim.proxy_reports()[0];
    const double f = r.elapsed > 0 ? glm::length(r.impulse) / r.elapsed : 0.0;
    sim.clear_impulses();
    return f;
  }
};

int run(const std::string& path, int rounds) {
  const Scene scene = load_scene(path).front();
  ModelSpec boundary = scene.spec;
  boundary.surface = nullptr;
  if (!scene.spec.surface) {
    std::fprintf(stderr, "embedding_bench: %s has no \"surface\"\n", path.c_str());
    return 2;
  }
  // The proxy waits 14 mm above the organ's top and has a 6 mm radius: 22 mm down presses it about 5 mm in.
  const double kDrop = 0.022;
  std::printf("# Embedded surface and per-vertex fields: %s\n\n", scene.name.c_str());
  Body probe(scene.spec, 0.0);
  std::printf("%d tets, %d nodes; fine surface of %d vertices and %zu triangles; %s; %.0f steps a second\n\n",
              probe.sim.n_tets(), probe.sim.n_nodes(), scene.spec.surface->n_vertices(),
              scene.spec.surface->rest.triangles.size(), probe.sim.precision() == Precision::Float ? "float" : "double",
              double(probe.sim.steps()) / probe.sim.time());

  std::printf("## The step, us (median of %d alternated rounds of 2000 steps)\n\n", rounds);
  std::printf(
      "| proxy             | on its fine surface | on its boundary | difference | force N (surface / boundary) |\n");
  std::printf(
      "|-------------------|---------------------|-----------------|------------|------------------------------|\n");
  for (const double drop : {0.0, kDrop}) {
    Body fine(scene.spec, drop), coarse(boundary, drop);
    std::vector<double> a, b;
    for (int r = 0; r < rounds; ++r) {
      a.push_back(fine.time_steps(2000));
      b.push_back(coarse.time_steps(2000));
    }
    const double ta = median(a) * 1e6, tb = median(b) * 1e6;
    std::printf("| %-17s | %19.1f | %15.1f | %+9.1f%% | %12.3f / %-13.3f |\n",
                drop > 0 ? "pressed 5 mm in" : "waiting above", ta, tb, 100.0 * (ta / tb - 1.0), fine.mean_force(),
                coarse.mean_force());
  }

  std::printf("\n## A state frame, us per frame (FrameEncoder::state_frame, proxy pressed; median of %d rounds)\n\n",
              rounds);
  std::printf("| fields asked for         | us per frame | bytes | share of a core at 30 Hz |\n");
  std::printf("|--------------------------|--------------|-------|--------------------------|\n");
  Body pressed(scene.spec, kDrop);
  FrameEncoder frames(pressed.sim, scene.name, 1, 0.0);
  std::vector<std::pair<std::string, ViewFieldMask>> cases = {{"none", 0}};
  ViewFieldMask all = 0;
  for (int k = 0; k < kViewFieldCount; ++k) {
    cases.emplace_back(view_field_info(ViewField(k)).name, view_field_bit(ViewField(k)));
    all |= view_field_bit(ViewField(k));
  }
  cases.emplace_back("all four", all);
  for (const auto& [name, mask] : cases) {
    frames.state_frame(0, mask);  // (the first builds the map of tets to vertices)
    std::vector<double> t;
    size_t bytes = 0;
    for (int r = 0; r < rounds; ++r) {
      const Clock::time_point t0 = Clock::now();
      for (int k = 0; k < 50; ++k) bytes = frames.state_frame(k, mask).size();
      t.push_back(std::chrono::duration<double>(Clock::now() - t0).count() / 50);
    }
    const double us = median(t) * 1e6;
    std::printf("| %-24s | %12.1f | %5zu | %23.2f%% |\n", name.c_str(), us, bytes, us * 30 / 1e4);
  }
  return 0;
}

}  // namespace
}  // namespace tactile

int main(int argc, char** argv) {
  std::string scene = "server/scenes/organ.json";
  int rounds = 5;
  CLI::App app("embedding_bench: what an embedded surface and per-vertex fields cost; prints figures only.",
               "embedding_bench");
  tactile::configure_command_line(app);
  app.add_option("--scene", scene, "a scene with a \"surface\"")->capture_default_str();
  app.add_option("--rounds", rounds, "alternated rounds, >= 1")
      ->capture_default_str()
      ->check(tactile::number_where([](double v) { return v >= 1; }, ">= 1"));
  if (const std::optional<int> status = tactile::parse_command_line(app, argc, argv)) return *status;
  try {
    return tactile::run(scene, rounds);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "embedding_bench: %s\n", e.what());
    return 2;
  }
}
