// Headless runs: every shipped scene runs, the files written agree with the
// state, faults stop a run and are reported, and the paper's Fig. 2 shows.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>

#include <glm/geometric.hpp>
#include <nlohmann/json.hpp>

#include "app/headless.hpp"
#include "app/simulation.hpp"
#include "app_fixtures.hpp"
#include "scene/scene.hpp"

namespace tactile {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using test::TempDir;

// A 0.4 x 0.1 x 0.1 m StVK beam clamped at x = 0 under gravity: 192 tets.
Scene make_beam(const json& amend = json::object()) {
  json j = json::parse(R"({
    "name": "beam",
    "mesh": { "primitive": "box", "lo": [0, 0, 0], "hi": [0.4, 0.1, 0.1], "cells": [8, 2, 2] },
    "material": { "model": "stvk", "E": 1e5, "nu": 0.3, "rho": 1000 },
    "boundary": [ { "name": "clamp", "select": { "box": { "lo": [0, 0, 0], "hi": [0, 0.1, 0.1] } }, "fixed": true } ],
    "effects": { "gravity": [0, -9.81, 0] },
    "run": { "duration": 0.05, "frame_rate": 100, "vtu_every": 2, "track": [ { "name": "tip", "point": [0.4, 0.05, 0.05] } ] }
  })");
  j.merge_patch(amend);
  return parse_scene(j, "beam.json").at(0);
}

HeadlessOptions quiet_options(const TempDir& dir, bool vtu) {
  HeadlessOptions o;
  o.out_dir = dir.path();
  o.write_vtu = vtu;
  o.progress = false;
  return o;
}

