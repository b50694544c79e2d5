// A one-line progress bar on a terminal, for runs that take more than a second.
//
// Debian 12 packages no C++ progress-bar library (indicators is not there),
// and a bar that redraws one line needs little code.
#pragma once

#include <chrono>
#include <cstdio>
#include <string>

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

}  // namespace tactile
