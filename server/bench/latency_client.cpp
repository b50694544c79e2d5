// Loopback latency client: connects to a running tactile-server as a device,
// sends DeviceInput at a fixed rate while it presses the device's proxy a few
// millimetres into the body and holds it there, and prints figures (it passes
// and fails nothing):
//
//   - latency from sending input N to receiving the first haptic frame whose
//     last_input_sequence >= N: p50, p90, p99, p99.9, max; and that latency
//     split into the wait for the step that used the input and what follows;
//   - haptic frames received, and the frames the device never got;
//   - how steady the force in the frames is while held.
//
//   tactile-server SCENE.json --port 8765 --token T --dt 0.001 &
//   latency_client --port 8765 --token T [--host 127.0.0.1] [--device stylus]
//                  [--rate 1000] [--seconds 5] [--press 1] [--depth 0.003]
//                  [--from x,y,z --to x,y,z] [--no-sweep]
//
// Without --from/--to the press starts where the first haptic frame shows the
// device's first proxy and goes --depth metres down (-y).
//
// What the figure includes: both instants are taken in this process on
// steady_clock, the first just before the write of input N, the second just
// after the read of the frame returns; so it holds the client's write and
// read, the loopback, the server's read of the input, its wait for the next
// step, the step, the frame's encoding and the server's write. It holds no
// scripting-language time. The split uses the frame's server_time_ns (the
// start of the step, on the server's steady_clock): it is only meaningful on
// one machine, where both read the same CLOCK_MONOTONIC.
//
// One thread does everything: asio's reactor wakes it for each frame (no CPU
// while it waits) and for a timer 100 us before each input's deadline, and it
// spins only those last 100 us (reading frames as they come). A second thread
// would add a wakeup hop to every input or share the Beast stream between
// threads, which Beast does not allow.
//
// Inputs slip by one input period (or one step, if longer) over the run: two
// clocks of the same rate on one machine otherwise keep one phase between
// input and step for the whole run, and the figure would be that phase's.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <optional>
#include <string>
#include <utility>  // before Boost.Asio: its awaitable.hpp uses std::exchange without it (GCC 12)
#include <vector>

#include <immintrin.h>

#include <boost/asio.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/websocket.hpp>

#include "app/command_line.hpp"
#include "tactile_generated.h"