std::vector<std::string> csv_lines(const std::string& path) {
  std::vector<std::string> lines;
  std::istringstream in(test::read_file(path));
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

std::vector<double> csv_numbers(const std::string& line) {
  std::vector<double> out;
  std::istringstream in(line);
  for (std::string cell; std::getline(in, cell, ',');) out.push_back(std::stod(cell));
  return out;
}

TEST(Headless, EveryShippedSceneRunsAFewHundredStepsWithoutFault) {
  TempDir dir;
  int runs = 0;
  for (const auto& entry : fs::directory_iterator(TACTILE_SCENE_DIR)) {
    const std::string path = entry.path().string();
    if (entry.path().extension() != ".json" || path.ends_with(".schema.json")) continue;
    for (Scene s : load_scene(path)) {
      SCOPED_TRACE(s.name + "/" + s.variant);
      const double dt = s.spec.integrator.safety * Simulation(s.spec).dt_rest();
      s.run.duration = 300 * dt;
      s.run.frame_rate = 10 / s.run.duration;
      const HeadlessResult r = run_headless(s, quiet_options(dir, false));
      EXPECT_TRUE(r.ok()) << r.fault.message;
      EXPECT_GE(r.steps, 300);
      EXPECT_LT(r.steps, 600);
      EXPECT_EQ(r.frames, 10);
      EXPECT_NEAR(r.t, s.run.duration, 1e-12);
      EXPECT_TRUE(fs::exists(fs::path(r.dir) / "summary.json"));
      EXPECT_EQ(csv_lines((fs::path(r.dir) / "frames.csv").string()).size(), 12u);  // header, frames 0..10
      ++runs;
    }
  }
  EXPECT_GE(runs, 6);
}

TEST(Headless, VtuFilesAreXmlWithThePointsAndCellsOfTheState) {
  TempDir dir;
  const Scene scene = make_beam();
  const HeadlessResult r = run_headless(scene, quiet_options(dir, true));
  ASSERT_TRUE(r.ok()) << r.fault.message;
  EXPECT_EQ(r.dir, (fs::path(dir.path()) / "beam" / "run").string());

  // The same run, stepped here: the last frame must show this state.
  Simulation sim(scene.spec);
  for (int f = 0; f < 5; ++f) ASSERT_FALSE(sim.advance(0.01).fault);
  std::vector<double> u, v;
  sim.copy_displacement(u);
  sim.copy_velocity(v);
  const TetMesh& mesh = sim.mesh();

  const test::XmlElement pvd = test::XmlReader::parse(test::read_file(r.dir + "/series.pvd"));
  const auto& sets = pvd.child("Collection").children;
  ASSERT_EQ(sets.size(), 4u);  // frames 0, 2, 4 and the last, 5
  const int frames[] = {0, 2, 4, 5};
  for (size_t k = 0; k < sets.size(); ++k) {
    EXPECT_NEAR(std::stod(sets[k].attr("timestep")), 0.01 * frames[k], 1e-12);
    const std::string file = sets[k].attr("file");
    const test::XmlElement vtk = test::XmlReader::parse(test::read_file(r.dir + "/" + file));
    EXPECT_EQ(vtk.attr("type"), "UnstructuredGrid");
    const test::XmlElement& piece = vtk.child("UnstructuredGrid").child("Piece");
    EXPECT_EQ(std::stoi(piece.attr("NumberOfPoints")), mesh.n_nodes());
    EXPECT_EQ(std::stoi(piece.attr("NumberOfCells")), mesh.n_tets());
    const auto points = test::decode_vtk_array<double>(test::find_array(piece.child("Points"), "Points"));
    const auto disp = test::decode_vtk_array<double>(test::find_array(piece.child("PointData"), "displacement"));
    const auto conn = test::decode_vtk_array<int32_t>(test::find_array(piece.child("Cells"), "connectivity"));
    const auto offsets = test::decode_vtk_array<int32_t>(test::find_array(piece.child("Cells"), "offsets"));
    const auto types = test::decode_vtk_array<uint8_t>(test::find_array(piece.child("Cells"), "types"));
    const auto density = test::decode_vtk_array<double>(test::find_array(piece.child("CellData"), "strain_energy_density"));
    const auto material = test::decode_vtk_array<int32_t>(test::find_array(piece.child("CellData"), "material"));
    ASSERT_EQ(points.size(), 3 * size_t(mesh.n_nodes()));
    ASSERT_EQ(disp.size(), points.size());
    ASSERT_EQ(conn.size(), 4 * size_t(mesh.n_tets()));
    ASSERT_EQ(offsets.size(), size_t(mesh.n_tets()));
    EXPECT_EQ(offsets.back(), 4 * mesh.n_tets());
    EXPECT_TRUE(std::all_of(types.begin(), types.end(), [](uint8_t t) { return t == 10; }));
    EXPECT_TRUE(std::all_of(material.begin(), material.end(), [](int32_t m) { return m == 0; }));
    for (size_t e = 0; e < size_t(mesh.n_tets()); ++e)
      for (size_t c = 0; c < 4; ++c) ASSERT_EQ(conn[4 * e + c], mesh.tets[e][c]);
    for (size_t i = 0; i < size_t(mesh.n_nodes()); ++i)
      for (size_t d = 0; d < 3; ++d) ASSERT_EQ(points[3 * i + d], mesh.X[i][int(d)] + disp[3 * i + d]);
    if (frames[k] == 0) {
      EXPECT_TRUE(std::all_of(disp.begin(), disp.end(), [](double x) { return x == 0; }));
      continue;
    }
    if (frames[k] != 5) continue;
    EXPECT_EQ(disp, u);
    EXPECT_EQ(test::decode_vtk_array<double>(test::find_array(piece.child("PointData"), "velocity")), v);
    // Energy density times rest volume sums to the elastic energy.
    double elastic = 0;
    for (size_t e = 0; e < density.size(); ++e) elastic += density[e] * sim.tet_volume()[e];
    EXPECT_NEAR(elastic, sim.compute_energy().elastic, 1e-12 * std::fabs(elastic));
    EXPECT_GT(elastic, 0);
  }
}

TEST(Headless, SummaryAndFramesReportTheTrackedDisplacementOfTheState) {
  TempDir dir;
  const Scene scene = make_beam(json{{"effects", {{"damping", {{"alpha", 2.0}}}}}});
  const HeadlessResult r = run_headless(scene, quiet_options(dir, false));
  ASSERT_TRUE(r.ok());
  Simulation sim(scene.spec);
  for (int f = 0; f < 5; ++f) ASSERT_FALSE(sim.advance(0.01).fault);
  const int32_t node = scene.track.at(0).node;
  const Vec3 u = sim.displacement(node);
  EXPECT_LT(u.y, -1e-4);  // it sags

  const json s = json::parse(test::read_file(r.dir + "/summary.json"));
  EXPECT_EQ(s["status"], "ok");
  EXPECT_EQ(s["scene"], "beam");
  EXPECT_EQ(s["mesh"]["tets"], 192);
  EXPECT_EQ(s["run"]["steps"], sim.steps());
  EXPECT_EQ(s["tracked"][0]["name"], "tip");
  EXPECT_EQ(s["tracked"][0]["node"], node);
  for (int d = 0; d < 3; ++d) {
    EXPECT_EQ(s["tracked"][0]["displacement_m"][d].get<double>(), u[d]);
    EXPECT_EQ(s["tracked"][0]["rest_m"][d].get<double>(), scene.track[0].X[d]);
    EXPECT_EQ(r.tracked[0].u[d], u[d]);
  }
  EXPECT_TRUE(s["fault"].is_null());
  EXPECT_GT(s["performance"]["tet_steps_per_s"].get<double>(), 0);
  EXPECT_TRUE(s["performance"]["cost_per_pass"].contains("elastic"));
  // Energy is conserved up to what damping took and the step's O(dt^2) error, here near the stability limit.
  EXPECT_GT(s["energy"]["dissipated_J"].get<double>(), 0);
  EXPECT_LT(std::fabs(s["energy"]["balance_drift_relative"].get<double>()), 1e-2);

  const std::vector<std::string> lines = csv_lines(r.dir + "/frames.csv");
  ASSERT_EQ(lines.size(), 7u);
  EXPECT_EQ(lines[0].rfind("frame,t_s,substeps,dt_s,tip_ux_m,tip_uy_m,tip_uz_m,", 0), 0u);
  const std::vector<double> last = csv_numbers(lines.back());
  EXPECT_EQ(last[0], 5);
  EXPECT_NEAR(last[1], 0.05, 1e-12);
  for (int d = 0; d < 3; ++d) EXPECT_NEAR(last[4 + size_t(d)], u[d], 1e-8 * std::fabs(u.y));
}

TEST(Headless, FixedStepAboveTheCriticalStepIsRefusedOrSubdivided) {
  TempDir dir;
  const double dt_rest = Simulation(make_beam().spec).dt_rest();
  const double dt = 3 * dt_rest;

  const Scene refuse = make_beam(json{{"integrator", {{"dt", dt}, {"unstable", "refuse"}}}});
  const HeadlessResult r = run_headless(refuse, quiet_options(dir, true));
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.fault.kind, Fault::Kind::StepTooLarge);
  EXPECT_EQ(r.frames, 0);
  const json s = json::parse(test::read_file(r.dir + "/summary.json"));
  EXPECT_EQ(s["status"], "fault");
  EXPECT_EQ(s["fault"]["kind"], "step-too-large");
  EXPECT_NE(s["fault"]["message"].get<std::string>().find("exceeds the critical step"), std::string::npos);
  EXPECT_TRUE(fs::exists(r.dir + "/frame_000000.vtu"));
  EXPECT_EQ(csv_lines(r.dir + "/frames.csv").size(), 3u);  // header, rest, the refused frame

  const Scene subdivide = make_beam(json{{"integrator", {{"dt", dt}, {"unstable", "subdivide"}}}});
  const HeadlessResult q = run_headless(subdivide, quiet_options(dir, false));
  ASSERT_TRUE(q.ok()) << q.fault.message;
  const json t = json::parse(test::read_file(q.dir + "/summary.json"));
  EXPECT_EQ(t["integrator"]["frames_subdivided"], 5);
  EXPECT_LE(t["integrator"]["dt_s"]["max"].get<double>(), dt_rest);
  EXPECT_GT(q.steps, 5 * 0.01 / dt);
}

