// FEM step benchmark: rate of the explicit step per material, precision and
// mesh size; one thread against two (and two threads against two one-thread
// runs at once); the cost of each effect a scene may ask
// for; the ISA levels; the float-vs-double difference of a loaded beam; and
// the allocations inside steps. Prints figures, passes and fails nothing.
//
//   fem_bench            all tables, meshes up to 100 k tets (a minute or two)
//   fem_bench --large    also 1 M and 2 M tets
//   fem_bench --quick    small meshes and few repeats, for CI (seconds)
//   fem_bench --only=T   one table: rates, threads, passes, effects, hand, refresh, isas, precision, invertible,
//                        quadratic
//
// Times are wall-clock medians of repeated runs of many steps, so that other
// processes on the machine shift them less than a mean would; rates are
// element updates per second (tets x steps / s).
#include <malloc.h>
#include <pthread.h>
#include <sched.h>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "app/command_line.hpp"
#include "core/kernels/kernels.hpp"
#include "core/material.hpp"
#include "core/model.hpp"
#include "core/model_build.hpp"
#include "core/quadratic.hpp"
#include "core/stepper.hpp"
#include "mesh/primitives.hpp"
#include "parallel/thread_pool.hpp"

// Every heap allocation of the process, counted only while a timed loop of
// steps runs (alloc_count::all).
#include "alloc_count.hpp"

namespace tactile {
namespace {

using Clock = std::chrono::steady_clock;

struct Options {
  bool quick = false;
  bool large = false;
  std::string only;  // one table's name, or empty for all
  bool wants(const char* table) const { return only.empty() || only == table; }
};

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

const char* name_of(Precision p) { return p == Precision::Float ? "float" : "double"; }

// A box of about `tets` tets, 6 per cell (Kuhn split), `aspect` cells along x per cell along y and z.
TetMesh make_bench_box(double tets, int aspect, double size_y) {
  const int n = std::max(1, int(std::lround(std::cbrt(tets / (6.0 * aspect)))));
  return make_box(Vec3(0.0), Vec3(aspect * size_y, size_y, size_y), {aspect * n, n, n});
}

ModelSpec make_spec(TetMesh mesh, MaterialModel model, Precision precision) {
  ModelSpec spec;
  spec.mesh = std::move(mesh);
  spec.materials = {MaterialSpec{model, 1e5, 0.3, 1000}};
  spec.integrator.precision = precision;
  return spec;
}

// Selects the nodes on the face x = x0 of a box.
NodeSelector face_x(const TetMesh& mesh, double x0) {
  const Aabb box = compute_aabb(mesh.X);
  NodeSelector s;
  s.kind = NodeSelector::Kind::Box;
  s.lo = Vec3(x0, box.lo.y, box.lo.z);
  s.hi = Vec3(x0, box.hi.y, box.hi.z);
  s.tolerance = 1e-9;
  return s;
}

// A swinging, twisting velocity field, so that every element deforms and the
// step does its real work (a body at rest would multiply zeros).
template <class Real>
void set_swing(const Model<Real>& model, State<Real>& s, double amplitude) {
  const Aabb box = compute_aabb(model.mesh.X);
  const Vec3 c = 0.5 * (box.lo + box.hi);
  const double L = std::max(box.size().x, 1e-9);
  for (int32_t i = 0; i < model.n_nodes; ++i) {
    const Vec3 r = model.mesh.X[size_t(i)] - c;
    const double x = (model.mesh.X[size_t(i)].x - box.lo.x) / L;
    s.v[3 * size_t(i) + 0] = Real(0.0);
    s.v[3 * size_t(i) + 1] = Real(amplitude * (0.5 * x * x - 2.0 * r.z * x));  // [m/s]
    s.v[3 * size_t(i) + 2] = Real(amplitude * 2.0 * r.y * x);
  }
}

// Keeps the calling thread on one CPU while it lives (cpu < 0: leaves it
// alone), then lets it run anywhere it could before.
class PinThread {
 public:
  explicit PinThread(int cpu) {
    if (cpu < 0 || pthread_getaffinity_np(pthread_self(), sizeof before_, &before_) != 0) return;
    cpu_set_t one;
    CPU_ZERO(&one);
    CPU_SET(cpu, &one);
    pinned_ = pthread_setaffinity_np(pthread_self(), sizeof one, &one) == 0;
  }
  ~PinThread() {
    if (pinned_) pthread_setaffinity_np(pthread_self(), sizeof before_, &before_);
  }
  PinThread(const PinThread&) = delete;
  PinThread& operator=(const PinThread&) = delete;

 private:
  cpu_set_t before_{};
  bool pinned_ = false;
};

// The first two CPUs this process may run on, or none if it may run on fewer.
std::vector<int> two_cpus() {
  cpu_set_t set;
  CPU_ZERO(&set);
  std::vector<int> out;
  if (sched_getaffinity(0, sizeof set, &set) != 0) return out;
  for (int c = 0; c < CPU_SETSIZE && out.size() < 2; ++c)
    if (CPU_ISSET(c, &set)) out.push_back(c);
  if (out.size() < 2) out.clear();
  return out;
}

// One model with its stepper and state, stepped in timed runs.
template <class Real>
struct Run {
  Model<Real> model;
  Stepper<Real> stepper;
  State<Real> state;
  State<Real> start;
  double dt;
  int64_t faults = 0;
  int cpu = -1;         // >= 0: timed runs keep the calling thread on this CPU
  bool frames = false;  // timed runs call advance(dt), as the live loop does, rather than step(dt)
  Run* twin = nullptr;  // timed runs step this one at the same time, on another thread (see time_steps)