namespace {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace websocket = beast::websocket;
namespace fb = flatbuffers;
namespace wire = tactile::proto;
using tcp = asio::ip::tcp;
using Clock = std::chrono::steady_clock;

constexpr auto kSpinWindow = std::chrono::microseconds(100);  // timer slack is ~50 us: spin the rest
constexpr int64_t kLateSendNs = 50'000;                       // a send this far past its deadline is "late"

struct Vec3 {
  double x = 0, y = 0, z = 0;
};

struct Options {
  std::string host = "127.0.0.1", port, token, device = "stylus";
  double rate = 1000;    // inputs per second [Hz]
  double seconds = 5;    // of inputs [s]
  double press = 1;      // time to go from `from` to `to` [s]
  double depth = 0.003;  // press depth when `to` is not given [m]
  std::optional<Vec3> from, to;
  bool sweep = true;  // slip the input phase against the steps over the run
};

// "x,y,z" as three finite numbers, or nullopt.
std::optional<Vec3> parse_xyz(const std::string& text) {
  double c[3];
  size_t begin = 0;
  for (int i = 0; i < 3; ++i) {
    const size_t end = i < 2 ? text.find(',', begin) : text.size();
    if (end == std::string::npos) return std::nullopt;
    const std::string part = text.substr(begin, end - begin);
    char* stop = nullptr;
    c[i] = std::strtod(part.c_str(), &stop);
    if (part.empty() || *stop != '\0' || !std::isfinite(c[i])) return std::nullopt;
    begin = end + 1;
  }
  return Vec3{c[0], c[1], c[2]};
}

// Reads the command line into `o`: nullopt when the client is to run, else
// its exit status (tactile::parse_command_line).
std::optional<int> parse_args(int argc, char** argv, Options& o) {
  CLI::App app(
      "Connects to a running tactile-server as a device, presses the device's proxy into the body and holds it, "
      "and prints the input-to-force latency, the frames lost and how steady the force is.",
      "latency_client");
  tactile::configure_command_line(app);
  const CLI::Validator xyz([](std::string& text) { return parse_xyz(text) ? std::string() : "not x,y,z: " + text; },
                           "x,y,z");
  std::string from, to;
  bool no_sweep = false;
  app.add_option("--host", o.host, "the server's address")->capture_default_str();
  app.add_option("--port", o.port, "the server's port")->required();
  app.add_option("--token", o.token, "the session's token, when the server asks for one");
  app.add_option("--device", o.device, "the device channel to drive")->capture_default_str();
  app.add_option("--rate", o.rate, "inputs per second, in (0, 100000] [Hz]")
      ->capture_default_str()
      ->check(tactile::number_where([](double v) { return v > 0 && v <= 100'000; }, "in (0, 100000]"));
  app.add_option("--seconds", o.seconds, "how long to send inputs, > 0 [s]")
      ->capture_default_str()
      ->check(tactile::positive_number());
  app.add_option("--press", o.press, "time to go from the start of the press to its end, >= 0 [s]")
      ->capture_default_str()
      ->check(tactile::number_where([](double v) { return v >= 0; }, ">= 0"));
  app.add_option("--depth", o.depth, "press depth below the proxy's first position (-y) without --to [m]")
      ->capture_default_str()
      ->check(tactile::finite_number());
  CLI::Option* from_option = app.add_option("--from", from, "where the press starts [m]")->check(xyz);
  CLI::Option* to_option = app.add_option("--to", to, "where the press ends [m]")->check(xyz);
  from_option->needs(to_option);
  to_option->needs(from_option);
  app.add_flag("--no-sweep", no_sweep, "keep the input's phase against the steps instead of slipping it");
  if (const std::optional<int> status = tactile::parse_command_line(app, argc, argv)) return status;
  if (!from.empty()) o.from = parse_xyz(from);
  if (!to.empty()) o.to = parse_xyz(to);
  o.sweep = !no_sweep;
  return std::nullopt;
}

int64_t ns_of(Clock::time_point t) {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(t.time_since_epoch()).count();
}

int64_t now_ns() { return ns_of(Clock::now()); }

Clock::duration seconds(double s) {
  return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
}

// What this client keeps of one haptic frame.
struct FrameRecord {
  uint64_t step = 0;
  double sim_time = 0;      // [s]
  int64_t server_ns = 0;    // start of the step, server steady_clock [ns]
  int64_t received_ns = 0;  // this client's steady_clock [ns]
  uint64_t last_input = 0;  // last_input_sequence
  float force_y = 0;        // on the device's first proxy [N]
};

// Same rank rule as server_bench.py's pct(), so the two clients' figures compare.
double percentile(std::vector<double> v, double p) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, size_t(p / 100 * double(v.size())))];
}

void print_row(const char* label, const std::vector<double>& ms) {
  std::printf("%-46s p50 %6.3f  p90 %6.3f  p99 %6.3f  p99.9 %6.3f  max %6.3f\n", label, percentile(ms, 50),
              percentile(ms, 90), percentile(ms, 99), percentile(ms, 99.9), percentile(ms, 100));
}

class LatencyClient {
 public:
  explicit LatencyClient(Options o) : opt_(std::move(o)), ws_(ioc_), timer_(ioc_) {}

  // Connects, says Hello, reads Welcome and SceneDescription (synchronously:
  // nothing is timed yet). Returns an error, or "" when greeted.
  std::string greet() {
    tcp::resolver resolver(ioc_);
    beast::get_lowest_layer(ws_).connect(resolver.resolve(opt_.host, opt_.port));
    // Nagle would hold an input back until the previous one is acknowledged.
    beast::get_lowest_layer(ws_).socket().set_option(tcp::no_delay(true));
    ws_.handshake(opt_.host + ":" + opt_.port, "/ws");
    ws_.binary(true);

    fb::FlatBufferBuilder b;
    const std::vector<fb::Offset<fb::String>> devices{b.CreateString(opt_.device)};
    b.Finish(wire::CreateEnvelope(b, wire::Message::Hello,
                                  wire::CreateHelloDirect(b, uint16_t(wire::ProtocolMajor::Current),
                                                          uint16_t(wire::ProtocolMinor::Current), wire::Role::Device,
                                                          opt_.token.c_str(), "latency_client", &devices)
                                      .Union()),
             wire::EnvelopeIdentifier());
    ws_.write(asio::buffer(b.GetBufferPointer(), b.GetSize()));
    for (const wire::Message want : {wire::Message::Welcome, wire::Message::SceneDescription}) {
      in_.consume(in_.size());
      ws_.read(in_);
      const wire::Envelope* e = envelope();
      if (!e) return "the server sent a message that is not a valid Envelope";
      if (e->message_type() == wire::Message::Error) {
        const wire::Error* err = e->message_as_Error();
        return std::string("the server refused: ") + wire::EnumNameErrorCode(err->code()) + ": " +
               (err->message() ? err->message()->str() : "");
      }
      if (e->message_type() != want)
        return std::string("expected ") + wire::EnumNameMessage(want) + ", got " +
               wire::EnumNameMessage(e->message_type());
      if (want == wire::Message::SceneDescription) read_scene(*e->message_as_SceneDescription());
    }
    if (proxy_ < 0 && !opt_.from) return "the scene has no proxy on device '" + opt_.device + "': give --from and --to";
    in_.consume(in_.size());
    return "";
  }