TEST(Headless, FaultStopsTheRunAndIsReportedWithItsElements) {
  TempDir dir;
  // The free end driven 90 % of the way to the clamp: StVK elements invert, which StVK cannot undo.
  const Scene scene = make_beam(json::parse(R"({
    "boundary": [ { "name": "clamp", "select": { "box": { "lo": [0, 0, 0], "hi": [0, 0.1, 0.1] } }, "fixed": true },
                  { "name": "crush", "select": { "box": { "lo": [0.4, 0, 0], "hi": [0.4, 0.1, 0.1] } },
                    "translate": { "direction": [-1, 0, 0], "distance": 0.36, "duration": 0.2 } } ],
    "run": { "duration": 0.4, "frame_rate": 100 } })"));
  const HeadlessResult r = run_headless(scene, quiet_options(dir, true));
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.fault.kind, Fault::Kind::Inverted) << r.fault.message;
  EXPECT_FALSE(r.fault.elements.empty());
  EXPECT_LT(r.frames, 40);
  const json s = json::parse(test::read_file(r.dir + "/summary.json"));
  EXPECT_EQ(s["status"], "fault");
  EXPECT_EQ(s["fault"]["kind"], "inverted");
  EXPECT_EQ(s["fault"]["elements"].get<std::vector<int32_t>>(), r.fault.elements);
  EXPECT_EQ(s["run"]["frames_done"], r.frames);
  // What was produced is there: the frames up to the fault, the fault's own frame last.
  EXPECT_EQ(csv_lines(r.dir + "/frames.csv").size(), size_t(r.frames) + 3);
  const test::XmlElement pvd = test::XmlReader::parse(test::read_file(r.dir + "/series.pvd"));
  EXPECT_EQ(pvd.child("Collection").children.size(), size_t(r.frames) / 2 + 2);
}

