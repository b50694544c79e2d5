#include "live/resim.hpp"

#include <cmath>
#include <cstring>
#include <deque>
#include <iterator>
#include <map>
#include <memory>
#include <optional>

#include <nlohmann/json.hpp>

#include "live/director.hpp"
#include "record/mcap.hpp"
#include "record/recorder.hpp"
#include "tactile_generated.h"

namespace tactile {
namespace {

namespace wire = proto;

// What a file cut short lacks is said as its cut: "; cut short: <the reader's problems>".
std::string cut_note(const mcap::Recording& rec) {
  if (rec.complete) return "";
  std::string out = "; the file is cut short";
  for (const std::string& p : rec.problems) out += (out.ends_with("short") ? ": " : "; ") + p;
  return out;
}

const mcap::Map& tactile_metadata(const mcap::Recording& rec, const std::string& path) {
  for (const auto& [name, map] : rec.metadata)
    if (name == "tactile") return map;
  if (!rec.complete) throw ResimError("recording '" + path + "' ends before its 'tactile' metadata" + cut_note(rec));
  throw ResimError("recording '" + path + "' has no 'tactile' metadata: not a tactile-server recording");
}

const std::string& field(const mcap::Map& m, const std::string& key, const std::string& path) {
  const auto it = m.find(key);
  if (it == m.end() || it->second.empty())
    throw ResimError("recording '" + path + "' lacks '" + key + "' in its metadata (recorded by an older server?)");
  return it->second;
}

double number(const mcap::Map& m, const std::string& key, const std::string& path) {
  const std::string& text = field(m, key, path);
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (*end != '\0' || !std::isfinite(v))
    throw ResimError("recording '" + path + "': metadata " + key + " is not a number");
  return v;
}

template <class T>
bool same_vector(const flatbuffers::Vector<T>* a, const flatbuffers::Vector<T>* b) {
  const size_t na = a ? a->size() : 0, nb = b ? b->size() : 0;
  if (na != nb) return false;
  return na == 0 || std::memcmp(a->Data(), b->Data(), na * sizeof(T)) == 0;
}
template <class T>
bool same_structs(const flatbuffers::Vector<const T*>* a, const flatbuffers::Vector<const T*>* b) {
  const size_t na = a ? a->size() : 0, nb = b ? b->size() : 0;
  if (na != nb) return false;
  return na == 0 || std::memcmp(a->Data(), b->Data(), na * sizeof(T)) == 0;
}

// Field by field, the server's clock aside.
bool same_state(const wire::StateFrame& a, const wire::StateFrame& b) {
  const bool energies =
      (!a.energies() && !b.energies()) ||
      (a.energies() && b.energies() && std::memcmp(a.energies(), b.energies(), sizeof(wire::Energies)) == 0);
  return a.scene_id() == b.scene_id() && a.step() == b.step() && a.sim_time() == b.sim_time() &&
         same_vector(a.positions(), b.positions()) && same_vector(a.scalar(), b.scalar()) &&
         same_structs(a.proxies(), b.proxies()) && same_structs(a.contact_forces(), b.contact_forces()) && energies;
}
bool same_haptic(const wire::HapticFrame& a, const wire::HapticFrame& b) {
  return a.scene_id() == b.scene_id() && a.step() == b.step() && a.sim_time() == b.sim_time() &&
         a.last_input_sequence() == b.last_input_sequence() && same_structs(a.proxies(), b.proxies()) &&
         same_structs(a.devices(), b.devices()) && same_structs(a.device_poses(), b.device_poses()) &&
         same_vector(a.device_input_sequences(), b.device_input_sequences());
}

// The largest proxy force of a haptic frame [N].
double peak_proxy_force(const wire::HapticFrame& f) {
  double peak = 0;
  if (f.proxies())
    for (const wire::ProxyHaptics* p : *f.proxies())
      peak = std::max(peak, std::hypot(double(p->force().x()), double(p->force().y()), double(p->force().z())));
  return peak;
}

// The recorded frame nearest in simulated time to t, within `within`, or nullptr.
template <class Frame>
const Frame* nearest(const std::map<double, const Frame*>& frames, double t, double within) {
  auto it = frames.lower_bound(t);
  const Frame* best = nullptr;
  double gap = within;
  if (it != frames.end() && it->first - t <= gap) {
    best = it->second;
    gap = it->first - t;
  }
  if (it != frames.begin() && t - std::prev(it)->first <= gap) best = std::prev(it)->second;
  return best;
}

}  // namespace

namespace {

// One re-simulation in its stages: read_recording() (its first scene, its
// frames by simulated time, what the loop applied and the inputs),
// build_scene() (the recorded scene or another, paced as recorded),
// open_output() (the re-simulation as a recording, when asked), compare()
// (each frame the loop publishes against the recorded one), feed() (each
// input before the step it was applied at), then finish().
class Resimulation {
 public:
  explicit Resimulation(const ResimOptions& options) : o(options) {}
  ResimReport run() {
    read_recording();
    build_scene();
    open_output();
    compare();
    feed();
    finish();
    return report;
  }

