// The short version of the hard-case stability suite (tactile-stability
// --quick): one test per case, named after it, so a failure names the case,
// the material and the mesh, and says which check failed and the figures.
#include <gtest/gtest.h>

#include <cctype>
#include <map>
#include <string>
#include <vector>

#include "study/stability.hpp"

namespace tactile::study {
namespace {

SuiteOptions quick() {
  SuiteOptions o;
  o.quick = true;
  return o;
}

std::vector<std::string> case_names() {
  std::vector<std::string> names;
  for (const StabilityCase& c : stability_cases(quick())) names.push_back(c.name);
  return names;
}

// Cases the suite found failing, each a bug still open (issue 8), skipped here by name so the rest of the
// suite guards against regressions meanwhile; tactile-stability still runs and fails them. Empty this as
// they are fixed: a fixed case that is still listed fails below.
const std::map<std::string, std::string>& known_failures() {
  static const std::map<std::string, std::string> known{};
  return known;
}

class Stability : public ::testing::TestWithParam<std::string> {};

TEST_P(Stability, StaysFiniteBoundedAndReportsWhatItCannotDo) {
  SuiteOptions o = quick();
  o.filter = GetParam();
  const std::vector<StabilityCase> cases = stability_cases(o);
  ASSERT_FALSE(cases.empty());
  for (const StabilityCase& c : cases) {
    if (c.name != GetParam()) continue;
    const CaseOutcome r = c.run();
    RecordProperty("outcome", r.outcome);
    if (const auto known = known_failures().find(r.name); known != known_failures().end()) {
      ASSERT_FALSE(r.pass) << r.name << " passes now: take it off known_failures()";
      GTEST_SKIP() << "known failure, open: " << known->second << " (this run: " << r.why << ")";
    }
    EXPECT_TRUE(r.pass) << r.name << " (expects: " << to_string(r.expect) << "): " << r.outcome << " -- " << r.why
                        << "; size x" << r.size_ratio << ", drift " << r.energy_drift << ", depth " << r.penetration_mm
                        << " mm, " << r.steps << " steps";
    EXPECT_FALSE(r.outcome.empty()) << r.name;
  }
}

std::string test_name(const ::testing::TestParamInfo<std::string>& info) {
  std::string s;
  for (char ch : info.param) s += std::isalnum(static_cast<unsigned char>(ch)) ? ch : '_';
  return s;
}

INSTANTIATE_TEST_SUITE_P(Quick, Stability, ::testing::ValuesIn(case_names()), test_name);

}  // namespace
}  // namespace tactile::study
