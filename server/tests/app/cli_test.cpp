// tactile-sim as a user runs it: what it prints, what it writes, its exit codes.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <string>

#include <sys/wait.h>

#include <nlohmann/json.hpp>

#include "app_fixtures.hpp"

namespace tactile {
namespace {

namespace fs = std::filesystem;
using test::TempDir;

struct Outcome {
  int code;
  std::string out, err;
};

// Runs tactile-sim with `args` (shell words), capturing stdout and stderr.
Outcome run_cli(const TempDir& dir, const std::string& args) {
  const std::string out = dir.file("stdout.txt"), err = dir.file("stderr.txt");
  const std::string cmd = std::string("'") + TACTILE_SIM_EXE + "' " + args + " > '" + out + "' 2> '" + err + "'";
  const int status = std::system(cmd.c_str());
  EXPECT_TRUE(WIFEXITED(status)) << cmd;
  return {WEXITSTATUS(status), test::read_file(out), test::read_file(err)};
}

std::string beam_scene(const std::string& integrator) {
  return R"({
    "name": "clibeam",
    "mesh": { "primitive": "box", "lo": [0, 0, 0], "hi": [0.4, 0.1, 0.1], "cells": [8, 2, 2] },
    "material": { "model": "stvk", "E": 1e5, "nu": 0.3, "rho": 1000 },
    "boundary": [ { "name": "clamp", "select": { "box": { "lo": [0, 0, 0], "hi": [0, 0.1, 0.1] } }, "fixed": true } ],
    "effects": { "gravity": [0, -9.81, 0] },
    "integrator": )" +
         integrator + R"(,
    "run": { "duration": 0.05, "frame_rate": 100, "track": [ { "name": "tip", "point": [0.4, 0.05, 0.05] } ] },
    "variants": [ { "name": "lin", "material": { "model": "linear" } }, { "name": "nh", "material": { "model": "neohookean" } } ]
  })";
}

TEST(Cli, HelpAndBadCommandLines) {
  TempDir dir;
  Outcome o = run_cli(dir, "--help");
  EXPECT_EQ(o.code, 0);
  for (const char* part : {"run", "check", "resim", "--precision", "--no-vtu", "--scene"})
    EXPECT_NE(o.out.find(part), std::string::npos) << part;  // every command's options, in one text
  o = run_cli(dir, "run --help");
  EXPECT_EQ(o.code, 0);
  EXPECT_NE(o.out.find("tactile-sim run [OPTIONS] SCENE.json"), std::string::npos) << o.out;
  o = run_cli(dir, "");
  EXPECT_EQ(o.code, 2);
  EXPECT_NE(o.err.find("A subcommand is required"), std::string::npos) << o.err;
  o = run_cli(dir, "run x.json --precision half");
  EXPECT_EQ(o.code, 2);
  EXPECT_NE(o.err.find("--precision: must be float or double, got half"), std::string::npos) << o.err;
  o = run_cli(dir, "run x.json --threads 0");
  EXPECT_EQ(o.code, 2);
  EXPECT_NE(o.err.find("--threads"), std::string::npos) << o.err;
  o = run_cli(dir, "run x.json --frobnicate");
  EXPECT_EQ(o.code, 2);
  EXPECT_NE(o.err.find("not expected: --frobnicate"), std::string::npos) << o.err;
  o = run_cli(dir, "run x.json --scene y.json");  // --scene is resim's
  EXPECT_EQ(o.code, 2);
  EXPECT_NE(o.err.find("--scene"), std::string::npos) << o.err;
}

TEST(Cli, BadSceneExitsTwoNamingTheField) {
  TempDir dir;
  const std::string scene = dir.file("bad.json");
  test::write_file(scene, beam_scene(R"({ "dt": "fast" })"));
  for (const char* cmd : {"check", "run"}) {
    const std::string out = std::string(cmd) == "run" ? " --out '" + dir.file("out") + "'" : "";
    const Outcome o = run_cli(dir, std::string(cmd) + " '" + scene + "'" + out);
    EXPECT_EQ(o.code, 2) << cmd;
    EXPECT_NE(o.err.find(scene + ": variant 'lin': integrator.dt: must be \"auto\" or a number > 0, got \"fast\""),
              std::string::npos)
        << o.err;
  }
  EXPECT_EQ(run_cli(dir, "check '" + dir.file("missing.json") + "'").code, 2);
}

TEST(Cli, CheckPrintsQualityAndTheCriticalStep) {
  TempDir dir;
  const std::string scene = dir.file("ok.json");
  test::write_file(scene, beam_scene(R"({ "dt": "auto" })"));
  const Outcome o = run_cli(dir, "check '" + scene + "'");
  EXPECT_EQ(o.code, 0) << o.err;
  EXPECT_NE(o.out.find("192 tets, 81 nodes"), std::string::npos) << o.out;
  EXPECT_NE(o.out.find("critical step at rest"), std::string::npos) << o.out;
  EXPECT_FALSE(fs::exists(dir.file("out")));
}

TEST(Cli, RunWritesItsOutputAndSaysWhere) {
  TempDir dir;
  const std::string scene = dir.file("ok.json");
  test::write_file(scene, beam_scene(R"({ "dt": "auto" })"));
  const std::string out = dir.file("out");
  const Outcome o = run_cli(dir, "run '" + scene + "' --out '" + out + "' --duration 0.02 --precision float --quiet");
  EXPECT_EQ(o.code, 0) << o.err;
  EXPECT_NE(o.out.find("wrote " + out + "/clibeam/lin/"), std::string::npos) << o.out;
  EXPECT_NE(o.out.find("comparison.csv"), std::string::npos) << o.out;
  EXPECT_TRUE(fs::exists(out + "/clibeam/nh/series.pvd"));
  EXPECT_TRUE(fs::exists(out + "/clibeam/comparison.json"));
  const auto s = nlohmann::json::parse(test::read_file(out + "/clibeam/lin/summary.json"));
  EXPECT_EQ(s["integrator"]["precision"], "float");
  EXPECT_NEAR(s["run"]["duration_s"].get<double>(), 0.02, 1e-15);
  EXPECT_EQ(s["variant"], "lin");

  const Outcome one = run_cli(dir, "run '" + scene + "' --out '" + out + "' --variant nh --no-vtu --quiet");
  EXPECT_EQ(one.code, 0) << one.err;
  EXPECT_EQ(one.out.find("clibeam [lin]"), std::string::npos);
  EXPECT_FALSE(fs::exists(out + "/clibeam/nh/series.pvd"));  // the earlier run's frames are cleared
  EXPECT_EQ(run_cli(dir, "run '" + scene + "' --variant nope").code, 2);
}

TEST(Cli, FaultExitsOne) {
  TempDir dir;
  const std::string scene = dir.file("refuse.json");
  test::write_file(scene, beam_scene(R"({ "dt": 0.01, "unstable": "refuse" })"));
  const Outcome o = run_cli(dir, "run '" + scene + "' --out '" + dir.file("out") + "' --no-vtu --quiet");
  EXPECT_EQ(o.code, 1);
  EXPECT_NE(o.out.find("fault (step-too-large)"), std::string::npos) << o.out;
  EXPECT_NE(o.err.find("stopped by a fault"), std::string::npos) << o.err;
}

}  // namespace
}  // namespace tactile
