#include "record/recording.hpp"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <ctime>
#include <filesystem>

namespace tactile {

namespace {

// A string for a one-line message: control characters shown as '?'.
std::string printable(std::string out) {
  for (char& c : out)
    if (uint8_t(c) < 0x20 || c == 0x7f) c = '?';
  return out;
}

bool plain_name(const std::string& file) {
  return !file.empty() && file.size() <= 128 && file[0] != '.' && std::all_of(file.begin(), file.end(), [](char ch) {
    return std::isalnum(static_cast<unsigned char>(ch)) || ch == '.' || ch == '_' || ch == '-';
  });
}

}  // namespace

std::string Recording::path_in(const std::string& folder, const std::string& name,
                               std::chrono::system_clock::time_point now, std::string* error) {
  namespace fs = std::filesystem;
  if (folder.empty()) {
    *error = "StartRecording: this server has no recordings folder (start it with --recordings DIR)";
    return "";
  }
  std::error_code ec;
  std::string file = name;
  if (file.empty()) {  // a second one in the same millisecond is its own
    const std::time_t t = std::chrono::system_clock::to_time_t(now);
    const auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(now.time_since_epoch()).count() % 1000;
    char stamp[48];
    const size_t n = std::strftime(stamp, sizeof stamp, "%Y%m%d-%H%M%S", std::gmtime(&t));
    std::snprintf(stamp + n, sizeof stamp - n, "-%03lld", static_cast<long long>(ms));
    file = std::string("session-") + stamp + ".mcap";
    for (int k = 2; fs::exists(fs::path(folder) / file, ec); ++k)
      file = std::string("session-") + stamp + "-" + std::to_string(k) + ".mcap";
  }
  if (!plain_name(file)) {
    *error = "StartRecording: '" + printable(file) +
             "' is not a plain file name (letters, digits, '.', '_', '-'; not starting with '.'; at most 128)";
    return "";
  }
  if (!file.ends_with(".mcap")) file += ".mcap";
  const fs::path path = fs::path(folder) / file;
  if (fs::exists(path, ec)) {
    *error = "StartRecording: '" + file + "' is already in the recordings folder: pick another name";
    return "";
  }
  fs::create_directories(folder, ec);
  return path.string();
}

std::string Recording::start(const std::string& path, const mcap::Map& metadata, RecorderOptions options) {
  if (recorder_) return "a recording is under way ('" + recorder_->path() + "'): stop it first";
  std::error_code ec;
  const bool existed = std::filesystem::exists(path, ec);
  try {
    recorder_ = std::make_unique<Recorder>(path, metadata, options);
  } catch (const mcap::McapError& e) {
    // (A full disk: the file may have been made, empty. Not left behind.)
    if (!existed) std::filesystem::remove(path, ec);
    return std::string("StartRecording: ") + e.what();
  }
  std::fprintf(stderr, "recording: %s\n", path.c_str());
  return "";
}

const std::string& Recording::path() const {
  static const std::string none;
  return recorder_ ? recorder_->path() : none;
}

void Recording::stop() {
  if (!recorder_) return;
  recorder_->stop();
  std::fprintf(stderr, "recording: stopped %s\n", recorder_->path().c_str());
  finishing_.push_back(std::move(recorder_));
}

std::string Recording::check() {
  std::erase_if(finishing_, [](const std::unique_ptr<Recorder>& r) {
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
  if (!recorder_) return "";
  const std::string fault = recorder_->stats().fault;
  if (fault.empty()) return "";
  std::fprintf(stderr, "recording: %s: %s\n", recorder_->path().c_str(), fault.c_str());
  stop();
  return "recording: " + fault;
}

RecorderStats Recording::stats() const { return recorder_ ? recorder_->stats() : RecorderStats{}; }

void Recording::finish() {
  stop();
  for (auto& r : finishing_) r->wait();  // closed files, with their summaries
  finishing_.clear();
}

}  // namespace tactile
