// Headless runs: every shipped scene runs, the files written agree with the
// state, faults stop a run and are reported, and the paper's Fig. 2 shows.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <sstream>

#include <glm/geometric.hpp>
#include <nlohmann/json.hpp>

#include "app/headless.hpp"
#include "app_fixtures.hpp"
#include "scene/scene.hpp"
#include "sim/simulation.hpp"

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
  // The frames number the nodes as the scene's mesh does, as the Simulation does.
  const TetMesh& mesh = scene.spec.mesh;
  std::vector<double> u, v;
  sim.copy_displacement(u);
  sim.copy_velocity(v);

  const pugi::xml_document pvd = test::read_xml(r.dir + "/series.pvd");
  const std::vector<pugi::xml_node> sets = test::elements(pvd.child("VTKFile").child("Collection"));
  ASSERT_EQ(sets.size(), 4u);  // frames 0, 2, 4 and the last, 5
  const int frames[] = {0, 2, 4, 5};
  for (size_t k = 0; k < sets.size(); ++k) {
    EXPECT_NEAR(std::stod(sets[k].attribute("timestep").value()), 0.01 * frames[k], 1e-12);
    const std::string file = sets[k].attribute("file").value();
    const pugi::xml_document doc = test::read_xml(r.dir + "/" + file);
    const pugi::xml_node vtk = doc.child("VTKFile");
    EXPECT_STREQ(vtk.attribute("type").value(), "UnstructuredGrid");
    const pugi::xml_node piece = vtk.child("UnstructuredGrid").child("Piece");
    ASSERT_TRUE(piece) << file;
    EXPECT_EQ(std::stoi(piece.attribute("NumberOfPoints").value()), mesh.n_nodes());
    EXPECT_EQ(std::stoi(piece.attribute("NumberOfCells").value()), mesh.n_tets());
    const auto points = test::decode_vtk_array<double>(test::find_array(piece.child("Points"), "Points"));
    const auto disp = test::decode_vtk_array<double>(test::find_array(piece.child("PointData"), "displacement"));
    const auto conn = test::decode_vtk_array<int32_t>(test::find_array(piece.child("Cells"), "connectivity"));
    const auto offsets = test::decode_vtk_array<int32_t>(test::find_array(piece.child("Cells"), "offsets"));
    const auto types = test::decode_vtk_array<uint8_t>(test::find_array(piece.child("Cells"), "types"));
    const auto density =
        test::decode_vtk_array<double>(test::find_array(piece.child("CellData"), "strain_energy_density"));
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
    // Points at rest: ParaView's Warp By Vector by the displacement gives the body once deformed, not twice.
    for (size_t i = 0; i < size_t(mesh.n_nodes()); ++i)
      for (size_t d = 0; d < 3; ++d) ASSERT_EQ(points[3 * i + d], mesh.X[i][int(d)]);
    // The clamp's nodes (x = 0) are marked held in place, every other node free.
    const auto fixed = test::decode_vtk_array<uint8_t>(test::find_array(piece.child("PointData"), "fixed"));
    ASSERT_EQ(fixed.size(), size_t(mesh.n_nodes()));
    for (size_t i = 0; i < size_t(mesh.n_nodes()); ++i) ASSERT_EQ(fixed[i], mesh.X[i].x == 0.0 ? 1 : 0) << i;
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
  const int32_t node = scene.track.at(0).node;  // as the scene's mesh numbers it
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
  EXPECT_TRUE(s["proxies"].empty());
  EXPECT_FALSE(fs::exists(r.dir + "/forces.csv"));  // no proxies, no force traces
  EXPECT_FALSE(fs::exists(r.dir + "/devices.csv"));
  EXPECT_GT(s["performance"]["tet_steps_per_s"].get<double>(), 0);
  EXPECT_TRUE(s["performance"]["cost_per_pass"].contains("elastic"));
  // Energy is conserved up to what damping took and the step's O(dt^2) error, here near the stability limit.
  EXPECT_GT(s["energy"]["dissipated_J"].get<double>(), 0);
  EXPECT_LT(std::fabs(s["energy"]["balance_drift_relative"].get<double>()), 1e-2);

  const std::vector<std::string> lines = csv_lines(r.dir + "/frames.csv");
  ASSERT_EQ(lines.size(), 7u);
  EXPECT_EQ(lines[0].rfind("frame,sim_time_s,substeps,dt_s,tip_ux_m,tip_uy_m,tip_uz_m,", 0), 0u);
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
  const pugi::xml_document pvd = test::read_xml(r.dir + "/series.pvd");
  EXPECT_EQ(test::elements(pvd.child("VTKFile").child("Collection")).size(), size_t(r.frames) / 2 + 2);
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

// ---- proxies ----------------------------------------------------------------

// One row of forces.csv or devices.csv: the names, and the numbers in order.
struct TraceRow {
  std::string proxy, device;
  std::vector<double> x;  // sim_time_s, then the columns after the names
};

std::vector<TraceRow> read_trace(const std::string& path, int names) {
  const std::vector<std::string> lines = csv_lines(path);
  std::vector<TraceRow> rows;
  for (size_t i = 1; i < lines.size(); ++i) {
    std::istringstream in(lines[i]);
    std::vector<std::string> cells;
    for (std::string cell; std::getline(in, cell, ',');) cells.push_back(cell);
    TraceRow r;
    r.x.push_back(std::stod(cells.at(0)));
    if (names == 2) {
      r.proxy = cells.at(1);
      r.device = cells.at(2);
    } else {
      r.device = cells.at(1);
    }
    for (size_t k = 1 + size_t(names); k < cells.size(); ++k) r.x.push_back(std::stod(cells[k]));
    rows.push_back(r);
  }
  return rows;
}

constexpr const char* kForcesHeader =
    "sim_time_s,proxy,device,fx_N,fy_N,fz_N,tx_Nm,ty_Nm,tz_Nm,contacts,px_m,py_m,pz_m";
constexpr const char* kDevicesHeader = "sim_time_s,device,fx_N,fy_N,fz_N,tx_Nm,ty_Nm,tz_Nm,contacts";

TEST(HeadlessProxies, PokeForcePushesTheSphereOutOfTheBlockAndIsZeroBeforeContact) {
  TempDir dir;
  Scene scene = load_scene(std::string(TACTILE_SCENE_DIR) + "/poke.json").at(0);
  scene.run.duration = 0.6;  // the approach and the press, 8 mm deep at the end
  const HeadlessResult r = run_headless(scene, quiet_options(dir, false));
  ASSERT_TRUE(r.ok()) << r.fault.message;
  const ProxySpec& tip = scene.spec.proxies.at(0);
  const PoseScript& script = scene.proxy_script.at(0).value();
  const double top = compute_aabb(scene.spec.mesh.X).hi.y;
  const double R = tip.geometry.radius;

  ASSERT_EQ(csv_lines(r.dir + "/forces.csv").at(0), kForcesHeader);
  ASSERT_EQ(csv_lines(r.dir + "/devices.csv").at(0), kDevicesHeader);
  const std::vector<TraceRow> rows = read_trace(r.dir + "/forces.csv", 2);
  const std::vector<TraceRow> dev = read_trace(r.dir + "/devices.csv", 1);
  ASSERT_EQ(rows.size(), 600u);  // 1 ms intervals, one proxy
  ASSERT_EQ(dev.size(), rows.size());
  int before = 0, pressed = 0;
  double deepest = 0, force_deepest = 0;
  for (size_t i = 0; i < rows.size(); ++i) {
    const TraceRow& row = rows[i];
    const double t = row.x[0], fx = row.x[1], fy = row.x[2], fz = row.x[3];
    ASSERT_NEAR(t, 0.001 * double(i + 1), 1e-9);
    EXPECT_EQ(row.proxy, "tip");
    EXPECT_EQ(row.device, "stylus");
    // The proxy is where its script puts it at the interval's end.
    const Vec3 p(row.x[8], row.x[9], row.x[10]);
    EXPECT_LT(glm::length(p - script.at(t).position), 1e-9) << t;
    // Its device feels exactly its force (it is the device's only proxy).
    for (size_t k = 0; k < 7; ++k) EXPECT_EQ(dev[i].x[k], row.x[k]);
    const double depth = top - (p.y - R);
    if (depth < -1e-3) {  // more than a millimetre above the block
      EXPECT_EQ(fx, 0.0);
      EXPECT_EQ(fy, 0.0);
      EXPECT_EQ(fz, 0.0);
      EXPECT_EQ(row.x[7], 0.0);  // contacts
      ++before;
    } else if (depth > 3e-3) {  // pressed in: pushed back up, out of the body
      EXPECT_GT(fy, 0.0) << t;
      EXPECT_LT(std::hypot(fx, fz), 0.05 * fy) << t;
      ++pressed;
      if (depth > deepest) deepest = depth, force_deepest = fy;
    }
  }
  EXPECT_GT(before, 100);
  EXPECT_GT(pressed, 100);
  // Hertz's sphere on a half-space, F = 4/3 E/(1 - nu^2) sqrt(R) d^1.5: the block is
  // finite and fixed below, so somewhat stiffer, but of that order.
  const MaterialSpec& m = scene.spec.materials[0];
  const double hertz = 4.0 / 3.0 * m.E / (1 - m.nu * m.nu) * std::sqrt(R) * std::pow(deepest, 1.5);
  std::printf("poke: %.2f mm deep, force %.3f N, Hertz %.3f N\n", 1e3 * deepest, force_deepest, hertz);
  EXPECT_GT(deepest, 7.5e-3);
  EXPECT_GT(force_deepest, 0.7 * hertz);
  EXPECT_LT(force_deepest, 2.0 * hertz);

  // The result and summary.json give the last interval's means.
  ASSERT_EQ(r.proxies.size(), 1u);
  ASSERT_EQ(r.devices.size(), 1u);
  EXPECT_NEAR(r.proxies[0].force.y, rows.back().x[2], 1e-8 * rows.back().x[2]);  // the file has 9 digits
  EXPECT_GE(r.proxies[0].peak_force, r.proxies[0].force.y);
  const json s = json::parse(test::read_file(r.dir + "/summary.json"));
  ASSERT_EQ(s["proxies"].size(), 1u);
  EXPECT_EQ(s["proxies"][0]["name"], "tip");
  EXPECT_EQ(s["proxies"][0]["device"], "stylus");
  EXPECT_EQ(s["proxies"][0]["shape"], "sphere");
  EXPECT_EQ(s["proxies"][0]["scripted"], true);
  EXPECT_EQ(s["proxies"][0]["force_N"][1].get<double>(), r.proxies[0].force.y);
  EXPECT_EQ(s["proxies"][0]["position_m"][1].get<double>(), r.proxies[0].position.y);
  EXPECT_NEAR(r.proxies[0].position.y, script.at(0.6).position.y, 1e-12);
  EXPECT_EQ(s["devices"][0]["name"], "stylus");
  EXPECT_EQ(s["devices"][0]["force_N"][1].get<double>(), r.devices[0].force.y);
  EXPECT_NEAR(s["run"]["control_interval_s"].get<double>(), 1e-3, 1e-15);
}

// A soft block, a hand of two spheres pressed into it by one device, and a
// sphere on another device that nothing moves, away from the block.
Scene make_hand_scene(double frame_rate) {
  json j = json::parse(R"({
    "name": "hand",
    "mesh": { "primitive": "box", "lo": [-0.05, 0, -0.05], "hi": [0.05, 0.04, 0.05], "cells": [10, 4, 10] },
    "material": { "model": "neohookean", "E": 3e4, "nu": 0.3, "rho": 1000 },
    "boundary": [ { "select": { "plane": { "point": [0, 0, 0], "normal": [0, 1, 0] } }, "fixed": true } ],
    "hands": [ { "name": "h", "device": "glove", "position": [0, 0.06, 0],
                 "script": { "keyframes": [ { "t": 0, "position": [0, 0.06, 0] }, { "t": 0.2, "position": [0, 0.047, 0] } ] } } ],
    "proxies": [
      { "name": "a", "hand": "h", "shape": "sphere", "radius": 0.015, "position": [-0.025, 0.057, 0] },
      { "name": "b", "hand": "h", "shape": "capsule", "radius": 0.012, "half_length": 0.01, "position": [0.025, 0.054, 0] },
      { "name": "idle", "device": "other", "shape": "sphere", "radius": 0.01, "position": [0, 0.2, 0] }
    ],
    "effects": { "damping": { "alpha": 5 } },
    "run": { "duration": 0.25, "frame_rate": 30 }
  })");
  j["run"]["frame_rate"] = frame_rate;
  return parse_scene(j, "hand.json").at(0);
}