 private:
  void read_recording();
  void build_scene();
  void open_output();
  void compare();
  void feed();
  void finish();

  struct Applied {
    int64_t loop_step;
    int32_t device;
    uint64_t sequence;
    DeviceDrive drive;
  };

  const ResimOptions& o;
  ResimReport report;
  mcap::Recording rec;
  const mcap::Map* meta = nullptr;  // the recording's 'tactile' metadata
  uint32_t scene_id = 0;
  std::vector<std::string> recorded_devices;
  std::map<double, const wire::StateFrame*> states;  // by simulated time
  std::map<double, const wire::HapticFrame*> haptics;
  double last_frame = 0;  // of the first scene, any kind [s]
  std::vector<Applied> applied;
  std::map<std::pair<std::string, uint64_t>, std::deque<const mcap::Message*>> inputs;
  Scene scene;
  LiveOptions lo;
  std::unique_ptr<LiveScene> live;
  std::vector<int32_t> device_index;  // per recorded channel, the scene's (-1: it has none)
  std::unique_ptr<Recorder> out;
  bool same_scene = false;
};

void Resimulation::read_recording() {
  rec = mcap::read_file(o.recording);
  restore_envelopes(rec);
  meta = &tactile_metadata(rec, o.recording);

  // The recorded session: its first scene, from its start.
  const uint16_t ch_scene = rec.channel_of("/scene"), ch_state = rec.channel_of("/state"),
                 ch_haptic = rec.channel_of("/haptic"), ch_input = rec.channel_of("/input"),
                 ch_applied = rec.channel_of("/applied");
  if (!ch_applied)
    throw ResimError("recording '" + o.recording + "' has no /applied channel (recorded by an older server?)");
  const wire::SceneDescription* recorded_scene = nullptr;
  for (const mcap::Message& m : rec.messages)
    if (m.channel == ch_scene) {
      recorded_scene = wire::GetEnvelope(m.data.data())->message_as_SceneDescription();
      break;
    }
  if (!recorded_scene) {
    std::string why = "recording '" + o.recording + "' holds no scene description";
    if (!rec.complete) why += " whole" + cut_note(rec);
    for (size_t k = 0; rec.complete && k < rec.problems.size(); ++k) why += "; " + rec.problems[k];  // (unread chunks)
    throw ResimError(why);
  }
  scene_id = recorded_scene->scene_id();
  if (recorded_scene->devices())
    for (const flatbuffers::String* d : *recorded_scene->devices()) recorded_devices.push_back(d->str());

  double first_state = -1;  // of the first scene
  bool later_scene = false;
  for (const mcap::Message& m : rec.messages) {
    if (m.channel == ch_state) {
      const wire::StateFrame* f = wire::GetEnvelope(m.data.data())->message_as_StateFrame();
      if (!f) continue;
      if (f->scene_id() != scene_id) {
        later_scene = true;
        continue;
      }
      if (first_state < 0) first_state = f->sim_time();
      last_frame = std::max(last_frame, f->sim_time());
      states[f->sim_time()] = f;
    } else if (m.channel == ch_haptic) {
      const wire::HapticFrame* f = wire::GetEnvelope(m.data.data())->message_as_HapticFrame();
      if (!f || f->scene_id() != scene_id) continue;
      haptics[f->sim_time()] = f;
      report.recorded_peak_force = std::max(report.recorded_peak_force, peak_proxy_force(*f));
      last_frame = std::max(last_frame, f->sim_time());
    }
  }
  if (first_state != 0.0)
    throw ResimError("recording '" + o.recording + "' starts at t = " + std::to_string(first_state) +
                     " s of its scene: a re-simulation starts from the scene's start (record with --record, "
                     "or from a load or reset)");
  if (!rec.complete)
    report.note =
        "the recording is cut short: re-simulated to its last whole frame, t = " + std::to_string(last_frame) +
        " s (inputs applied just before the cut may be lost with it)";
  if (later_scene)
    report.note += std::string(report.note.empty() ? "" : "; ") +
                   "the recording goes on in a later scene (a load, reset or parameter change): "
                   "re-simulated up to it";

  // What the loop applied, and the inputs themselves.
  for (const mcap::Message& m : rec.messages)
    if (m.channel == ch_applied) {
      const auto j = nlohmann::json::parse(m.data.begin(), m.data.end(), nullptr, false);
      if (j.is_discarded() || !j.contains("loop_step") || !j.contains("device") || !j.contains("sequence"))
        throw ResimError("recording '" + o.recording + "': an /applied message is not {loop_step, device, sequence}");
      Applied a{j["loop_step"].get<int64_t>(), j["device"].get<int32_t>(), j["sequence"].get<uint64_t>(), {}};
      a.drive.direct = j.value("direct", false);
      if (const auto l = j.find("limits"); l != j.end()) {
        if (!l->is_array() || l->size() != 3 || !(*l)[0].is_number() || !(*l)[1].is_number() || !(*l)[2].is_number())
          throw ResimError("recording '" + o.recording + "': an /applied message's limits are not 3 numbers");
        a.drive.has_limits = true;
        a.drive.limits = {(*l)[0].get<double>(), (*l)[1].get<double>(), (*l)[2].get<double>()};
      }
      applied.push_back(a);
    }
  for (const mcap::Message& m : rec.messages)
    if (m.channel == ch_input) {
      const wire::DeviceInput* in = wire::GetEnvelope(m.data.data())->message_as_DeviceInput();
      if (in && in->device()) inputs[{in->device()->str(), in->sequence()}].push_back(&m);
    }
}

void Resimulation::build_scene() {
  // The scene: the recorded one (its file as it was), or another.
  {
    std::vector<Scene> scenes;
    std::string variant = o.variant;
    if (o.scene.empty()) {
      const auto j = nlohmann::json::parse(field(*meta, "scene_file", o.recording), nullptr, false);
      if (j.is_discarded()) throw ResimError("recording '" + o.recording + "': its scene file is not JSON");
      scenes = parse_scene(j, field(*meta, "scene_path", o.recording));
      if (variant.empty() && meta->count("variant")) variant = meta->at("variant");
    } else if (!o.scene_text.empty()) {
      const auto j = nlohmann::json::parse(o.scene_text, nullptr, false);
      if (j.is_discarded()) throw SceneError(o.scene + ": not JSON");
      scenes = parse_scene(j, o.scene);
    } else {
      scenes = load_scene(o.scene);
    }
    const std::string path = o.scene.empty() ? "recording '" + o.recording + "'" : o.scene;
    scene = variant.empty() ? std::move(scenes.front()) : pick_variant(std::move(scenes), variant, path);
  }
  lo.dt = number(*meta, "dt", o.recording);
  lo.state_rate_hz = number(*meta, "state_rate_hz", o.recording);
  lo.haptic_rate_hz = number(*meta, "haptic_rate_hz", o.recording);
  lo.force_window = number(*meta, "force_window", o.recording);
  live = std::make_unique<LiveScene>(scene, scene_id, lo);
  report.scene_name = scene.name;
  // Channels by name: another scene may order them otherwise, or lack one.
  for (const std::string& name : recorded_devices) {
    const auto& names = live->sim().devices();
    const auto it = std::find(names.begin(), names.end(), name);
    device_index.push_back(it == names.end() ? -1 : int32_t(it - names.begin()));
  }
}

void Resimulation::open_output() {
  same_scene = o.scene.empty();
  if (!o.out.empty()) {
    mcap::Map m = *meta;
    m["scene_name"] = scene.name;
    m["scene_path"] = scene.path;
    m["resimulated_from"] = o.recording;
    if (!o.scene.empty()) m.erase("scene_file");  // (its own file is at scene_path)
    out = std::make_unique<Recorder>(o.out, m, RecorderOptions{.wait_for_room = true});
    const std::vector<uint8_t> d = live->describe({});
    out->post(Topic::Scene, 0, 0, d);
  }
}

void Resimulation::compare() {
  live->loop().on_state([this](std::span<const uint8_t> bytes) {
    const wire::StateFrame* f = wire::GetEnvelope(bytes.data())->message_as_StateFrame();
    ++report.states;
    if (out) out->post(Topic::State, int64_t(std::llround(f->sim_time() * 1e9)), 0, bytes);
    // The same scene steps to the same times, bit for bit; another may
    // subdivide its steps otherwise, and lands within half a step.
    const wire::StateFrame* found = nearest(states, f->sim_time(), same_scene ? 0.0 : 0.5 * lo.dt.value());
    if (!found) return;
    ++report.states_matched;
    const wire::StateFrame& r = *found;
    if (same_scene && same_state(*f, r)) {
      ++report.states_identical;
      return;
    }
    if (report.first_difference_time < 0) report.first_difference_time = f->sim_time();
    if (f->positions() && r.positions() && f->positions()->size() == r.positions()->size())
      for (size_t i = 0; i < f->positions()->size(); ++i)
        report.max_position_difference =
            std::max(report.max_position_difference, double(std::fabs(f->positions()->Get(i) - r.positions()->Get(i))));
  });
  live->loop().on_haptic([this](std::span<const uint8_t> bytes) {
    const wire::HapticFrame* f = wire::GetEnvelope(bytes.data())->message_as_HapticFrame();
    ++report.haptic;
    report.peak_force = std::max(report.peak_force, peak_proxy_force(*f));
    if (out) out->post(Topic::Haptic, int64_t(std::llround(f->sim_time() * 1e9)), 0, bytes);
    const wire::HapticFrame* found = nearest(haptics, f->sim_time(), same_scene ? 0.0 : 0.5 * lo.dt.value());
    if (!found) return;
    ++report.haptic_matched;
    const wire::HapticFrame& r = *found;
    if (same_scene && same_haptic(*f, r)) {
      ++report.haptic_identical;
      return;
    }
    if (f->proxies() && r.proxies())
      for (size_t j = 0; j < std::min(f->proxies()->size(), r.proxies()->size()); ++j) {
        const wire::Vec3f& a = f->proxies()->Get(j)->force();
        const wire::Vec3f& b = r.proxies()->Get(j)->force();
        report.max_force_difference =
            std::max(report.max_force_difference,
                     std::hypot(double(a.x() - b.x()), double(a.y() - b.y()), double(a.z() - b.z())));
      }
  });
}

void Resimulation::feed() {
  RealtimeLoop& loop = live->loop();
  const Simulation& sim = live->sim();
  loop.begin(0);
  size_t next = 0;
  while (sim.time() < last_frame - 0.5 * loop.dt()) {
    const int64_t k = loop.loop_steps();
    for (; next < applied.size() && applied[next].loop_step <= k; ++next) {
      const Applied& a = applied[next];
      if (a.device < 0 || size_t(a.device) >= recorded_devices.size())
        throw ResimError("recording '" + o.recording + "': an input applied on channel " + std::to_string(a.device) +
                         ", which its scene lacks");
      const std::string& name = recorded_devices[size_t(a.device)];
      auto found = inputs.find({name, a.sequence});
      if (found == inputs.end() || found->second.empty())
        throw ResimError("recording '" + o.recording + "': input " + std::to_string(a.sequence) + " of channel '" +
                         name + "' was applied but is not in the recording");
      const mcap::Message* m = found->second.front();
      found->second.pop_front();
      if (device_index[size_t(a.device)] < 0) continue;  // another scene without this channel: noted below
      const wire::DeviceInput* in = wire::GetEnvelope(m->data.data())->message_as_DeviceInput();
      loop.post_input(device_sample(*in, device_index[size_t(a.device)], a.drive));
      ++report.inputs;
      if (out) {
        out->post(Topic::Input, int64_t(std::llround(sim.time() * 1e9)), 0, m->data);
        char json[256];
        const int n = format_applied({k, device_index[size_t(a.device)], a.sequence, a.drive}, json, sizeof json);
        out->post(Topic::Applied, int64_t(std::llround(sim.time() * 1e9)), 0,
                  {reinterpret_cast<const uint8_t*>(json), size_t(n)});
      }
    }
    loop.step(int64_t(std::llround((sim.time() + loop.dt()) * 1e9)));
    ++report.steps;
    if (const std::string fault = loop.stats().fault; !fault.empty()) {
      report.note += std::string(report.note.empty() ? "" : "; ") +
                     "the re-simulation stopped on a fault at t = " + std::to_string(sim.time()) + " s: " + fault;
      break;
    }
  }
}

void Resimulation::finish() {
  for (size_t d = 0; d < device_index.size(); ++d)
    if (device_index[d] < 0)
      report.note += std::string(report.note.empty() ? "" : "; ") + "scene '" + scene.name + "' has no channel '" +
                     recorded_devices[d] + "': its inputs were left out";
  if (out) {
    out->stop();
    out->wait();
    if (const std::string fault = out->stats().fault; !fault.empty())
      throw ResimError("writing " + o.out + ": " + fault);
  }
}

}  // namespace

ResimReport resimulate(const ResimOptions& o) { return Resimulation(o).run(); }

}  // namespace tactile