  // Sends the inputs on their deadlines while the frames are read, then
  // waits for the answers to the last ones. Returns false if the connection failed.
  bool run() {
    const size_t n_inputs = size_t(std::llround(opt_.seconds * opt_.rate));
    sent_ns_.assign(n_inputs + 1, 0);
    due_ns_.assign(n_inputs + 1, 0);
    answer_.assign(n_inputs + 1, -1);
    frames_.reserve(size_t((opt_.seconds + 2) / std::max(dt_, 1e-5)) + 1024);  // the hot loop does not grow it
    read();

    // The first frame says where the proxy is; the press starts there.
    while (frames_.empty() && !failed_) ioc_.run_one();
    if (failed_) return false;
    if (!opt_.from) {
      opt_.from = first_pose_;
      opt_.to = Vec3{first_pose_.x, first_pose_.y - opt_.depth, first_pose_.z};
    }
    measure_from_ = frames_.size();

    const double period = 1.0 / opt_.rate;
    const double slip = opt_.sweep ? std::max(period, dt_) / double(n_inputs) : 0.0;  // per input [s]
    const Clock::time_point t0 = Clock::now();
    start_ns_ = ns_of(t0);
    for (size_t k = 1; k <= n_inputs && !failed_; ++k) {
      const Clock::time_point due = t0 + seconds(double(k) * (period + slip));
      bool woken = false;
      timer_.expires_at(due - kSpinWindow);
      timer_.async_wait([&woken](beast::error_code) { woken = true; });
      while (!woken) ioc_.run_one();
      while (Clock::now() < due) {
        ioc_.poll();  // frames that come while spinning are still read and timed at once
        _mm_pause();
      }
      while (writing_ && !failed_) ioc_.run_one();  // the previous input is still being written (rare)
      due_ns_[k] = ns_of(due);
      send(k);
    }
    // The answers to the last inputs, then a clean close.
    const Clock::time_point stop = Clock::now() + std::chrono::milliseconds(200) + seconds(4 * dt_);
    while (!failed_ && newest_ < n_inputs && Clock::now() < stop) ioc_.run_one_until(stop);
    end_ns_ = now_ns();
    const bool ok = !failed_;
    closing_ = true;
    ws_.async_close(websocket::close_code::normal, [](beast::error_code) {});
    ioc_.run_for(std::chrono::seconds(1));
    return ok;
  }

  void report() const;

 private:
  const wire::Envelope* envelope() const {
    const auto* data = static_cast<const uint8_t*>(in_.data().data());
    fb::Verifier verifier(data, in_.size());
    return wire::VerifyEnvelopeBuffer(verifier) ? wire::GetEnvelope(data) : nullptr;
  }

  void read_scene(const wire::SceneDescription& s) {
    dt_ = s.dt();
    if (s.proxies())
      for (fb::uoffset_t j = 0; j < s.proxies()->size(); ++j) {
        const wire::ProxyInfo* p = s.proxies()->Get(j);
        if (p->device() && p->device()->str() == opt_.device) {
          proxy_ = int32_t(j);
          break;
        }
      }
  }

  void read() {
    ws_.async_read(in_, [this](beast::error_code ec, size_t) {
      const int64_t received = now_ns();  // first, before anything else costs time
      if (ec) {
        if (!closing_) {
          std::fprintf(stderr, "latency_client: connection lost: %s\n", ec.message().c_str());
          failed_ = true;
        }
        return;
      }
      on_message(received);
      in_.consume(in_.size());
      read();
    });
  }

