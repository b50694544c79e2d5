#include "live/director.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <thread>

#include "scene/parameters.hpp"

namespace tactile {

namespace {

double step_for(const Scene& scene, const Simulation& sim, const LiveOptions& options) {
  if (options.dt) return *options.dt;
  if (scene.spec.integrator.dt > 0) return scene.spec.integrator.dt;
  return 0.7 * sim.dt_rest();  // RealtimeLoop's default, said here so the encoder announces the same
}

RealtimeOptions loop_options(double dt, const LiveOptions& options) {
  RealtimeOptions ro;
  ro.dt = dt;
  ro.state_rate_hz = options.state_rate_hz;
  ro.haptic_rate_hz = options.haptic_rate_hz;
  return ro;
}

// The haptic forces' window: as asked, and never shorter than the interval
// between haptic frames, so that every step's force reaches a frame.
double window_for(double dt, const LiveOptions& options) {
  double w = options.force_window;
  if (options.haptic_rate_hz > 0) w = std::max(w, std::ceil(1.0 / (options.haptic_rate_hz * dt) - 1e-9) * dt);
  return w;
}

// The most element-steps per second a live scene may ask for: five times
// what one core steps of plain StVK (fem_bench; docs/perf.md). A scene past
// it (a material far stiffer than its mesh was made for) falls behind real
// time on any machine this runs on, and sends a state every few seconds.
constexpr double kMaxLiveTetStepsPerSecond = 1e9;

}  // namespace

LiveScene::LiveScene(Scene scene, uint32_t id, const LiveOptions& options)
    : scene_(std::move(scene)),
      id_(id),
      sim_(scene_.spec),
      frames_(sim_, scene_.name, id_, step_for(scene_, sim_, options),
              window_for(step_for(scene_, sim_, options), options)),
      loop_(sim_, frames_, loop_options(step_for(scene_, sim_, options), options)) {
  const double dt = loop_.dt(), rate = double(sim_.n_tets()) / dt;
  if (rate > kMaxLiveTetStepsPerSecond) {
    char text[400];
    std::snprintf(text, sizeof text,
                  "scene '%s' would step every %.3g s (critical step at rest %.3g s): %d tets at %.3g steps per "
                  "second is %.3g tet-steps per second, more than a live loop keeps up with (%.0e); run it "
                  "headless instead (tactile-sim run), where it takes the time it needs",
                  scene_.name.c_str(), dt, sim_.dt_rest(), sim_.n_tets(), 1.0 / dt, rate, kMaxLiveTetStepsPerSecond);
    throw ModelError(text);
  }
  loop_.set_view_fields(scene_.view_fields);  // the server adds what its viewers ask
}

void LiveScene::publish(std::shared_ptr<Wakeup> wakeup) {
  // The most a frame takes: a state, its positions and up to four fields per
  // surface vertex and a pose and force per proxy; a haptic frame, ~92 B per
  // proxy and ~100 B per device channel (live/frames.hpp).
  const size_t state_bytes = 256 + 20 * 3 * frames_.surface().nodes.size() + 64 * sim_.proxies().size();
  const size_t haptic_bytes = 512 + 128 * sim_.proxies().size() + 160 * sim_.devices().size();
  outbox_ = std::make_unique<Outbox>(state_bytes, haptic_bytes, std::move(wakeup));
  outbox_->attach(loop_);
}

std::vector<uint8_t> LiveScene::describe(std::span<const std::string> scenes) {
  const std::vector<Parameter> parameters = list_parameters(scene_.spec);
  const std::span<const uint8_t> d = frames_.scene_description(parameters, scenes);
  return {d.begin(), d.end()};
}

Director::Director(std::shared_ptr<LiveScene> first) : next_id_(first->id() + 1), current_(std::move(first)) {
  current_->publish(wakeup_);
}

Director::~Director() { finish_building(); }

void Director::finish_building() {
  if (builder_.joinable()) builder_.join();
}

void Director::set_library(const std::string& scenes_dir, const LiveOptions& options) {
  scenes_dir_ = scenes_dir;
  options_ = options;
  scenes_.clear();
  if (scenes_dir.empty()) return;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(scenes_dir, ec)) {
    const std::string name = entry.path().filename().string();
    if (entry.is_regular_file() && entry.path().extension() == ".json" && name.find(".schema.") == std::string::npos)
      scenes_.push_back(name);
  }
  std::sort(scenes_.begin(), scenes_.end());
}

