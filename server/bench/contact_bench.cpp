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
// With --bodies, contact between bodies (core/contact/body_contact.hpp)
// instead: two such plates, the lower held at its base, the upper 5 cm
// above it (apart: the broad phase alone) or lying on it under gravity
// (resting: its whole underside in contact), each plate's boundary of about
// 600 to 100 000 triangles; per case the body-contact pass's time a step
// (Pass::BodyContact), the step's, and, with --threads, the real-time
// factor (the step over the time it takes). The 29-cell plates are 5 046
// tets each. Then a block of 5 184 tets (10 x 5 x 10 cm, 12 x 6 x 12 cells)
// resting on the 29-cell plate: two bodies of about 5 000 tets in contact
// over a patch, as an organ on its bed, rather than over a whole face.
//
//   build/release/contact_bench [--bodies] [--sizes 12,24,48,96,160] [--steps 300] [--rounds 3] [--threads 1]
//
// Times are medians over alternated rounds (waiting and pressed take turns).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "core/bodies.hpp"
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

// Sums the time of each step and of one of its passes (proxy or body contact).
class Timer : public StepProbe {
 public:
  explicit Timer(Pass timed = Pass::Contact) : timed_(timed) {}
  void enter(Pass p) override {
    // (A step split over threads opens with the elastic pass, not the predictor.)
    if (p == Pass::Predict || (p == Pass::Elastic && !in_step_)) {
      step_start_ = Clock::now();
      in_step_ = true;
    }
    if (p == timed_) contact_start_ = Clock::now();
  }
  void leave(Pass p) override {
    const Clock::time_point now = Clock::now();
    if (p == timed_) contact_ += std::chrono::duration<double>(now - contact_start_).count();
    if (p == Pass::Guard) {
      step_ += std::chrono::duration<double>(now - step_start_).count();
      in_step_ = false;
    }
  }
  void clear() { contact_ = step_ = 0; }
  double contact() const { return contact_; }
  double step() const { return step_; }

 private:
  Pass timed_;
  bool in_step_ = false;
  Clock::time_point step_start_, contact_start_;
  double contact_ = 0, step_ = 0;
};

constexpr double kSide = 0.2, kThick = 0.01, kRadius = 0.01, kBlock = 0.1;

// Over `steps` steps of sim, a millisecond's advance at a time: the timed
// pass's and the step's time a step [us], and the mean step [s].
void time_steps(Simulation& sim, Timer& timer, int64_t steps, double& pass_us, double& step_us, double& dt) {
  timer.clear();
  const int64_t first = sim.steps();
  const double t0 = sim.time();
  while (sim.steps() - first < steps)
    if (const AdvanceReport r = sim.advance(1e-3); r.fault) {
      std::fprintf(stderr, "contact_bench: %s\n", r.fault.message.c_str());
      std::exit(1);
    }
  const double n = double(sim.steps() - first);
  pass_us = 1e6 * timer.contact() / n;
  step_us = 1e6 * timer.step() / n;
  dt = (sim.time() - t0) / n;
}

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
    double dt = 0;
    time_steps(sim, timer, steps, contact_us, step_us, dt);
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

// Two plates of n x n x 1 cells, the lower held at its base; the upper 5 cm
// above (apart, no gravity) or let fall from 0.1 mm onto it under gravity
// and left 0.15 s to settle (resting).
struct Plates {
  Simulation sim;
  Timer timer{Pass::BodyContact};
  // With `block`, the upper body is the block, not a plate.
  Plates(int n, bool resting, int threads, bool block = false) : sim(spec(n, resting, threads, block)) {
    if (resting)
      while (sim.time() < 0.15)
        if (const AdvanceReport r = sim.advance(1e-3); r.fault) {
          std::fprintf(stderr, "contact_bench: the plates of %d cells failed: %s\n", n, r.fault.message.c_str());
          std::exit(1);
        }
    sim.set_probe(&timer);
  }
  static ModelSpec spec(int n, bool resting, int threads, bool block) {
    const double up = kThick + (resting ? 1e-4 : 0.05);
    std::vector<BodyParts> parts(2);
    for (int b = 0; b < 2; ++b) {
      parts[size_t(b)].name = b == 0 ? "bed" : block ? "block" : "plate";
      const double y0 = b == 0 ? 0.0 : up;
      parts[size_t(b)].mesh =
          b == 1 && block
              ? make_box(Vec3(-kBlock / 2, y0, -kBlock / 2), Vec3(kBlock / 2, y0 + kBlock / 2, kBlock / 2), {12, 6, 12})
              : make_box(Vec3(-kSide / 2, y0, -kSide / 2), Vec3(kSide / 2, y0 + kThick, kSide / 2), {n, 1, n});
      parts[size_t(b)].materials = {MaterialSpec{MaterialModel::Corotational, 5e4, 0.3, 1000}};
    }
    EssentialBc base;
    base.name = "base";
    base.where.kind = NodeSelector::Kind::Box;
    base.where.lo = Vec3(-1.0, -1.0, -1.0);
    base.where.hi = Vec3(1.0, 1e-9, 1.0);
    parts[0].essential = {base};
    ModelSpec s;
    add_bodies(s, std::move(parts));
    s.effects.body_contact = true;
    s.effects.gravity = resting;
    s.effects.damping = true;
    s.effects.alpha = 20.0;
    s.integrator.precision = Precision::Float;
    s.integrator.threads = threads;
    return s;
  }
  void time(int64_t steps, double& contact_us, double& step_us, double& dt) {
    time_steps(sim, timer, steps, contact_us, step_us, dt);
  }
};

