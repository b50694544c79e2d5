// The recordings of a live server, one at a time (record/recorder.hpp writes
// each): started by a controller's StartRecording or the command line's
// --record, fed by the network thread with every message it serves and
// receives, stopped by StopRecording, a fault of the recorder, or the
// server's stop; a stopped one closes its file off the network thread and is
// logged once closed. Not thread-safe: the network thread's.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "record/recorder.hpp"

namespace tactile {

class Recording {
 public:
  // Where a controller's StartRecording `name` goes in `folder`: a plain
  // file name (letters, digits, '.', '_', '-'; not starting with '.'; at
  // most 128; ".mcap" added when missing), or "" for
  // session-<UTC to the millisecond>[-N].mcap, N counting up past files
  // already there. The path, or "" and `error` says what is wrong (no
  // folder, a name that is not plain, a file already there).
  static std::string path_in(const std::string& folder, const std::string& name,
                             std::chrono::system_clock::time_point now, std::string* error);

  // Starts one at `path` with `metadata`: "" or what is wrong (one under
  // way already; a file that cannot be made, which is not left behind).
  std::string start(const std::string& path, const mcap::Map& metadata, RecorderOptions options = {});
  bool active() const { return recorder_ != nullptr; }
  const std::string& path() const;  // the one under way ("" for none)

  // A message for the one under way, stamped with the server's steady clock [ns].
  void post(Topic topic, std::span<const uint8_t> message, int64_t time_ns) {
    if (recorder_) recorder_->post(topic, time_ns, 0, message);
  }
  // Stops the one under way with `fault` (it shows in stats() until check()).
  void fail(const std::string& fault) {
    if (recorder_) recorder_->fail(fault);
  }
  void stop();  // the one under way, if any: its file closes off this thread

  // Logs each stopped recording whose file has closed, and lets it go; the
  // fault that stopped the one under way (which is then stopped), once, as
  // "recording: <fault>", else "".
  std::string check();
  RecorderStats stats() const;  // the one under way (empty for none)
  void finish();                // stops and waits for every file to close (the server's stop)

 private:
  std::unique_ptr<Recorder> recorder_;                // under way
  std::vector<std::unique_ptr<Recorder>> finishing_;  // stopped, closing their files
};

}  // namespace tactile
