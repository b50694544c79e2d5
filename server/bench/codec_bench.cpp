// Codec benchmark, C++: the size of the protocol's frames and what encoding
// and decoding one costs (proto/tactile.fbs). The same cases as
// proto/python/bench_codec.py and proto/js/bench/codec.bench.js, so that the
// three tables compare. Prints figures, passes and fails nothing.
//
//   build/release/codec_bench           all cases (a few seconds)
//   build/release/codec_bench --quick   fewer repeats, for CI
//
// Cases: StateFrames of about 5 k, 20 k and 50 k surface vertices (positions,
// a scalar per vertex, 1 proxy), HapticFrames of 1 proxy / 1 device and of 5
// proxies / 1 device. Columns:
//   encode   FrameEncoder::state_frame / haptic_frame: the server's own path,
//            gathering from the Simulation included;
//   builder  the same frame built from ready arrays with the generated
//            builder, which is what the Python and JavaScript figures time;
//   decode   verify the Envelope, get it and the frame, and read every value
//            once (sums), as the server does with what it receives;
//   read     the same without the verifier (what a trusting reader pays).
// Times are medians over repeated batches of calls, per frame.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include <flatbuffers/flatbuffers.h>

#include "app/command_line.hpp"
#include "live/frames.hpp"
#include "mesh/primitives.hpp"
#include "sim/simulation.hpp"
#include "tactile_generated.h"

