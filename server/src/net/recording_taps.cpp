#include "net/server_impl.hpp"

namespace tactile {

// ---- recording ---------------------------------------------------------------------------

void Server::Impl::record(Topic topic, const uint8_t* data, size_t n, int64_t time_ns) {
  if (recorder) recorder->post(topic, time_ns, 0, {data, n});
}

void Server::Impl::tap_feed(Feed& f) {
  if (!f.tap) f.tap = std::make_unique<RecordTap>(f.state_bytes(), f.haptic_bytes());
  // Frames left from an earlier recording's last moments are not this one's.
  f.tap->states.drain([](const uint8_t*, size_t) {});
  f.tap->haptics.drain([](const uint8_t*, size_t) {});
  f.tap->applied.drain([](const uint8_t*, size_t) {});
  f.tap->states_dropped = f.tap->states.dropped();
  f.tap->haptics_dropped = f.tap->haptics.dropped();
  f.tap->applied_dropped = f.tap->applied.dropped();
  f.recording.store(true, std::memory_order_release);
}

// Every frame the simulation published since the last drain, stamped with
// its own server time.
void Server::Impl::drain_tap(Feed& f) {
  if (!recorder || !f.tap) return;
  f.tap->haptics.drain([&](const uint8_t* data, size_t n) {
    record(Topic::Haptic, data, n, wire::GetEnvelope(data)->message_as_HapticFrame()->server_time_ns());
  });
  f.tap->states.drain([&](const uint8_t* data, size_t n) {
    record(Topic::State, data, n, wire::GetEnvelope(data)->message_as_StateFrame()->server_time_ns());
  });
  const int64_t now = now_ns();
  f.tap->applied.drain([&](const uint8_t* data, size_t) {
    AppliedInput a;
    std::memcpy(&a, data, sizeof a);
    char json[256];
    const int n = format_applied(a, json, sizeof json);
    record(Topic::Applied, reinterpret_cast<const uint8_t*>(json), size_t(n), now);
  });
  const int64_t lost_h = f.tap->haptics.dropped() - f.tap->haptics_dropped;
  const int64_t lost_s = f.tap->states.dropped() - f.tap->states_dropped;
  const int64_t lost_a = f.tap->applied.dropped() - f.tap->applied_dropped;
  if (lost_h > 0 || lost_s > 0 || lost_a > 0)
    recorder->fail("the simulation published frames faster than the recording took them (" + std::to_string(lost_h) +
                   " haptic and " + std::to_string(lost_s) + " state frames, " + std::to_string(lost_a) +
                   " applied inputs had no room): stopped, what was written stays readable");
}

namespace {

// A double as text that reads back to the same bits.
std::string exact(double v) {
  char s[32];
  std::snprintf(s, sizeof s, "%.17g", v);
  return s;
}

std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return in ? std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>()) : "";
}

}  // namespace