  // `swing` scales the starting velocity field (1: up to about 0.5 m/s).
  Run(const ModelSpec& spec, ParallelFor* pool, double swing = 1.0)
      : model(build_model<Real>(spec)), stepper(model, pool), state(stepper.make_state()) {
    set_swing(model, state, swing);
    start = state;
    dt = 0.5 * model.dt_rest;
  }
  // Seconds per step over `steps` steps; a fault restarts from the start state.
  // Allocations are counted unless `warm_up` (the first step from a state
  // sets up its energy accounting, with a full energy pass). With a twin, the
  // two step at once, one thread each (on `cpu` and the twin's), and the
  // result is the step time of their rates added up.
  double time_steps(int64_t steps, bool warm_up = false) {
    if (twin) {
      std::atomic<int> finished{0};
      std::atomic<bool> go{false};
      double other = 0;
      std::thread thread([&] {
        while (!go.load(std::memory_order_acquire)) {
        }
        other = twin->loop(steps, warm_up, &finished);
      });
      alloc_count::all = !warm_up;
      go.store(true, std::memory_order_release);
      const double mine = loop(steps, warm_up, &finished);
      thread.join();
      alloc_count::all = false;
      return 1.0 / (1.0 / mine + 1.0 / other);
    }
    alloc_count::all = !warm_up;
    const double s = loop(steps, warm_up, nullptr);
    alloc_count::all = false;
    return s;
  }