TEST(Headless, PaperFig2LinearStrainChangesTheTwistedSectionAndStvkKeepsIt) {
  TempDir dir;
  std::vector<Scene> scenes = load_scene(std::string(TACTILE_SCENE_DIR) + "/fig2_twist.json");
  ASSERT_EQ(scenes.size(), 2u);
  for (Scene& s : scenes) {
    s.run.duration = 1.0;  // the twist itself; the full scene then holds it and settles
    s.run.frame_rate = 10;
  }
  const std::vector<HeadlessResult> r = run_headless_all(scenes, quiet_options(dir, false));
  ASSERT_EQ(r.size(), 2u);
  for (const HeadlessResult& x : r) {
    ASSERT_TRUE(x.ok()) << x.variant << ": " << x.fault.message;
    ASSERT_EQ(x.sections.size(), 1u);
    EXPECT_NEAR(x.sections[0].rest_area, 0.1 * 0.1, 1e-12);
  }
  const double linear = r[0].sections[0].area / r[0].sections[0].rest_area;
  const double stvk = r[1].sections[0].area / r[1].sections[0].rest_area;
  std::printf("fig2 mid-section area after the 90 degree twist: linear %.4f, stvk %.4f of rest\n", linear, stvk);
  EXPECT_EQ(r[0].variant, "linear");
  EXPECT_GT(std::fabs(linear - 1.0), 0.25);
  EXPECT_LT(std::fabs(stvk - 1.0), 0.05);
  // The lid turned a quarter turn: its corner went from (w/2, w/2) to (-w/2, w/2) about the axis.
  for (const HeadlessResult& x : r) {
    const TrackedResult& lid = x.tracked.at(1);
    ASSERT_EQ(lid.name, "lid_corner");
    EXPECT_NEAR(glm::length(lid.X + lid.u - Vec3(0.05, 0.3, -0.05)), 0.0, 1e-9);
  }
  // The comparison lists both.
  const json c = json::parse(test::read_file(dir.path() + "/fig2_twist/comparison.json"));
  ASSERT_EQ(c["variants"].size(), 2u);
  EXPECT_EQ(c["variants"][1]["variant"], "stvk");
  EXPECT_NEAR(c["variants"][0]["sections"][0]["ratio"].get<double>(), linear, 1e-12);
  const std::vector<std::string> lines = csv_lines(dir.path() + "/fig2_twist/comparison.csv");
  ASSERT_EQ(lines.size(), 3u);
  EXPECT_NE(lines[0].find("mid_area_m2"), std::string::npos);
  EXPECT_EQ(lines[1].rfind("linear,ok,", 0), 0u);
}

}  // namespace
}  // namespace tactile