namespace tactile {
namespace {

using Clock = std::chrono::steady_clock;
namespace wire = proto;

// What the timed calls return goes here, so that the compiler keeps them.
volatile double g_sink = 0;

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// Seconds per call of f: the median over `repeats` batches, each batch long
// enough (>= 2 ms) that the clock's resolution does not show.
template <class F>
double time_per_call(F&& f, int repeats) {
  int calls = 1;
  for (;;) {  // find the batch size (this also warms the caches and the builders)
    const Clock::time_point t0 = Clock::now();
    for (int k = 0; k < calls; ++k) g_sink = g_sink + f();
    if (std::chrono::duration<double>(Clock::now() - t0).count() >= 2e-3) break;
    calls *= 2;
  }
  std::vector<double> samples;
  for (int r = 0; r < repeats; ++r) {
    const Clock::time_point t0 = Clock::now();
    for (int k = 0; k < calls; ++k) g_sink = g_sink + f();
    samples.push_back(std::chrono::duration<double>(Clock::now() - t0).count() / calls);
  }
  return median(samples);
}

// A slab one cell thick, (n + 1)^2 x 2 nodes of 1 mm cells: every node is on
// the surface, so the encoder's gather copies the surface only and the
// figures are the codec's, not those of a body's interior (a solid cube of
// 50 k surface vertices would carry ~780 k nodes).
ModelSpec slab_spec(int surface_vertices, int n_proxies) {
  const int n = std::max(1, int(std::lround(std::sqrt(surface_vertices / 2.0))) - 1);
  const double h = 1e-3;  // cell edge [m]
  ModelSpec spec;
  spec.mesh = make_box(Vec3(0.0), Vec3(n * h, h, n * h), {n, 1, n});
  spec.materials = {MaterialSpec{MaterialModel::StVK, 3e4, 0.3, 1000}};
  // One proxy on a stylus, or a hand of several finger tips on one glove.
  if (n_proxies > 1) spec.hands = {HandSpec{"right", "glove", Pose{}, {}}};
  for (int j = 0; j < n_proxies; ++j) {
    ProxySpec p;
    p.name = "tip" + std::to_string(j);
    p.device = n_proxies > 1 ? "" : "stylus";
    p.hand = n_proxies > 1 ? "right" : "";
    p.geometry = ProxyGeometry{ProxyShape::Sphere, 0.008, 0, Vec3(0.0)};
    p.pose.position = Vec3(0.01 * (j + 1), 0.02, 0.01);  // above the slab
    spec.proxies.push_back(p);
  }
  return spec;
}

const wire::Envelope* open(std::span<const uint8_t> bytes, bool verify) {
  if (verify) {
    flatbuffers::Verifier v(bytes.data(), bytes.size());
    if (!wire::VerifyEnvelopeBuffer(v)) throw std::runtime_error("the encoded frame does not verify");
  }
  return wire::GetEnvelope(bytes.data());
}

double sum(const wire::Vec3f& v) { return double(v.x()) + v.y() + v.z(); }
double sum(const wire::Quatf& q) { return double(q.w()) + q.x() + q.y() + q.z(); }
double sum(const wire::ProxyPose& p) { return sum(p.position()) + sum(p.orientation()); }
double sum(const wire::Mat3f& m) {
  return double(m.m00()) + m.m01() + m.m02() + m.m10() + m.m11() + m.m12() + m.m20() + m.m21() + m.m22();
}

// Decodes a StateFrame and reads every value once.
double read_state(std::span<const uint8_t> bytes, bool verify) {
  const wire::StateFrame* f = open(bytes, verify)->message_as_StateFrame();
  double s = f->sim_time() + double(f->step()) + double(f->server_time_ns()) + f->scene_id();
  for (float x : *f->positions()) s += x;
  for (float x : *f->scalar()) s += x;
  for (const wire::ProxyPose* p : *f->proxies()) s += sum(*p);
  for (const wire::Vec3f* v : *f->contact_forces()) s += sum(*v);
  return s;
}

// Decodes a HapticFrame and reads every value once.
double read_haptic(std::span<const uint8_t> bytes, bool verify) {
  const wire::HapticFrame* f = open(bytes, verify)->message_as_HapticFrame();
  double s = f->sim_time() + double(f->step()) + double(f->server_time_ns()) + double(f->last_input_sequence()) +
             f->scene_id();
  for (const wire::ProxyHaptics* p : *f->proxies())
    s += sum(p->force()) + sum(p->torque()) + sum(p->pose()) + sum(p->stiffness()) + p->contacts();
  for (const wire::DeviceHaptics* d : *f->devices())
    s += sum(d->force()) + sum(d->torque()) + sum(d->stiffness()) + d->contacts();
  for (const wire::ProxyPose* p : *f->device_poses()) s += sum(*p);
  for (uint64_t q : *f->device_input_sequences()) s += double(q);
  return s;
}

template <class T>
size_t seal(flatbuffers::FlatBufferBuilder& b, wire::Message type, flatbuffers::Offset<T> body) {
  b.Finish(wire::CreateEnvelope(b, type, body.Union()), wire::EnvelopeIdentifier());
  return b.GetSize();
}

// The decoded frame's arrays, ready for the builder-only encode.
struct StateArrays {
  std::vector<float> positions, scalar;  // (n_vertices x 3) [m], (n_vertices)
  std::vector<wire::ProxyPose> proxies;  // (n_proxies)
  std::vector<wire::Vec3f> forces;       // (n_proxies) [N]
};

StateArrays copy_state(std::span<const uint8_t> bytes) {
  const wire::StateFrame* f = open(bytes, true)->message_as_StateFrame();
  StateArrays a;
  a.positions.assign(f->positions()->begin(), f->positions()->end());
  a.scalar.assign(f->scalar()->begin(), f->scalar()->end());
  for (const wire::ProxyPose* p : *f->proxies()) a.proxies.push_back(*p);
  for (const wire::Vec3f* v : *f->contact_forces()) a.forces.push_back(*v);
  return a;
}

size_t build_state(flatbuffers::FlatBufferBuilder& b, const StateArrays& a) {
  b.Clear();
  const auto positions = b.CreateVector(a.positions);
  const auto scalar = b.CreateVector(a.scalar);
  const auto proxies = b.CreateVectorOfStructs(a.proxies.data(), a.proxies.size());
  const auto forces = b.CreateVectorOfStructs(a.forces.data(), a.forces.size());
  return seal(b, wire::Message::StateFrame,
              wire::CreateStateFrame(b, 1, 1000, 0.2, 123456789, positions, scalar, proxies, forces));
}

struct HapticArrays {
  std::vector<wire::ProxyHaptics> proxies;    // (n_proxies)
  std::vector<wire::DeviceHaptics> devices;   // (n_devices)
  std::vector<wire::ProxyPose> device_poses;  // (n_devices)
  std::vector<uint64_t> sequences;            // (n_devices)
};

HapticArrays copy_haptic(std::span<const uint8_t> bytes) {
  const wire::HapticFrame* f = open(bytes, true)->message_as_HapticFrame();
  HapticArrays a;
  for (const wire::ProxyHaptics* p : *f->proxies()) a.proxies.push_back(*p);
  for (const wire::DeviceHaptics* d : *f->devices()) a.devices.push_back(*d);
  for (const wire::ProxyPose* p : *f->device_poses()) a.device_poses.push_back(*p);
  a.sequences.assign(f->device_input_sequences()->begin(), f->device_input_sequences()->end());
  return a;
}

size_t build_haptic(flatbuffers::FlatBufferBuilder& b, const HapticArrays& a) {
  b.Clear();
  const auto proxies = b.CreateVectorOfStructs(a.proxies.data(), a.proxies.size());
  const auto devices = b.CreateVectorOfStructs(a.devices.data(), a.devices.size());
  const auto device_poses = b.CreateVectorOfStructs(a.device_poses.data(), a.device_poses.size());
  const auto sequences = b.CreateVector(a.sequences);
  return seal(b, wire::Message::HapticFrame,
              wire::CreateHapticFrame(b, 1, 1000, 0.2, 123456789, 42, proxies, devices, device_poses, sequences));
}

struct Row {
  std::string name;
  size_t bytes = 0, vertices = 0;                        // vertices: 0 for haptic frames
  double encode = 0, builder = 0, decode = 0, read = 0;  // [s per frame]
};

void print(const std::vector<Row>& rows) {
  std::printf("C++ codec cost per frame (flatbuffers %d.%d.%d, medians)\n\n", FLATBUFFERS_VERSION_MAJOR,
              FLATBUFFERS_VERSION_MINOR, FLATBUFFERS_VERSION_REVISION);
  std::printf("%-18s %9s %8s %8s %10s %11s %10s %9s\n", "frame", "vertices", "bytes", "B/vert", "encode us",
              "builder us", "decode us", "read us");
  for (const Row& r : rows) {
    char per_vertex[16] = "-", vertices[16] = "-";
    if (r.vertices > 0) {
      std::snprintf(per_vertex, sizeof per_vertex, "%.2f", double(r.bytes) / double(r.vertices));
      std::snprintf(vertices, sizeof vertices, "%zu", r.vertices);
    }
    std::printf("%-18s %9s %8zu %8s %10.2f %11.2f %10.2f %9.2f\n", r.name.c_str(), vertices, r.bytes, per_vertex,
                1e6 * r.encode, 1e6 * r.builder, 1e6 * r.decode, 1e6 * r.read);
  }
  std::printf(
      "\nencode: FrameEncoder (gathers from the Simulation); builder: from ready arrays;\n"
      "decode: verify + read every value; read: without the verifier.\n");
}

int run(int argc, char** argv) {
  bool quick = false;
  CLI::App app("Times the encoding and decoding of state and haptic frames of 5 k to 50 k-element bodies.",
               "codec_bench");
  configure_command_line(app);
  app.add_flag("--quick", quick, "5 repeats a case instead of 31 (a smoke run, not figures to quote)");
  if (const std::optional<int> status = parse_command_line(app, argc, argv)) return *status;
  const int repeats = quick ? 5 : 31;
  std::vector<Row> rows;
  flatbuffers::FlatBufferBuilder builder;

  for (int target : {5000, 20000, 50000}) {
    Simulation sim(slab_spec(target, 1));
    sim.advance(1e-3);  // so that step and time are not 0, which the builder would leave out
    FrameEncoder frames(sim, "bench", 1, 0.0);
    const std::span<const uint8_t> first = frames.state_frame(123456789);
    const std::vector<uint8_t> bytes(first.begin(), first.end());  // the span lives until the next call
    const StateArrays arrays = copy_state(bytes);
    Row r;
    r.name = "state " + std::to_string(target / 1000) + "k";
    r.vertices = frames.surface().nodes.size();
    r.bytes = bytes.size();
    r.encode = time_per_call([&] { return double(frames.state_frame(123456789).size()); }, repeats);
    r.builder = time_per_call([&] { return double(build_state(builder, arrays)); }, repeats);
    r.decode = time_per_call([&] { return read_state(bytes, true); }, repeats);
    r.read = time_per_call([&] { return read_state(bytes, false); }, repeats);
    rows.push_back(r);
  }

  for (int n_proxies : {1, 5}) {
    Simulation sim(slab_spec(200, n_proxies));  // a haptic frame does not depend on the mesh
    sim.advance(1e-3);
    FrameEncoder frames(sim, "bench", 1, 0.0);
    frames.add_step_forces();
    const std::vector<uint64_t> sequences(sim.devices().size(), 42);  // the newest input per channel
    const std::span<const uint8_t> first = frames.haptic_frame(123456789, 42, sequences);
    const std::vector<uint8_t> bytes(first.begin(), first.end());
    const HapticArrays arrays = copy_haptic(bytes);
    Row r;
    r.name = "haptic " + std::to_string(n_proxies) + "p/" + std::to_string(sim.devices().size()) + "d";
    r.bytes = bytes.size();
    r.encode = time_per_call([&] { return double(frames.haptic_frame(123456789, 42, sequences).size()); }, repeats);
    r.builder = time_per_call([&] { return double(build_haptic(builder, arrays)); }, repeats);
    r.decode = time_per_call([&] { return read_haptic(bytes, true); }, repeats);
    r.read = time_per_call([&] { return read_haptic(bytes, false); }, repeats);
    rows.push_back(r);
  }
  print(rows);
  return 0;
}

}  // namespace
}  // namespace tactile

int main(int argc, char** argv) { return tactile::run(argc, argv); }
