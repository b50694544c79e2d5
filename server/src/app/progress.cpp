#include "app/progress.hpp"

#include <algorithm>

#include <unistd.h>

namespace tactile {

ProgressBar::ProgressBar(std::FILE* out, bool enabled, std::string label)
    : out_(out), enabled_(enabled && out && ::isatty(::fileno(out))), label_(std::move(label)) {
  start_ = last_ = Clock::now();
}

ProgressBar::~ProgressBar() { finish(); }

void ProgressBar::update(double fraction, const std::string& note) {
  if (!enabled_) return;
  const Clock::time_point now = Clock::now();
  const double elapsed = std::chrono::duration<double>(now - start_).count();
  if (elapsed < 1.0 || (drawn_ && now - last_ < std::chrono::milliseconds(100))) return;
  last_ = now;
  fraction = std::clamp(fraction, 0.0, 1.0);
  constexpr int kWidth = 30;
  const int filled = int(fraction * kWidth + 0.5);
  std::string bar(size_t(filled), '#');
  bar.append(size_t(kWidth - filled), '.');
  const double eta = fraction > 0 ? elapsed * (1.0 - fraction) / fraction : 0.0;
  std::fprintf(out_, "\r\033[K%s [%s] %3.0f%% %s  %.0f s left", label_.c_str(), bar.c_str(), 100.0 * fraction,
               note.c_str(), eta);
  std::fflush(out_);
  drawn_ = true;
}

void ProgressBar::finish() {
  if (!drawn_) return;
  std::fprintf(out_, "\r\033[K");
  std::fflush(out_);
  drawn_ = false;
}

void MeshingProgress::begin(const std::string& field, double expected_tets, double expected_s) {
  end();
  done_ = false;
  char note[96];
  std::snprintf(note, sizeof note, "about %.1f M tets (%s)", expected_tets / 1e6, field.c_str());
  drawer_ = std::thread([this, note = std::string(note), expected_s] {
    ProgressBar bar(out_, enabled_, "meshing");
    const auto start = std::chrono::steady_clock::now();
    std::unique_lock<std::mutex> lock(mutex_);
    while (!wake_.wait_for(lock, std::chrono::milliseconds(100), [this] { return done_; })) {
      const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      bar.update(std::min(0.99, elapsed / expected_s), note);
    }
  });
}

void MeshingProgress::end() {
  if (!drawer_.joinable()) return;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    done_ = true;
  }
  wake_.notify_all();
  drawer_.join();
}

}  // namespace tactile