TEST(HeadlessProxies, AHandsDeviceFeelsTheSumOfItsProxiesAndAnUnscriptedProxyHolds) {
  TempDir dir;
  const Scene scene = make_hand_scene(30);
  const HeadlessResult r = run_headless(scene, quiet_options(dir, false));
  ASSERT_TRUE(r.ok()) << r.fault.message;
  const std::vector<TraceRow> rows = read_trace(r.dir + "/forces.csv", 2);
  const std::vector<TraceRow> dev = read_trace(r.dir + "/devices.csv", 1);
  ASSERT_EQ(rows.size() % 3, 0u);
  ASSERT_EQ(dev.size(), 2 * rows.size() / 3);
  int both_pressing = 0;
  for (size_t i = 0; i < rows.size() / 3; ++i) {
    const TraceRow &a = rows[3 * i], &b = rows[3 * i + 1], &idle = rows[3 * i + 2];
    const TraceRow &glove = dev[2 * i], &other = dev[2 * i + 1];
    ASSERT_EQ(a.proxy, "a");
    ASSERT_EQ(b.proxy, "b");
    ASSERT_EQ(idle.proxy, "idle");
    EXPECT_EQ(a.device, "glove");  // a hand's proxies go to its device
    EXPECT_EQ(b.device, "glove");
    ASSERT_EQ(glove.device, "glove");
    ASSERT_EQ(other.device, "other");
    // The hand's device: the sum of its proxies' forces and contacts (up to the files' 9 digits).
    for (size_t k = 1; k <= 3; ++k)
      EXPECT_NEAR(glove.x[k], a.x[k] + b.x[k],
                  1e-8 * (std::fabs(a.x[k]) + std::fabs(b.x[k]) + std::fabs(glove.x[k])) + 1e-15);
    EXPECT_EQ(glove.x[7], a.x[7] + b.x[7]);
    // The other device feels nothing, and its proxy stays where it was put.
    for (size_t k = 1; k <= 7; ++k) EXPECT_EQ(other.x[k], 0.0);
    EXPECT_EQ(Vec3(idle.x[8], idle.x[9], idle.x[10]), Vec3(0, 0.2, 0));
    // The hand's proxies keep their offsets from it.
    EXPECT_NEAR(a.x[8] - b.x[8], -0.05, 1e-12);
    EXPECT_NEAR(a.x[9] - b.x[9], 0.003, 1e-12);
    if (a.x[2] > 0 && b.x[2] > 0) ++both_pressing;
  }
  EXPECT_GT(both_pressing, 20);
  EXPECT_GT(r.devices.at(0).force.y, 0.1);  // still pressed at the end
}