std::string Director::request(const Change& change, Done done, bool* busy) {
  if (busy) *busy = false;
  if (building_.load()) {
    if (busy) *busy = true;
    return "a scene change is under way: wait for its SceneDescription";
  }
  const std::shared_ptr<LiveScene> running = current();
  Scene scene = running->scene();
  std::string load_path;
  bool carry = false;
  uint32_t id = next_id_;
  if (change.kind == Change::Kind::Load) {
    if (std::find(scenes_.begin(), scenes_.end(), change.scene) == scenes_.end()) {
      std::string known;
      for (const std::string& n : scenes_) known += (known.empty() ? "" : ", ") + n;
      return "no scene '" + change.scene +
             "' on this server; it has: " + (known.empty() ? "none (no scene folder)" : known);
    }
    load_path = (std::filesystem::path(scenes_dir_) / change.scene).string();
  } else if (change.kind == Change::Kind::Parameter) {
    try {
      apply_parameter(scene.spec, change.parameter, change.value);
    } catch (const SceneError& e) {
      return e.what();
    }
    // The body goes on under the new parameter, in the same timeline; after
    // a fault there is no body to carry, and it starts again from rest.
    carry = fault().empty();
    if (carry) id = running->id();
  }
  if (id == next_id_) ++next_id_;
  finish_building();
  building_.store(true);
  builder_ = std::thread(
      [this, scene = std::move(scene), load_path, id, carry, done = std::move(done), options = options_]() mutable {
        std::shared_ptr<LiveScene> live;
        try {
          if (!load_path.empty()) scene = load_scene(load_path).front();
          live = std::make_shared<LiveScene>(std::move(scene), id, options);
        } catch (const std::exception& e) {
          building_.store(false);
          return done(nullptr, e.what());
        }
        live->publish(wakeup_);
        replace(std::move(live), carry, std::move(done));
        building_.store(false);
      });
  return "";
}

std::shared_ptr<LiveScene> Director::current() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return current_;
}

void Director::replace(std::shared_ptr<LiveScene> next, bool carry, Done done) {
  std::shared_ptr<LiveScene> running;
  Done replaced;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (next_) replaced = std::move(next_done_);
    next_ = std::move(next);
    carry_ = carry;
    next_done_ = std::move(done);
    running = current_;
  }
  if (replaced) replaced(nullptr, "replaced by a later change before it ran");
  running->loop().interrupt();
}

void Director::set_view_fields(ViewFieldMask extra) {
  std::lock_guard<std::mutex> lock(mutex_);
  extra_fields_ = extra;
  current_->loop().set_view_fields(current_->scene().view_fields | extra);
}

std::string Director::fault() const {
  if (!faulted_.load()) return "";
  return current()->loop().stats().fault;
}

void Director::run(const std::atomic<bool>& stop, double duration) {
  double ran = 0;
  std::shared_ptr<LiveScene> scene = current();
  while (!stop.load(std::memory_order_relaxed)) {
    if (!faulted_.load()) {
      scene->loop().run(stop, duration - ran);
      const RealtimeStats st = scene->loop().stats();
      ran += st.sim_time;
      if (ran >= duration - 1e-12) return;
      if (!st.fault.empty()) {
        faulted_.store(true);
        std::fprintf(stderr,
                     "tactile-server: the simulation stopped at t = %.6f s on a fault: %s (a reset or a scene load "
                     "starts it again)\n",
                     scene->sim().time(), st.fault.c_str());
        if (duration < std::numeric_limits<double>::infinity()) return;
      }
    }
    std::shared_ptr<LiveScene> next;
    bool carry = false;
    Done done;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      next = std::move(next_);
      carry = carry_;
      done = std::move(next_done_);
    }
    if (!next) {
      // Interrupted with nothing to switch to (a replacement replaced), or
      // faulted and waiting for one.
      if (faulted_.load()) std::this_thread::sleep_for(std::chrono::milliseconds(1));
      continue;
    }
    if (carry && !faulted_.load()) next->sim().continue_from(scene->sim());
    next->loop().set_paused(scene->loop().paused());
    {
      std::lock_guard<std::mutex> lock(mutex_);
      next->loop().set_view_fields(next->scene().view_fields | extra_fields_);
      current_ = next;
    }
    faulted_.store(false);
    scene = std::move(next);
    if (installed_) installed_(scene);
    if (done) done(scene, "");
  }
}

}  // namespace tactile