  // Seconds per step of at least `steps` steps. With `finished` (shared with
  // a twin), it goes on stepping until the twin has done its steps too, so
  // that both are timed only while both run.
  double loop(int64_t steps, bool warm_up, std::atomic<int>* finished) {
    const PinThread pin(cpu);
    const Clock::time_point t0 = Clock::now();
    int64_t k = 0;
    for (;; ++k) {
      if (k >= steps) {
        if (!finished) break;
        if (k == steps) finished->fetch_add(1, std::memory_order_acq_rel);
        if (finished->load(std::memory_order_acquire) >= 2) break;
      }
      if (frames ? bool(stepper.advance(state, dt).fault) : bool(stepper.step(state, dt))) {
        const bool counting = alloc_count::all;
        alloc_count::all = false;
        ++faults;
        std::fprintf(stderr, "fault (restarting): %s\n", state.fault.message.c_str());
        stepper.clear_fault(state);
        state = start;
        alloc_count::all = counting && !warm_up;
      }
    }
    return seconds_since(t0) / double(k);
  }
};

// How many steps make one timed run of about `target` seconds.
template <class Real>
int64_t calibrate(Run<Real>& run, double target) {
  run.time_steps(3, true);  // warm up: first step, caches, pool threads
  int64_t steps = 4;
  for (;;) {
    const Clock::time_point t0 = Clock::now();
    run.time_steps(steps);
    const double s = seconds_since(t0);
    if (s > 0.25 * target || steps > (int64_t(1) << 24))
      return std::max<int64_t>(1, int64_t(double(steps) * target / s));
    steps *= 4;
  }
}

// Median seconds per step of several runs, alternating between the cases so
// that a burst of load elsewhere on the machine hits all of them alike.
template <class Real>
std::vector<double> time_alternating(std::vector<Run<Real>*> runs, const Options& opt) {
  const double target = opt.quick ? 0.004 : 0.03;
  const int repeats = opt.quick ? 5 : 11;
  std::vector<int64_t> steps;
  for (Run<Real>* r : runs) steps.push_back(calibrate(*r, target));
  std::vector<std::vector<double>> t(runs.size());
  for (int k = 0; k < repeats; ++k)
    for (size_t i = 0; i < runs.size(); ++i) t[i].push_back(runs[i]->time_steps(steps[i]));
  std::vector<double> out;
  for (auto& v : t) out.push_back(median(v));
  return out;
}

std::vector<double> bench_sizes(const Options& opt) {
  if (opt.quick) return {1e3, 2e4};
  std::vector<double> s = {1e3, 5e3, 2e4, 1e5};
  if (opt.large) {
    s.push_back(1e6);
    s.push_back(2e6);
  }
  return s;
}

// ---- tables --------------------------------------------------------------------

template <class Real>
void rate_rows(const Options& opt, MaterialModel model) {
  const Precision precision = sizeof(Real) == 4 ? Precision::Float : Precision::Double;
  for (double size : bench_sizes(opt)) {
    if (model != MaterialModel::StVK && size > 2.5e5) continue;  // the large meshes for the paper's model only
    Run<Real> run(make_spec(make_bench_box(size, 1, 0.1), model, precision), nullptr);
    const double s = time_alternating<Real>({&run}, opt)[0];
    std::printf("| %-12s | %-6s | %9d | %12.0f | %10.1f |\n", std::string(to_string(model)).c_str(), name_of(precision),
                run.model.n_tets, s * 1e9, run.model.n_tets / s * 1e-6);
  }
}

void table_rates(const Options& opt) {
  std::printf("\n## Explicit step, one thread (forces, predictor, corrector, guards)\n\n");
  std::printf("| material     | real   |      tets |  ns per step | M tets/s   |\n");
  std::printf("|--------------|--------|-----------|--------------|------------|\n");
  for (int m = 0; m < kMaterialModelCount; ++m) {
    rate_rows<float>(opt, MaterialModel(m));
    rate_rows<double>(opt, MaterialModel(m));
  }
}

template <class Real>
void thread_rows(const Options& opt, ThreadPool& pool, const std::vector<int>& cpus) {
  const Precision precision = sizeof(Real) == 4 ? Precision::Float : Precision::Double;
  for (double size : bench_sizes(opt)) {
    ModelSpec spec = make_spec(make_bench_box(size, 1, 0.1), MaterialModel::StVK, precision);
    Run<Real> one(spec, nullptr);
    // Two one-thread runs at once, one on each CPU.
    Run<Real> pair_a(spec, nullptr), pair_b(spec, nullptr);
    std::vector<Run<Real>*> runs = {&one};
    if (cpus.size() == 2) {
      pair_a.cpu = cpus[0];
      pair_b.cpu = cpus[1];
      pair_a.twin = &pair_b;
      runs.push_back(&pair_a);
    }
    spec.integrator.threads = 2;
    Run<Real> two(spec, &pool);
    runs.insert(runs.begin() + 1, &two);
    const std::vector<double> t = time_alternating<Real>(runs, opt);
    const double tets = one.model.n_tets;
    std::printf("| %-6s | %9d | %10.1f | %10.1f | %5d | %7.2fx |", name_of(precision), one.model.n_tets,
                tets / t[0] * 1e-6, tets / t[1] * 1e-6, two.stepper.parts(), t[0] / t[1]);
    if (cpus.size() == 2) std::printf(" %12.1f | %10.0f %% |", tets / t[2] * 1e-6, 100.0 * t[2] / t[1]);
    std::printf("\n");
  }
}

// Round trip of the pool on an empty job of two indices: the fixed cost of a
// pass split over two threads.
double pool_handoff_seconds(ThreadPool& pool) {
  std::atomic<int> sink{0};
  auto fn = [](void* ctx, int32_t i) { static_cast<std::atomic<int>*>(ctx)->fetch_add(i, std::memory_order_relaxed); };
  for (int k = 0; k < 10000; ++k) pool.run(2, fn, &sink);
  std::vector<double> t;
  for (int rep = 0; rep < 5; ++rep) {
    const int runs = 100000;
    const Clock::time_point t0 = Clock::now();
    for (int k = 0; k < runs; ++k) pool.run(2, fn, &sink);
    t.push_back(seconds_since(t0) / runs);
  }
  return median(t);
}

void table_threads(const Options& opt) {
  ThreadPool pool(2);
  const std::vector<int> cpus = two_cpus();
  std::printf("\n## StVK, one thread against two (M tets/s)\n\n");
  std::printf("(parts: how many ways the stepper split the passes; small meshes stay on one)\n");
  if (cpus.size() == 2) {
    std::printf(
        "(2 at once: two one-thread runs stepping at the same time, one on cpu %d and one on cpu %d,\n"
        " their rates added up: what these two CPUs give when both are busy, which on a shared or\n"
        " virtual machine can fall well short of twice one; of 2 at once: two threads' rate against it)\n\n",
        cpus[0], cpus[1]);
    std::printf("| real   |      tets |  1 thread  | 2 threads  | parts | speedup  |   2 at once  | of 2 at once |\n");
    std::printf("|--------|-----------|------------|------------|-------|----------|--------------|--------------|\n");
  } else {
    std::printf("\n| real   |      tets |  1 thread  | 2 threads  | parts | speedup  |\n");
    std::printf("|--------|-----------|------------|------------|-------|----------|\n");
  }
  thread_rows<float>(opt, pool, cpus);
  thread_rows<double>(opt, pool, cpus);
  std::printf("\nHand-off: %.2f us per pass split over the two threads (an empty job's round trip)\n",
              pool_handoff_seconds(pool) * 1e6);
  if (std::thread::hardware_concurrency() < 2) std::printf("\n(this machine has one core: two threads share it)\n");
}

// A sphere of a fifth of the body's height sunk 1 mm into the middle of its top face.
ProxySpec top_sphere(const TetMesh& mesh, double friction) {
  const Aabb box = compute_aabb(mesh.X);
  const double r = 0.2 * box.size().y;
  ProxySpec p;
  p.name = "sphere";
  p.device = "arm";
  p.geometry = ProxyGeometry{ProxyShape::Sphere, r, 0.0, Vec3(0.0)};
  p.pose.position = Vec3(0.5 * (box.lo.x + box.hi.x), box.hi.y + r - 0.001, 0.5 * (box.lo.z + box.hi.z));
  p.friction = friction;
  return p;
}

// Scenes on a 4:1:1 beam that each add one effect to the bare step.
struct Scene {
  const char* name;
  std::function<void(ModelSpec&)> add;
};

std::vector<Scene> effect_scenes() {
  auto clamp = [](ModelSpec& s) {
    EssentialBc bc;
    bc.name = "clamp";
    bc.where = face_x(s.mesh, 0.0);
    s.essential.push_back(bc);
  };
  return {
      {"bare step", [](ModelSpec&) {}},
      {"gravity", [](ModelSpec& s) { s.effects.gravity = true; }},
      {"damping (alpha M)",
       [](ModelSpec& s) {
         s.effects.damping = true;
         s.effects.alpha = 2.0;
       }},
      {"load (tip face)",
       [](ModelSpec& s) {
         NaturalLoad load;
         load.name = "tip";
         load.where = face_x(s.mesh, compute_aabb(s.mesh.X).hi.x);
         load.force = Vec3(0.0, -0.5, 0.0);
         s.loads.push_back(load);
       }},
      {"fixed BC (clamped face)", clamp},
      {"rotating BC (twisted face)",
       [](ModelSpec& s) {
         EssentialBc bc;
         bc.name = "twist";
         const Aabb box = compute_aabb(s.mesh.X);
         bc.where = face_x(s.mesh, box.hi.x);
         bc.centre = 0.5 * (box.lo + box.hi);
         bc.axis = Vec3(1.0, 0.0, 0.0);
         MotionProfile rate;
         rate.kind = MotionProfile::Kind::ConstantRate;
         rate.rate = 0.2;  // [rad/s]
         bc.angle = rate;
         s.essential.push_back(bc);
       }},
      {"contact (sphere on the top)", [](ModelSpec& s) { s.proxies = {top_sphere(s.mesh, 0.0)}; }},
      {"contact + friction (mu 0.5)",
       [](ModelSpec& s) {
         s.proxies = {top_sphere(s.mesh, 0.5)};
         s.effects.friction = true;
       }},
      {"all of the above",
       [clamp](ModelSpec& s) {
         s.effects.gravity = true;
         s.effects.damping = true;
         s.effects.alpha = 2.0;
         clamp(s);
         NaturalLoad load;
         load.where = face_x(s.mesh, compute_aabb(s.mesh.X).hi.x);
         load.force = Vec3(0.0, -0.5, 0.0);
         s.loads.push_back(load);
       }},
  };
}

template <class Real>
void effect_rows(const Options& opt, double size) {
  const Precision precision = sizeof(Real) == 4 ? Precision::Float : Precision::Double;
  const std::vector<Scene> scenes = effect_scenes();
  std::vector<std::unique_ptr<Run<Real>>> runs;
  for (const Scene& scene : scenes) {
    ModelSpec spec = make_spec(make_bench_box(size, 4, 0.1), MaterialModel::StVK, precision);
    spec.materials[0].E = 1e7;  // [Pa]: stiff enough to hang clamped under gravity (3.8 mm sag)
    scene.add(spec);
    runs.push_back(std::make_unique<Run<Real>>(spec, nullptr, 0.1));  // gentle: clamped, twisted and loaded too
  }
  std::vector<Run<Real>*> ptrs;
  for (auto& r : runs) ptrs.push_back(r.get());
  // The bare step twice, first and last: how far two identical cases differ here.
  ptrs.push_back(runs[0].get());
  const std::vector<double> t = time_alternating<Real>(ptrs, opt);
  const double bare = t[0];
  for (size_t i = 0; i < scenes.size(); ++i) {
    const double d = t[i] - bare;
    std::printf("| %-6s | %-27s | %11.0f | %+9.0f | %+7.1f %% |\n", name_of(precision), scenes[i].name, t[i] * 1e9,
                d * 1e9, 100.0 * d / bare);
  }
  std::printf("| %-6s | %-27s | %11.0f | %+9.0f | %+7.1f %% |\n", name_of(precision), "bare step, timed again",
              t.back() * 1e9, (t.back() - bare) * 1e9, 100.0 * (t.back() - bare) / bare);
  for (size_t i = 0; i < scenes.size(); ++i)
    if (runs[i]->faults)
      std::printf("(%s: %lld fault(s), restarted; see stderr)\n", scenes[i].name,
                  static_cast<long long>(runs[i]->faults));
}

void table_effects(const Options& opt) {
  const double size = opt.quick ? 5e3 : 2.4e4;
  std::printf("\n## Cost of each effect: StVK beam (0.4 x 0.1 x 0.1 m, E = 10 MPa, ~%.0f k tets), one thread\n\n",
              size * 1e-3);
  std::printf("A scene pays only for the effects it asks for: each row adds one to the bare step.\n\n");
  std::printf("| real   | scene                       | ns per step | vs bare   | vs bare   |\n");
  std::printf("|--------|-----------------------------|-------------|-----------|-----------|\n");
  effect_rows<float>(opt, size);
  effect_rows<double>(opt, size);
}

// Time spent per pass of the bare StVK step, from the stepper's probe.
class PassClock final : public StepProbe {
 public:
  void enter(Pass) override { t0_ = Clock::now(); }
  void leave(Pass p) override { total_[int(p)] += std::chrono::duration<double>(Clock::now() - t0_).count(); }
  double total(Pass p) const { return total_[int(p)]; }