TEST(HeadlessProxies, ControlIntervalsAreAtMostAMillisecondAndFillEachFrame) {
  struct Case {
    double frame_rate, duration;
    int intervals;    // in the run
    double interval;  // [s]
  };
  // 30 Hz: frames of 33.3 ms, 34 intervals each; 4 kHz: the 0.25 ms frame is the interval.
  for (const Case c : {Case{30, 0.1, 3 * 34, 0.1 / 102}, Case{4000, 0.01, 40, 0.25e-3}}) {
    SCOPED_TRACE(c.frame_rate);
    TempDir dir;
    Scene scene = make_hand_scene(c.frame_rate);
    scene.run.duration = c.duration;
    const HeadlessResult r = run_headless(scene, quiet_options(dir, false));
    ASSERT_TRUE(r.ok()) << r.fault.message;
    const std::vector<TraceRow> rows = read_trace(r.dir + "/forces.csv", 2);
    ASSERT_EQ(rows.size(), 3 * size_t(c.intervals));
    for (size_t i = 0; i < rows.size(); i += 3) EXPECT_NEAR(rows[i].x[0], c.interval * double(i / 3 + 1), 1e-9);
    const json s = json::parse(test::read_file(r.dir + "/summary.json"));
    EXPECT_NEAR(s["run"]["control_interval_s"].get<double>(), c.interval, 1e-15);
  }
}

}  // namespace
}  // namespace tactile
