// A one-line progress bar on a terminal, for runs that take more than a second.
//
// Debian 12 packages no C++ progress-bar library (indicators is not there),
// and a bar that redraws one line needs little code.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <mutex>
#include <string>
#include <thread>

#include "scene/scene_mesh.hpp"

namespace tactile {

class ProgressBar {
 public:
  // Draws on `out` only when `enabled` and `out` is a terminal.
  ProgressBar(std::FILE* out, bool enabled, std::string label);
  ~ProgressBar();

  // fraction in [0, 1]; the bar appears once a second has passed, then redraws at most 10 times a second.
  void update(double fraction, const std::string& note);
  // Clears the line, if one was drawn.
  void finish();

 private:
  using Clock = std::chrono::steady_clock;
  std::FILE* out_;
  bool enabled_;
  bool drawn_ = false;
  std::string label_;
  Clock::time_point start_, last_;
};

// A progress bar for long meshing (scene/scene_mesh.hpp): TetGen says
// nothing while it works, so the bar runs on the time expected, from its
// own thread, and stops at 99 % until the meshing ends.
class MeshingProgress final : public MeshingWatch {
 public:
  MeshingProgress(std::FILE* out, bool enabled) : out_(out), enabled_(enabled) {}
  ~MeshingProgress() override { end(); }
  void begin(const std::string& field, double expected_tets, double expected_s) override;
  void end() override;

 private:
  std::FILE* out_;
  bool enabled_;
  std::thread drawer_;
  std::mutex mutex_;
  std::condition_variable wake_;
  bool done_ = false;
};

}  // namespace tactile