  void on_message(int64_t received) {
    const wire::Envelope* e = envelope();
    if (!e) {
      ++invalid_;
      return;
    }
    if (e->message_type() == wire::Message::Error) {
      const wire::Error* err = e->message_as_Error();
      std::fprintf(stderr, "latency_client: server error %s: %s\n", wire::EnumNameErrorCode(err->code()),
                   err->message() ? err->message()->c_str() : "");
      return;
    }
    if (e->message_type() != wire::Message::HapticFrame) return;  // telemetry
    const wire::HapticFrame& h = *e->message_as_HapticFrame();
    FrameRecord f;
    f.step = h.step();
    f.sim_time = h.sim_time();
    f.server_ns = h.server_time_ns();
    f.received_ns = received;
    f.last_input = h.last_input_sequence();
    if (proxy_ >= 0 && h.proxies() && fb::uoffset_t(proxy_) < h.proxies()->size()) {
      const wire::ProxyHaptics* p = h.proxies()->Get(fb::uoffset_t(proxy_));
      f.force_y = p->force().y();
      if (frames_.empty()) {
        const wire::Vec3f& x = p->pose().position();
        first_pose_ = {x.x(), x.y(), x.z()};
      }
    }
    const int32_t index = int32_t(frames_.size());
    frames_.push_back(f);
    if (frames_.size() == 1) base_ = f.last_input;
    // Every input this frame is the first to have seen.
    const uint64_t seen = std::min<uint64_t>(f.last_input > base_ ? f.last_input - base_ : 0, sent_ns_.size() - 1);
    for (uint64_t s = newest_ + 1; s <= seen; ++s)
      if (sent_ns_[s] != 0) answer_[s] = index;
    newest_ = std::max(newest_, seen);
  }

  void send(size_t k) {
    const double a = opt_.press > 0 ? std::min(1.0, double(k) / (opt_.press * opt_.rate)) : 1.0;
    const Vec3 &x0 = *opt_.from, &x1 = *opt_.to;
    const wire::Vec3d position(x0.x + a * (x1.x - x0.x), x0.y + a * (x1.y - x0.y), x0.z + a * (x1.z - x0.z));
    const wire::Quatd orientation(1, 0, 0, 0);
    out_.Clear();  // keeps its buffer: no allocation per input
    const int64_t t = now_ns();
    out_.Finish(
        wire::CreateEnvelope(
            out_, wire::Message::DeviceInput,
            wire::CreateDeviceInputDirect(out_, opt_.device.c_str(), base_ + k, t, &position, &orientation, 0).Union()),
        wire::EnvelopeIdentifier());
    writing_ = true;
    sent_ns_[k] = now_ns();  // the write starts now: asio tries the send inside async_write
    ws_.async_write(asio::buffer(out_.GetBufferPointer(), out_.GetSize()), [this](beast::error_code ec, size_t) {
      writing_ = false;
      if (ec && !closing_) {
        std::fprintf(stderr, "latency_client: write failed: %s\n", ec.message().c_str());
        failed_ = true;
      }
    });
  }

  Options opt_;
  asio::io_context ioc_;
  websocket::stream<beast::tcp_stream> ws_;
  asio::steady_timer timer_;
  beast::flat_buffer in_;
  fb::FlatBufferBuilder out_{256};
  bool writing_ = false, failed_ = false, closing_ = false;