 private:
  Clock::time_point t0_;
  double total_[kPassCount] = {};
};

// A hand of five proxies on the top face of a body: a palm (rounded box)
// and four capsule fingers, each sunk 1 mm into it, on one device.
void add_hand(ModelSpec& spec, double friction) {
  const Aabb box = compute_aabb(spec.mesh.X);
  const Vec3 c = 0.5 * (box.lo + box.hi);
  const double w = box.size().x, top = box.hi.y;
  HandSpec hand;
  hand.name = "hand";
  hand.device = "glove";
  hand.pose.position = Vec3(c.x, top, c.z);
  spec.hands = {hand};
  ProxySpec palm;
  palm.name = "palm";
  palm.hand = "hand";
  palm.geometry = ProxyGeometry{ProxyShape::Box, 0.01 * w, 0.0, Vec3(0.15 * w, 0.05 * w, 0.15 * w)};
  palm.pose.position = Vec3(c.x - 0.15 * w, top + 0.06 * w - 0.001, c.z);
  palm.friction = friction;
  spec.proxies = {palm};
  for (int k = 0; k < 4; ++k) {
    ProxySpec finger;
    finger.name = "finger" + std::to_string(k);
    finger.hand = "hand";
    finger.geometry = ProxyGeometry{ProxyShape::Capsule, 0.03 * w, 0.08 * w, Vec3(0.0)};
    finger.pose.position = Vec3(c.x + 0.15 * w, top + 0.03 * w - 0.001, c.z + (k - 1.5) * 0.08 * w);
    finger.friction = friction;
    spec.proxies.push_back(finger);
  }
}

template <class Real>
void hand_rows(const Options& opt) {
  const Precision precision = sizeof(Real) == 4 ? Precision::Float : Precision::Double;
  const double size = opt.quick ? 5e3 : 1e4;
  std::vector<std::unique_ptr<Run<Real>>> runs;
  for (int variant = 0; variant < 4; ++variant) {
    ModelSpec spec = make_spec(make_bench_box(size, 1, 0.1), MaterialModel::StVK, precision);
    EssentialBc base;  // held, so that the hand does not push it away
    base.name = "base";
    base.where.kind = NodeSelector::Kind::Box;
    base.where.hi = Vec3(0.1, 0.0, 0.1);
    spec.essential = {base};
    if (variant > 0) add_hand(spec, 0.5);
    if (variant == 3)  // lifted 1 m clear of the body: the broad phase alone
      for (HandSpec& h : spec.hands) h.pose.position.y += 1.0;
    if (variant == 3)
      for (ProxySpec& p : spec.proxies) p.pose.position.y += 1.0;
    spec.effects.friction = variant >= 2;
    runs.push_back(std::make_unique<Run<Real>>(spec, nullptr, 0.1));
  }
  const std::vector<double> t =
      time_alternating<Real>({runs[0].get(), runs[1].get(), runs[2].get(), runs[3].get()}, opt);
  const char* names[] = {"no proxies", "hand: contact", "hand: contact + friction", "hand 1 m away"};
  for (int v = 0; v < 4; ++v) {
    int32_t contacts = 0;
    for (const ProxyReport& r : runs[size_t(v)]->state.contact.reports) contacts += r.contacts;
    std::printf("| %-6s | %9d | %-24s | %11.0f | %+7.1f %% | %8d |\n", name_of(precision), runs[0]->model.n_tets,
                names[v], t[size_t(v)] * 1e9, 100.0 * (t[size_t(v)] / t[0] - 1), contacts);
  }
}

void table_hand(const Options& opt) {
  std::printf("\n## Contact cost: a hand of five proxies (palm and four fingers) pressed into a swinging StVK body\n");
  std::printf("(0.1 m cube, base held), one thread\n\n");
  std::printf("(contacts: surface nodes inside the proxies at the end of the timed steps)\n\n");
  std::printf("| real   |      tets | scene                    | ns per step | vs bare   | contacts |\n");
  std::printf("|--------|-----------|--------------------------|-------------|-----------|----------|\n");
  hand_rows<float>(opt);
  hand_rows<double>(opt);
}

template <class Real>
void pass_rows(const Options& opt, ThreadPool& pool) {
  const Precision precision = sizeof(Real) == 4 ? Precision::Float : Precision::Double;
  std::vector<double> sizes = {opt.quick ? 5e3 : 2e4};
  if (opt.large) sizes.push_back(1e6);
  for (double size : sizes)
    for (int threads : {1, 2}) {
      ModelSpec spec = make_spec(make_bench_box(size, 1, 0.1), MaterialModel::StVK, precision);
      spec.integrator.threads = threads;
      Run<Real> run(spec, threads > 1 ? &pool : nullptr);
      const int64_t steps = std::max<int64_t>(3, calibrate(run, opt.quick ? 0.02 : 0.2));
      PassClock clock;
      run.stepper.set_probe(&clock);
      run.time_steps(steps, true);  // (clock reads are not the step's)
      run.stepper.set_probe(nullptr);
      double all = 0;
      for (int p = 0; p < kPassCount; ++p) all += clock.total(Pass(p));
      std::printf("| %-6s | %9d | %7d | %9.1f |", name_of(precision), run.model.n_tets, run.stepper.parts(),
                  all / double(steps) * 1e6);
      for (Pass p : {Pass::Predict, Pass::Elastic, Pass::Correct, Pass::Guard})
        std::printf(" %6.1f |", clock.total(p) / double(steps) * 1e6);
      std::printf("\n");
    }
}

void table_passes(const Options& opt) {
  ThreadPool pool(2);
  std::printf("\n## Where the bare StVK step goes (us per step; threads: parts the passes were split in)\n\n");
  std::printf(
      "(split over threads, each part predicts and, with no loads, corrects its nodes inside the elastic\n"
      " pass: its column has all three)\n\n");
  std::printf("| real   |      tets | threads | all       | predict | elastic | correct | guard  |\n");
  std::printf("|--------|-----------|---------|-----------|---------|---------|---------|--------|\n");
  pass_rows<float>(opt, pool);
  pass_rows<double>(opt, pool);
}

template <class Real>
void refresh_rows(const Options& opt) {
  const Precision precision = sizeof(Real) == 4 ? Precision::Float : Precision::Double;
  for (double size : bench_sizes(opt)) {
    if (size < 1e4) continue;
    const ModelSpec spec = make_spec(make_bench_box(size, 1, 0.1), MaterialModel::StVK, precision);
    Run<Real> step(spec, nullptr), frame(spec, nullptr);
    frame.frames = true;
    const std::vector<double> t = time_alternating<Real>({&step, &frame}, opt);
    std::vector<double> sweep;
    for (int k = 0; k < (opt.quick ? 3 : 9); ++k) {
      const Clock::time_point t0 = Clock::now();
      const double dt = frame.stepper.compute_critical_dt(frame.state);
      sweep.push_back(seconds_since(t0));
      if (!(dt > 0)) std::printf("(the estimate came out %g s)\n", dt);
    }
    const AdvanceReport r = frame.stepper.advance(frame.state, frame.dt);
    std::printf("| %-6s | %9d | %9.1f | %12.1f | %8d | %+17.1f %% | %21.1f |\n", name_of(precision), step.model.n_tets,
                t[0] * 1e6, t[1] * 1e6, r.substeps, 100.0 * (t[1] - t[0]) / t[0],
                median(sweep) * 1e9 / step.model.n_tets);
  }
}

// advance() refreshes the critical step as the body deforms, a sixteenth of
// the elements each call (Stepper::advance): what that costs a frame of one
// sub-step, the live loop's case, against step() alone.
void table_refresh(const Options& opt) {
  std::printf("\n## The critical step's refresh: advance() of a frame of one sub-step against step() alone\n\n");
  std::printf("(whole estimate: every element examined once, ns a tet; advance() examines a sixteenth a call)\n\n");
  std::printf(
      "| real   |      tets | step() us | advance() us | substeps | advance() vs step() | whole estimate ns/tet |\n");
  std::printf(
      "|--------|-----------|-----------|--------------|----------|---------------------|-----------------------|\n");
  refresh_rows<float>(opt);
  refresh_rows<double>(opt);
}

template <class Real>
void isa_rows(const Options& opt) {
  const Precision precision = sizeof(Real) == 4 ? Precision::Float : Precision::Double;
  Run<Real> run(make_spec(make_bench_box(opt.quick ? 5e3 : 2e4, 1, 0.1), MaterialModel::StVK, precision), nullptr);
  const double s = time_alternating<Real>({&run}, opt)[0];
  std::printf("| %-24s | %-6s | %9d | %10.1f |\n", std::string(kernel_isa()).c_str(), name_of(precision),
              run.model.n_tets, run.model.n_tets / s * 1e-6);
}

void table_isas(const Options& opt) {
  const std::string best(kernel_isa());
  std::printf("\n## StVK per ISA level (kernels chosen at run time; this CPU's best: %s)\n\n", best.c_str());
  std::printf("| ISA                      | real   |      tets | M tets/s   |\n");
  std::printf("|--------------------------|--------|-----------|------------|\n");
  for (const char* isa : {"baseline", "v3", "v4"}) {
    if (!select_isa(isa)) {
      std::printf("| %-24s | (not supported by this CPU)         |\n", isa);
      continue;
    }
    isa_rows<float>(opt);
    isa_rows<double>(opt);
  }
  select_isa(best.find("v4") != std::string::npos ? "v4" : best.find("v3") != std::string::npos ? "v3" : "baseline");
}

// A cantilever (clamped at x = 0, tip load down) stepped in float and in
// double from the same start: the max displacement difference over the max
// displacement.
template <class Real>
std::vector<double> beam_displacement(MaterialModel model, int steps, double dt) {
  ModelSpec spec = make_spec(make_box(Vec3(0.0), Vec3(0.4, 0.1, 0.1), {16, 4, 4}), model,
                             sizeof(Real) == 4 ? Precision::Float : Precision::Double);
  EssentialBc clamp;
  clamp.where = face_x(spec.mesh, 0.0);
  spec.essential.push_back(clamp);
  NaturalLoad load;
  load.where = face_x(spec.mesh, 0.4);
  load.force = Vec3(0.0, -2.0, 0.0);  // [N]
  spec.loads.push_back(load);
  const Model<Real> m = build_model<Real>(spec);
  Stepper<Real> stepper(m);
  State<Real> s = stepper.make_state();
  for (int k = 0; k < steps; ++k)
    if (Fault f = stepper.step(s, dt)) {
      std::fprintf(stderr, "beam fault: %s\n", f.message.c_str());
      break;
    }
  // In the mesh's node numbering: float and double models number the nodes
  // each their own way (a block holds 16 or 8 elements).
  std::vector<double> u(s.u.size());
  for (size_t i = 0; i < m.node_model.size(); ++i)
    for (size_t d = 0; d < 3; ++d) u[3 * i + d] = double(s.u[3 * size_t(m.node_model[i]) + d]);
  return u;
}

void table_precision(const Options& opt) {
  const int steps = opt.quick ? 400 : 4000;
  std::printf("\n## Float against double: loaded cantilever (0.4 m, 384 tets), %d steps\n\n", steps);
  std::printf("| material     | max |u| [m]  | max |u_float - u_double| / max |u| |\n");
  std::printf("|--------------|--------------|-------------------------------------|\n");
  ModelSpec probe =
      make_spec(make_box(Vec3(0.0), Vec3(0.4, 0.1, 0.1), {16, 4, 4}), MaterialModel::StVK, Precision::Double);
  const double dt = 0.5 * build_model<double>(probe).dt_rest;
  for (int m = 0; m < kMaterialModelCount; ++m) {
    const std::vector<double> uf = beam_displacement<float>(MaterialModel(m), steps, dt);
    const std::vector<double> ud = beam_displacement<double>(MaterialModel(m), steps, dt);
    double scale = 0, diff = 0;
    for (size_t k = 0; k < ud.size(); ++k) {
      scale = std::max(scale, std::fabs(ud[k]));
      diff = std::max(diff, std::fabs(uf[k] - ud[k]));
    }
    std::printf("| %-12s | %12.4e | %35.2e |\n", std::string(to_string(MaterialModel(m))).c_str(), scale,
                scale > 0 ? diff / scale : 0.0);
  }
}

std::string cpu_name() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("model name", 0) == 0) return line.substr(line.find(':') + 2);
  return "unknown CPU";
}

