// tactile-stability: the hard-case stability suite (study/stability.hpp),
// case by case, as a table with pass or fail and the figures behind it.
//
// Exit codes: 0 every case passed, 1 a case failed, 2 bad command line.
#include <cstdio>
#include <fstream>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "app/command_line.hpp"
#include "app/progress.hpp"
#include "study/stability.hpp"

namespace {

using namespace tactile::study;

std::string figure(double v, const char* f) {
  if (v < 0) return "-";
  char s[32];
  std::snprintf(s, sizeof s, f, v);
  return s;
}

}  // namespace

int main(int argc, char** argv) {
  SuiteOptions options;
  std::string json_path;
  bool quiet = false;
  CLI::App app("tactile-stability: the hard-case stability suite, case by case.", "tactile-stability");
  tactile::configure_command_line(app);
  app.footer("exit status: 0 all passed, 1 a case failed, 2 bad command line");
  app.add_flag("--quick", options.quick, "the short version (coarse meshes, shorter runs), as ctest runs it");
  app.add_option("--only", options.filter, "only the cases whose name (group/material/mesh) contains TEXT")
      ->type_name("TEXT");
  app.add_option("--seed", options.seed, "seed of the random velocities and device input")
      ->type_name("N")
      ->capture_default_str();
  app.add_option("--json", json_path, "also write every case's figures as JSON")->type_name("FILE");
  app.add_flag("--quiet", quiet, "no progress bar");
  if (const std::optional<int> status = tactile::parse_command_line(app, argc, argv)) return *status;
  const bool progress = !quiet;

  const std::vector<StabilityCase> cases = stability_cases(options);
  if (cases.empty()) {
    std::fprintf(stderr, "tactile-stability: no case matches '%s'\n", options.filter.c_str());
    return 2;
  }
  std::printf("%-44s %-9s %-5s %6s %9s %7s %6s %7s %7s %7s %8s %6s  %s\n", "case", "expects", "pass", "tets", "steps",
              "size", "drift", "depth", "force", "bodies", "substeps", "wall", "outcome");
  std::printf("%-44s %-9s %-5s %6s %9s %7s %6s %7s %7s %7s %8s %6s\n", "", "", "", "", "", "x rest", "%", "mm", "N",
              "mm", "max", "s");
  nlohmann::json all = nlohmann::json::array();
  int failed = 0;
  tactile::ProgressBar bar(stderr, progress, "stability");
  for (size_t k = 0; k < cases.size(); ++k) {
    bar.update(double(k) / double(cases.size()), cases[k].name);
    const CaseOutcome r = cases[k].run();
    bar.finish();
    if (!r.pass) ++failed;
    std::printf("%-44s %-9s %-5s %6d %9lld %7s %6s %7s %7s %7s %8d %6.1f  %s%s%s\n", r.name.c_str(),
                to_string(r.expect), r.pass ? "pass" : "FAIL", r.tets, static_cast<long long>(r.steps),
                figure(r.size_ratio, "%.2f").c_str(),
                figure(r.energy_drift < 0 ? -1 : 100 * r.energy_drift, "%.2f").c_str(),
                figure(r.peak_force_N < 0 ? -1 : r.penetration_mm, "%.2f").c_str(),
                figure(r.peak_force_N, "%.2f").c_str(), figure(r.body_depth_mm, "%.3f").c_str(), r.substeps_max,
                r.wall_s, r.outcome.c_str(), r.pass ? "" : " -- ", r.why.c_str());
    std::fflush(stdout);
    all.push_back(nlohmann::json::parse(outcome_json(r)));
  }
  std::printf("\n%zu cases: %zu passed, %d failed\n", cases.size(), cases.size() - size_t(failed), failed);
  if (!json_path.empty()) {
    std::ofstream f(json_path);
    f << all.dump(1) << "\n";
    if (!f) {
      std::fprintf(stderr, "tactile-stability: could not write %s\n", json_path.c_str());
      return 2;
    }
  }
  return failed ? 1 : 0;
}
