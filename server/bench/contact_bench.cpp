// What proxy contact costs as the surface grows (issue 43): a plate held at
// its base, its boundary of about 600 to 100 000 triangles, with a sphere
// (1 cm) waiting 5 cm above it, then pressed 2 mm into the middle of its top
// and held. Per case: the contact pass's time a step (Pass::Contact, timed by
// a StepProbe) and the whole step's, the contact's share, and the contact
// points. The broad phase (core/contact/cluster_set.hpp) should make the
// waiting case cost about one box test per cluster, and the pressed case
// grow with the points, not with the surface. Prints figures, passes and
// fails nothing.
//
//   build/release/contact_bench [--sizes 12,24,48,96,160] [--steps 300] [--rounds 3]
//
// Times are medians over alternated rounds (waiting and pressed take turns).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "core/mesh.hpp"
#include "core/spec.hpp"
#include "mesh/primitives.hpp"
#include "sim/simulation.hpp"

namespace tactile {
namespace {

using Clock = std::chrono::steady_clock;

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

// Sums the time of each step and of its contact pass.
class Timer : public StepProbe {
 public:
  void enter(Pass p) override {
    if (p == Pass::Predict) step_start_ = Clock::now();
    if (p == Pass::Contact) contact_start_ = Clock::now();
  }
  void leave(Pass p) override {
    const Clock::time_point now = Clock::now();
    if (p == Pass::Contact) contact_ += std::chrono::duration<double>(now - contact_start_).count();
    if (p == Pass::Guard) step_ += std::chrono::duration<double>(now - step_start_).count();
  }
  void clear() { contact_ = step_ = 0; }
  double contact() const { return contact_; }
  double step() const { return step_; }

 private:
  Clock::time_point step_start_, contact_start_;
  double contact_ = 0, step_ = 0;
};

constexpr double kSide = 0.2, kThick = 0.01, kRadius = 0.01;

// The plate of n x n x 1 cells, held at its base, its sphere `depth` [m] into the top's middle (negative:
// above it), brought there over 0.1 s and held 0.05 s.
struct Plate {
  Simulation sim;
  Timer timer;
  Plate(int n, double depth) : sim(spec(n)) {
    ProxyMotion m;
    m.t0 = 0.0;
    m.t1 = 0.1;
    m.from = sim.proxy_pose(0);
    m.to = m.from;
    m.to.position.y = kThick + kRadius - depth;
    sim.set_proxy_motion(0, m);
    while (sim.time() < 0.15)
      if (const AdvanceReport r = sim.advance(1e-3); r.fault) {
        std::fprintf(stderr, "contact_bench: the plate of %d cells failed: %s\n", n, r.fault.message.c_str());
        std::exit(1);
      }
    sim.set_probe(&timer);
  }
  static ModelSpec spec(int n) {
    ModelSpec s;
    s.mesh = make_box(Vec3(-kSide / 2, 0.0, -kSide / 2), Vec3(kSide / 2, kThick, kSide / 2), {n, 1, n});
    s.materials = {MaterialSpec{MaterialModel::Corotational, 5e4, 0.3, 1000}};
    EssentialBc base;
    base.name = "base";
    base.where.kind = NodeSelector::Kind::Box;
    base.where.lo = Vec3(-1.0, -1.0, -1.0);
    base.where.hi = Vec3(1.0, 1e-9, 1.0);
    s.essential = {base};
    ProxySpec tip;
    tip.name = "tip";
    tip.device = "stylus";
    tip.geometry = ProxyGeometry{ProxyShape::Sphere, kRadius, 0, Vec3(0.0)};
    tip.pose.position = Vec3(0.0, kThick + kRadius + 0.05, 0.0);
    s.proxies = {tip};
    s.integrator.precision = Precision::Float;
    s.integrator.threads = 1;
    return s;
  }
  // Over `steps` steps: contact and step time a step [us], and the contact points of the last.
  void time(int64_t steps, double& contact_us, double& step_us) {
    timer.clear();
    const int64_t first = sim.steps();
    while (sim.steps() - first < steps)
      if (const AdvanceReport r = sim.advance(1e-3); r.fault) {
        std::fprintf(stderr, "contact_bench: %s\n", r.fault.message.c_str());
        std::exit(1);
      }
    const double n = double(sim.steps() - first);
    contact_us = 1e6 * timer.contact() / n;
    step_us = 1e6 * timer.step() / n;
  }
};

int run(const std::vector<int>& sizes, int64_t steps, int rounds) {
  std::printf(
      "proxy contact on a plate's boundary (corotational, float, one thread): a 1 cm sphere waiting 5 cm above, and\n"
      "pressed 2 mm into the top and held; us a step, median of %d alternated rounds of %lld steps\n\n",
      rounds, static_cast<long long>(steps));
  std::printf(
      "| cells | tets | boundary triangles | waiting: contact us | step us | share "
      "| pressed: contact us | step us | share | points |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|\n");
  for (int n : sizes) {
    Plate waiting(n, -0.05), pressed(n, 0.002);
    std::vector<double> wc, ws, pc, ps;
    for (int r = 0; r < rounds; ++r) {
      double c = 0, s = 0;
      waiting.time(steps, c, s);
      wc.push_back(c);
      ws.push_back(s);
      pressed.time(steps, c, s);
      pc.push_back(c);
      ps.push_back(s);
    }
    const TetMesh& mesh = pressed.sim.mesh();
    const size_t triangles = compute_boundary_faces(mesh).size();
    int32_t points = 0;
    for (const ProxyReport& r : pressed.sim.proxy_reports()) points += r.contacts_peak;
    std::printf("| %d x %d x 1 | %d | %zu | %.2f | %.1f | %.1f %% | %.2f | %.1f | %.1f %% | %d |\n", n, n,
                int(mesh.tets.size()), triangles, median(wc), median(ws), 100 * median(wc) / median(ws), median(pc),
                median(ps), 100 * median(pc) / median(ps), points);
    std::fflush(stdout);
  }
  return 0;
}

}  // namespace
}  // namespace tactile

int main(int argc, char** argv) {
  CLI::App app{"What proxy contact costs as the surface grows"};
  std::vector<int> sizes{12, 24, 48, 96, 160};
  int64_t steps = 300;
  int rounds = 3;
  app.add_option("--sizes", sizes, "cells along each side of the plate")->delimiter(',');
  app.add_option("--steps", steps, "steps a round")->check(CLI::PositiveNumber);
  app.add_option("--rounds", rounds, "alternated rounds")->check(CLI::PositiveNumber);
  CLI11_PARSE(app, argc, argv);
  return tactile::run(sizes, steps, rounds);
}