  double dt_ = 0;                 // the server's step, from SceneDescription [s]
  int32_t proxy_ = -1;            // the device's first proxy in HapticFrame.proxies
  Vec3 first_pose_;               // its position in the first frame [m]
  std::vector<int64_t> sent_ns_;  // per input sequence (index 0 unused) [ns]
  std::vector<int64_t> due_ns_;   // its deadline [ns]
  std::vector<int32_t> answer_;   // per input: the first frame that saw it, or -1
  std::vector<FrameRecord> frames_;
  size_t measure_from_ = 0;  // frames before the first input are not counted
  uint64_t base_ = 0;        // sequence of input k is base_ + k: the server's count runs on over connections
  uint64_t newest_ = 0;      // the newest input k a frame has seen
  int64_t start_ns_ = 0, end_ns_ = 0;
  int64_t invalid_ = 0;
};

void LatencyClient::report() const {
  const size_t n_inputs = sent_ns_.size() - 1;
  std::vector<double> total, to_step, wait, after_step, late_us;
  int64_t arrived_late = 0, sends_late = 0;
  // Frames in step order by start time, to find the first step after each send.
  std::vector<int64_t> starts;
  for (size_t i = measure_from_; i < frames_.size(); ++i) starts.push_back(frames_[i].server_ns);
  for (size_t k = 1; k <= n_inputs; ++k) {
    if (sent_ns_[k] == 0) continue;
    const double behind = 1e-3 * double(sent_ns_[k] - due_ns_[k]);
    late_us.push_back(behind);
    if (sent_ns_[k] - due_ns_[k] > kLateSendNs) ++sends_late;
    if (answer_[k] < 0) continue;
    const FrameRecord& f = frames_[size_t(answer_[k])];
    total.push_back(1e-6 * double(f.received_ns - sent_ns_[k]));
    to_step.push_back(1e-6 * double(f.server_ns - sent_ns_[k]));
    after_step.push_back(1e-6 * double(f.received_ns - f.server_ns));
    const auto next = std::upper_bound(starts.begin(), starts.end(), sent_ns_[k]);
    if (next != starts.end()) {
      wait.push_back(1e-6 * double(*next - sent_ns_[k]));
      if (f.server_ns > *next) ++arrived_late;
    }
  }

  std::printf("## Device input to haptic frame (C++ client, loopback, inputs at %g Hz, %g s, server step %.3g ms)\n\n",
              opt_.rate, opt_.seconds, 1e3 * dt_);
  std::printf("inputs sent %zu, answered %zu; sends more than %lld us past their deadline: %lld (p99 %.1f us)\n",
              late_us.size(), total.size(), (long long)(kLateSendNs / 1000), (long long)sends_late,
              percentile(late_us, 99));
  std::printf("latency [ms], from the write of input N to the read of the first frame that saw it:\n");
  print_row("  total", total);
  print_row("  write to the start of the step that used it", to_step);
  print_row("    of which waiting for the next step", wait);
  print_row("  step start to frame read (step, delivery)", after_step);
  if (!to_step.empty())
    std::printf("inputs that reached the step loop after the next step had started: %lld (%.2f %%)\n",
                (long long)arrived_late, 100.0 * double(arrived_late) / double(to_step.size()));

  // Frames the device never got: each frame is one loop step of dt (a step the
  // stepper sub-divides advances `step` by several but is still one frame).
  const size_t n_frames = frames_.size() - measure_from_;
  if (n_frames > 1 && dt_ > 0) {
    int64_t missing = 0;
    for (size_t i = measure_from_ + 1; i < frames_.size(); ++i)
      missing += std::max<int64_t>(0, std::llround((frames_[i].sim_time - frames_[i - 1].sim_time) / dt_) - 1);
    const FrameRecord &a = frames_[measure_from_], &b = frames_.back();
    std::printf(
        "\nhaptic frames received %zu, missing %lld (%.2f %%) over %.2f s simulated in %.2f s; "
        "steps %llu..%llu (%.1f per frame)\n",
        n_frames, (long long)missing, 100.0 * double(missing) / double(int64_t(n_frames) + missing),
        b.sim_time - a.sim_time, 1e-9 * double(end_ns_ - start_ns_), (unsigned long long)a.step,
        (unsigned long long)b.step, double(b.step - a.step) / double(n_frames - 1 + size_t(missing)));
  }
  if (invalid_) std::printf("messages that were not a valid Envelope: %lld\n", (long long)invalid_);

  // Held after the press, once the body has settled (damping times are tens of ms).
  const int64_t held_from = start_ns_ + int64_t(1e9 * (opt_.press + 0.2));
  std::vector<double> held;
  for (size_t i = measure_from_; i < frames_.size(); ++i)
    if (frames_[i].received_ns >= held_from) held.push_back(frames_[i].force_y);
  double mean = 0;
  for (double f : held) mean += f;
  mean = held.empty() ? 0 : mean / double(held.size());
  if (mean > 0) {
    const auto zeros = std::count_if(held.begin(), held.end(), [](double f) { return f <= 0; });
    std::printf("force while held: mean %.3f N, frames at 0: %.1f %%, peak %.1f x mean\n", mean,
                100.0 * double(zeros) / double(held.size()), *std::max_element(held.begin(), held.end()) / mean);
  }
}

}  // namespace

int main(int argc, char** argv) {
  Options options;
  if (const std::optional<int> status = parse_args(argc, argv, options)) return *status;
  try {
    LatencyClient client(std::move(options));
    if (const std::string err = client.greet(); !err.empty()) {
      std::fprintf(stderr, "latency_client: %s\n", err.c_str());
      return 1;
    }
    const bool ok = client.run();
    client.report();
    return ok ? 0 : 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "latency_client: %s\n", e.what());
    return 1;
  }
}