// ---- invertible StVK: what its SVD costs -----------------------------------------

// The step of plain and invertible StVK side by side, nothing near the floor.
template <class Real>
void invertible_step_rows(const Options& opt) {
  const Precision precision = sizeof(Real) == 4 ? Precision::Float : Precision::Double;
  for (double size : opt.quick ? std::vector<double>{2e4} : std::vector<double>{5e3, 2e4, 1e5}) {
    const TetMesh mesh = make_bench_box(size, 1, 0.1);
    Run<Real> plain(make_spec(mesh, MaterialModel::StVK, precision), nullptr);
    Run<Real> inv(make_spec(mesh, MaterialModel::InvertibleStVK, precision), nullptr);
    const std::vector<double> t = time_alternating<Real>({&plain, &inv}, opt);
    const double n = plain.model.n_tets;
    std::printf("| %-6s | %9d | %10.1f | %10.1f | %6.2fx |\n", name_of(precision), plain.model.n_tets, n / t[0] * 1e-6,
                n / t[1] * 1e-6, t[0] / t[1]);
  }
}

// The element pass alone on a fixed deformation: the box's elements left of
// a plane squashed to half their height (past the floor), the rest at rest.
template <class Real>
void invertible_pass_rows(const Options& opt) {
  const Precision precision = sizeof(Real) == 4 ? Precision::Float : Precision::Double;
  constexpr int W = kLanes<Real>;
  const ModelSpec spec =
      make_spec(make_bench_box(opt.quick ? 2e4 : 1e5, 1, 0.1), MaterialModel::InvertibleStVK, precision);
  const Model<Real> model = build_model<Real>(spec);
  const KernelTable<Real>& k = kernels<Real>();
  for (double share : {0.0, 0.01, 0.1, 1.0}) {
    const double cut = share * 0.1 * (1 + 1e-9);
    std::vector<Node4<Real>> u(size_t(model.n_nodes)), f(size_t(model.n_nodes));
    for (size_t i = 0; i < spec.mesh.X.size(); ++i) {
      const Vec3& X = spec.mesh.X[i];
      u[size_t(model.node_model[i])] = Node4<Real>{{0, Real(X.x < cut ? -0.5 * X.y : 0.0), 0, 0}};
    }
    // Elements and blocks the SVD serves.
    std::vector<char> near(spec.mesh.tets.size(), 0);
    int64_t n_near = 0, blocks_near = 0;
    for (size_t e = 0; e < spec.mesh.tets.size(); ++e) {
      const Tet& t = spec.mesh.tets[e];
      Vec3 X[4], x[4];
      for (int c = 0; c < 4; ++c) {
        const size_t n = size_t(t[size_t(c)]);
        X[c] = spec.mesh.X[n];
        const Node4<Real>& d = u[size_t(model.node_model[n])];
        x[c] = X[c] + Vec3(double(d.v[0]), double(d.v[1]), double(d.v[2]));
      }
      const glm::dmat3 G = glm::dmat3(x[1] - x[0], x[2] - x[0], x[3] - x[0]) *
                           glm::inverse(glm::dmat3(X[1] - X[0], X[2] - X[0], X[3] - X[0]));
      double F[9];
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) F[3 * a + b] = G[b][a];
      near[e] = material::reaches_floor(F);
      n_near += near[e];
    }
    for (size_t b = 0; b * W < model.lane_tet.size(); ++b) {
      bool any = false;
      for (int l = 0; l < W; ++l) {
        const int32_t e = model.lane_tet[b * W + size_t(l)];
        any = any || (e >= 0 && near[size_t(e)]);
      }
      blocks_near += any;
    }
    const int64_t n_blocks = int64_t(model.lane_tet.size() / W);
    auto pass = [&](MaterialModel m) {
      for (const ElementGroup& g : model.groups)
        k.forces[int(m)](model.blocks.data(), g.begin, g.end, Real(g.lambda), Real(g.mu), u.data(), f.data());
    };
    // Alternated medians, as time_alternating does for steps.
    const int reps = opt.quick ? 5 : 11, calls = opt.quick ? 3 : 20;
    std::vector<double> tp, ti;
    for (int r = 0; r < reps; ++r) {
      for (MaterialModel m : {MaterialModel::StVK, MaterialModel::InvertibleStVK}) {
        const Clock::time_point t0 = Clock::now();
        for (int c = 0; c < calls; ++c) pass(m);
        (m == MaterialModel::StVK ? tp : ti).push_back(seconds_since(t0) / calls);
      }
    }
    const double n = model.n_tets, sp = median(tp), si = median(ti);
    std::printf("| %-6s | %9d | %9.1f %% | %9.1f %% | %10.1f | %10.1f | %6.2fx |\n", name_of(precision), model.n_tets,
                100.0 * double(n_near) / n, 100.0 * double(blocks_near) / double(n_blocks), n / sp * 1e-6,
                n / si * 1e-6, sp / si);
  }
}

