// tactile-accuracy: runs the accuracy-cost study (study/accuracy.hpp) and
// writes its records as JSON, for server/bench/accuracy_report.py to plot.
//
// Exit codes: 0 done, 1 a run failed to build (the message says which), 2 bad command line.
#include <cstdio>
#include <exception>
#include <fstream>
#include <optional>
#include <string>

#include "app/command_line.hpp"
#include "app/progress.hpp"
#include "study/accuracy.hpp"

int main(int argc, char** argv) {
  using namespace tactile::study;
  AccuracyOptions options;
  std::string out_path;
  bool quiet = false;
  CLI::App app("tactile-accuracy: the accuracy-cost study, as JSON for server/bench/accuracy_report.py.",
               "tactile-accuracy");
  tactile::configure_command_line(app);
  app.footer("exit status: 0 done, 1 a run failed to build, 2 bad command line");
  app.add_option("--out", out_path, "where the records go")->type_name("FILE.json")->required();
  app.add_flag("--quick", options.quick, "coarse levels and fewer variations (seconds), as the test suite runs it");
  app.add_option("--scenes", options.scenes,
                 "the shipped scenes (fig2_twist.json, fig3_cantilever.json, spheres_press.json)")
      ->type_name("DIR")
      ->capture_default_str();
  app.add_option("--only", options.only,
                 "cantilever_deflection, cantilever_frequency, wave_speed, rotation, fig3_tip, fig2_area,\n"
                 "hertz (two soft spheres pressed together; not with --quick) or realtime")
      ->type_name("PROBLEM");
  app.add_flag("--quiet", quiet, "no progress bar");
  if (const std::optional<int> status = tactile::parse_command_line(app, argc, argv)) return *status;
  const bool progress = !quiet;
  tactile::ProgressBar bar(stderr, progress, "accuracy");
  options.progress = [&](size_t done, size_t total, const std::string& what) {
    bar.update(total ? double(done) / double(total) : 1.0, what);
  };
  AccuracyResults results;
  try {
    results = run_accuracy_study(options);
  } catch (const std::exception& e) {
    bar.finish();
    std::fprintf(stderr, "tactile-accuracy: %s\n", e.what());
    return 1;
  }
  bar.finish();
  std::ofstream f(out_path);
  f << accuracy_json(results, options.quick);
  if (!f) {
    std::fprintf(stderr, "tactile-accuracy: could not write %s\n", out_path.c_str());
    return 2;
  }
  std::printf("tactile-accuracy: %zu records, %zu real-time scans -> %s\n", results.records.size(),
              results.realtime.size(), out_path.c_str());
  return 0;
}