std::string Server::Impl::start_recording(const std::string& name, bool any_path) {
  if (recorder) return "a recording is under way ('" + recorder->path() + "'): stop it first";
  std::string path = name;
  if (!any_path) {
    if (options.recordings_dir.empty())
      return "StartRecording: this server has no recordings folder (start it with --recordings DIR)";
    std::string file = name;
    if (file.empty()) {  // session-<UTC to the millisecond>[-N].mcap: a second one in the same second is its own
      const auto now = std::chrono::system_clock::now();
      const std::time_t t = std::chrono::system_clock::to_time_t(now);
      const auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(now.time_since_epoch()).count() % 1000;
      char stamp[48];
      const size_t n = std::strftime(stamp, sizeof stamp, "%Y%m%d-%H%M%S", std::gmtime(&t));
      std::snprintf(stamp + n, sizeof stamp - n, "-%03lld", static_cast<long long>(ms));
      file = std::string("session-") + stamp + ".mcap";
      std::error_code ec;
      for (int k = 2; std::filesystem::exists(std::filesystem::path(options.recordings_dir) / file, ec); ++k)
        file = std::string("session-") + stamp + "-" + std::to_string(k) + ".mcap";
    }
    const bool plain = file.size() <= 128 && file[0] != '.' && std::all_of(file.begin(), file.end(), [](char ch) {
                         return std::isalnum(static_cast<unsigned char>(ch)) || ch == '.' || ch == '_' || ch == '-';
                       });
    if (!plain)
      return "StartRecording: '" + printable_text(file) +
             "' is not a plain file name (letters, digits, '.', '_', '-'; not starting with '.'; at most 128)";
    if (!file.ends_with(".mcap")) file += ".mcap";
    std::error_code ec;
    std::filesystem::create_directories(options.recordings_dir, ec);
    path = (std::filesystem::path(options.recordings_dir) / file).string();
    if (std::filesystem::exists(path, ec))
      return "StartRecording: '" + file + "' is already in the recordings folder: pick another name";
  }
  const Scene& scene = feed->live->scene();
  mcap::Map meta{{"scene_name", scene.name},
                 {"scene_path", scene.path},
                 {"scene_file", read_text(scene.path)},
                 {"variant", scene.variant},
                 {"scene_id", std::to_string(feed->live->id())},
                 {"dt", exact(feed->live->loop().dt())},
                 {"state_rate_hz", exact(options.live.state_rate_hz)},
                 {"haptic_rate_hz", exact(options.live.haptic_rate_hz)},
                 {"force_window", exact(options.live.force_window)},
                 {"server", options.server_name}};
  std::error_code ec;
  const bool existed = std::filesystem::exists(path, ec);
  try {
    recorder = std::make_unique<Recorder>(path, meta);
  } catch (const mcap::McapError& e) {
    // (A full disk: the file may have been made, empty. Not left behind.)
    if (!existed) std::filesystem::remove(path, ec);
    return std::string("StartRecording: ") + e.what();
  }
  std::fprintf(stderr, "recording: %s\n", path.c_str());
  record(Topic::Scene, feed->description);
  tap_feed(*feed);
  if (incoming) tap_feed(*incoming);
  const Bytes t = telemetry_message("");
  for (WsSession* s : sessions)
    if (s->core().greeted()) s->send(t, OutKind::Control);
  return "";
}

void Server::Impl::stop_recording() {
  if (!recorder) return;
  for (Feed* f : {feed.get(), incoming.get()}) {
    if (!f) continue;
    f->recording.store(false, std::memory_order_release);
    drain_tap(*f);
  }
  recorder->stop();
  const RecorderStats st = recorder->stats();
  std::fprintf(stderr, "recording: stopped %s\n", st.path.c_str());
  finishing.push_back(std::move(recorder));
  const Bytes t = telemetry_message("");
  for (WsSession* s : sessions)
    if (s->core().greeted()) s->send(t, OutKind::Control);
}

std::string Server::Impl::check_recorder() {
  std::erase_if(finishing, [](const std::unique_ptr<Recorder>& r) {
    const RecorderStats st = r->stats();
    if (!st.finished) return false;
    r->wait();
    // The file's size as it lies on disk: what the writer handed over may
    // not all have landed (a full disk).
    std::error_code ec;
    const uintmax_t on_disk = std::filesystem::file_size(st.path, ec);
    std::fprintf(stderr, "recording: closed %s: %llu messages, %llu bytes", st.path.c_str(),
                 static_cast<unsigned long long>(st.messages), static_cast<unsigned long long>(ec ? 0 : on_disk));
    if (st.late > 0)
      std::fprintf(stderr, "; %llu came after a later-stamped one and carry its log time",
                   static_cast<unsigned long long>(st.late));
    if (st.unreadable > 0)
      std::fprintf(stderr, "; %llu did not verify as Envelopes and are left out",
                   static_cast<unsigned long long>(st.unreadable));
    std::fprintf(stderr, "\n");
    return true;
  });
  if (!recorder) return "";
  const std::string fault = recorder->stats().fault;
  if (fault.empty()) return "";
  std::fprintf(stderr, "recording: %s: %s\n", recorder->path().c_str(), fault.c_str());
  stop_recording();
  return "recording: " + fault;
}

}  // namespace tactile