void table_invertible(const Options& opt) {
  std::printf("\n## Invertible StVK against plain StVK, one thread (M tets/s)\n\n");
  std::printf("The step, nothing near the floor (the swinging box):\n\n");
  std::printf("| real   |      tets |      stvk  | invertible | ratio   |\n");
  std::printf("|--------|-----------|------------|------------|---------|\n");
  invertible_step_rows<float>(opt);
  invertible_step_rows<double>(opt);
  std::printf(
      "\nThe element pass alone, a share of the box squashed to half its height (past the floor); near: elements\n"
      "under the floor, blocks: element blocks with one (the SVD runs lane by lane for one or two, else for\n"
      "the whole block, two such blocks at once):\n\n");
  std::printf("| real   |      tets |     near    |   blocks    |  stvk pass | invertible | ratio   |\n");
  std::printf("|--------|-----------|-------------|-------------|------------|------------|---------|\n");
  invertible_pass_rows<float>(opt);
  invertible_pass_rows<double>(opt);
}

// The element pass of quadratic tets (issue 42) against the linear one on
// the same tets: the kernels alone over every block, from a deformed state,
// alternated; ns per tet-step each, and their ratio. A quadratic tet has
// four quadrature points and ten nodes where a linear one has one and four.
template <class Real>
void quadratic_rows(const Options& opt) {
  const Precision precision = sizeof(Real) == 4 ? Precision::Float : Precision::Double;
  const TetMesh mesh = make_bench_box(opt.quick ? 5e3 : 2e4, 1, 0.1);
  const TetMesh nodes = make_quadratic_mesh(mesh);
  const std::vector<MaterialSpec> materials{MaterialSpec{MaterialModel::StVK, 1e5, 0.3, 1000}};
  const ElementConstants constants = compute_element_constants(mesh, materials);
  const ElementOrder order = compute_element_order(mesh, constants.volume, 1);
  LaneBlocks<Real> linear = make_lane_blocks<Real>(mesh, constants, order);
  QuadraticLaneBlocks<Real> quadratic = make_quadratic_lane_blocks<Real>(nodes, constants, order);
  auto address = [](auto& lanes) {  // node ids as the kernels read them, 4 x id (the mesh's own numbering)
    for (auto& B : lanes.blocks)
      for (auto& ids : B.node4)
        for (int32_t& id : ids) id *= 4;
  };
  address(linear);
  address(quadratic);
  std::vector<Node4<Real>, CacheAlignedAllocator<Node4<Real>>> u(nodes.X.size()), f(nodes.X.size());
  for (size_t i = 0; i < nodes.X.size(); ++i) {  // a bend and a twist, a few per cent of strain
    const Vec3& X = nodes.X[i];
    u[i].v[0] = Real(0.02 * X.y * X.z / 0.1);
    u[i].v[1] = Real(-0.01 * X.x * X.x / 0.1);
    u[i].v[2] = Real(0.015 * X.x * X.y / 0.1);
  }
  const int reps = opt.quick ? 5 : 15, sweeps = opt.quick ? 20 : 50;
  for (MaterialModel model : {MaterialModel::Linear, MaterialModel::StVK, MaterialModel::Corotational,
                              MaterialModel::NeoHookean, MaterialModel::InvertibleStVK}) {
    const KernelTable<Real>& k = kernels<Real>();
    std::vector<double> t1, t2;
    for (int r = 0; r < reps; ++r) {
      Clock::time_point t0 = Clock::now();
      for (int s = 0; s < sweeps; ++s)
        k.forces[int(model)](linear.blocks.data(), 0, int32_t(linear.blocks.size()), Real(5.8e4), Real(3.8e4), u.data(),
                             f.data());
      t1.push_back(seconds_since(t0) / sweeps);
      t0 = Clock::now();
      for (int s = 0; s < sweeps; ++s)
        k.quadratic_forces[int(model)](quadratic.blocks.data(), 0, int32_t(quadratic.blocks.size()), Real(5.8e4),
                                       Real(3.8e4), u.data(), f.data());
      t2.push_back(seconds_since(t0) / sweeps);
    }
    const double p1 = median(t1) * 1e9 / mesh.n_tets(), p2 = median(t2) * 1e9 / mesh.n_tets();
    std::printf("| %-6s | %-15s | %7d | %9.1f | %9.1f | %5.2f |\n", name_of(precision),
                std::string(to_string(model)).c_str(), mesh.n_tets(), p1, p2, p2 / p1);
  }
}