int run_bodies(const std::vector<int>& sizes, int64_t steps, int rounds, int threads) {
  std::printf(
      "body contact between two plates (corotational, float, %d thread%s): the upper 5 cm above the lower, and\n"
      "lying on it; us a step, median of %d alternated rounds of %lld steps\n\n",
      threads, threads == 1 ? "" : "s", rounds, static_cast<long long>(steps));
  std::printf(
      "| cells | tets (both) | triangles (both) | apart: body contact us | step us | share "
      "| resting: body contact us | step us | share | points | real-time factor |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (int n : sizes) {
    Plates apart(n, false, threads), resting(n, true, threads);
    std::vector<double> ac, as, rc, rs;
    double dt = 0;
    for (int r = 0; r < rounds; ++r) {
      double c = 0, s = 0;
      apart.time(steps, c, s, dt);
      ac.push_back(c);
      as.push_back(s);
      resting.time(steps, c, s, dt);
      rc.push_back(c);
      rs.push_back(s);
    }
    const size_t triangles = compute_boundary_faces(resting.sim.mesh()).size();
    const Simulation::BodyContactReport report = resting.sim.body_contact_report();
    std::printf("| %d x %d x 1 | %d | %zu | %.2f | %.1f | %.1f %% | %.1f | %.1f | %.1f %% | %d | %.2f |\n", n, n,
                resting.sim.n_tets(), triangles, median(ac), median(as), 100 * median(ac) / median(as), median(rc),
                median(rs), 100 * median(rc) / median(rs), report.between, 1e6 * dt / median(rs));
    std::fflush(stdout);
  }
  // The block on the 29-cell plate.
  Plates block(29, true, threads, true);
  std::vector<double> bc, bs;
  double dt = 0;
  for (int r = 0; r < rounds; ++r) {
    double c = 0, s = 0;
    block.time(steps, c, s, dt);
    bc.push_back(c);
    bs.push_back(s);
  }
  std::printf(
      "\na block of %d tets resting on the 29-cell plate (%d tets in all), %d thread%s: body contact %.1f us of a "
      "%.1f us step (%.1f %%), %d points, real-time factor %.2f\n",
      block.sim.n_tets() - 5046, block.sim.n_tets(), threads, threads == 1 ? "" : "s", median(bc), median(bs),
      100 * median(bc) / median(bs), block.sim.body_contact_report().between, 1e6 * dt / median(bs));
  return 0;
}

}  // namespace
}  // namespace tactile

int main(int argc, char** argv) {
  CLI::App app{"What proxy contact costs as the surface grows"};
  std::vector<int> sizes{12, 24, 48, 96, 160};
  int64_t steps = 300;
  int rounds = 3;
  int threads = 1;
  bool bodies = false;
  app.add_flag("--bodies", bodies, "contact between two plates instead of a proxy's with one");
  app.add_option("--threads", threads, "threads the step is split over (with --bodies)")->check(CLI::PositiveNumber);
  app.add_option("--sizes", sizes, "cells along each side of the plate")->delimiter(',');
  app.add_option("--steps", steps, "steps a round")->check(CLI::PositiveNumber);
  app.add_option("--rounds", rounds, "alternated rounds")->check(CLI::PositiveNumber);
  CLI11_PARSE(app, argc, argv);
  return bodies ? tactile::run_bodies(sizes, steps, rounds, threads) : tactile::run(sizes, steps, rounds);
}