void table_quadratic(const Options& opt) {
  std::printf("\n## Quadratic tets (P2, 4 points, 10 nodes) against linear ones (P1): the element pass alone\n\n");
  std::printf("(ns per tet-step, one thread, the same tets; the accuracy each buys: docs/accuracy)\n\n");
  std::printf("| real   | model           |    tets |    P1 ns  |    P2 ns  | P2/P1 |\n");
  std::printf("|--------|-----------------|---------|-----------|-----------|-------|\n");
  quadratic_rows<float>(opt);
  quadratic_rows<double>(opt);
}

}  // namespace
}  // namespace tactile

int main(int argc, char** argv) {
  using namespace tactile;
  const std::pair<const char*, void (*)(const Options&)> tables[] = {
      {"rates", table_rates},        {"threads", table_threads},     {"passes", table_passes},
      {"effects", table_effects},    {"hand", table_hand},           {"refresh", table_refresh},
      {"isas", table_isas},          {"precision", table_precision}, {"invertible", table_invertible},
      {"quadratic", table_quadratic}};
  std::vector<std::string> names;
  for (const auto& [name, table] : tables) names.emplace_back(name);
  Options opt;
  CLI::App app("fem_bench: the FEM step benchmark; prints figures, passes and fails nothing.", "fem_bench");
  configure_command_line(app);
  app.add_flag("--quick", opt.quick, "small meshes and few repeats, for CI (seconds)");
  app.add_flag("--large", opt.large, "also 1 M and 2 M tets");
  app.add_option("--only", opt.only, "one table: " + CLI::detail::join(names, ", "))
      ->type_name("TABLE")
      ->check(one_of(names));
  if (const std::optional<int> status = parse_command_line(app, argc, argv)) return *status;
  std::printf("# tactile FEM step benchmark%s\n\n", opt.quick ? " (--quick)" : "");
  std::printf("CPU: %s, %u hardware threads; kernels: %s\n", cpu_name().c_str(), std::thread::hardware_concurrency(),
              std::string(kernel_isa()).c_str());
  std::printf("Box meshes (make_box, 6 tets per cell), E = 100 kPa, nu = 0.3, rho = 1000 kg/m^3, dt = dt_rest / 2,\n");
  std::printf("free bodies swinging and twisting unless a scene says otherwise. Medians of alternated runs.\n");
  std::fflush(stdout);

  for (const auto& [name, table] : tables) {
    if (!opt.wants(name)) continue;
    table(opt);
    std::fflush(stdout);
  }

  std::printf("\n## Allocations inside steps (all timed loops above): %lld\n",
              static_cast<long long>(alloc_count::count.load()));
  return 0;
}
