// Shared helpers of the scene tests: a temporary folder per test, scenes
// written inline, and checks on SceneError messages.
#pragma once

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <unistd.h>

#include <nlohmann/json.hpp>

#include "scene/scene.hpp"

#include "temp_dir.hpp"

namespace tactile::test {

// The test's folder, with scenes written as JSON.
struct SceneDir : TempDir {
  std::string write_json(const std::string& name, const nlohmann::json& j) const { return write(name, j.dump(2)); }
};

// A small valid scene: a 0.4 x 0.1 x 0.1 m StVK beam clamped at x = 0.
inline nlohmann::json make_beam_scene() {
  return nlohmann::json::parse(R"({
    "name": "beam",
    "mesh": { "primitive": "box", "lo": [0, 0, 0], "hi": [0.4, 0.1, 0.1], "cells": [8, 2, 2] },
    "material": { "model": "stvk", "E": 1e5, "nu": 0.3, "rho": 1000 },
    "boundary": [ { "name": "clamp", "select": { "box": { "lo": [0, 0, 0], "hi": [0, 0.1, 0.1] } }, "fixed": true } ],
    "effects": { "gravity": [0, -9.81, 0] },
    "run": { "duration": 0.05, "frame_rate": 100, "track": [ { "name": "tip", "point": [0.4, 0.05, 0.05] } ] }
  })");
}

// Loading `j` (written as `file_name`) throws SceneError whose message contains every part.
inline void expect_scene_error(const SceneDir& dir, const std::string& file_name, const nlohmann::json& j,
                               const std::vector<std::string>& parts) {
  const std::string path = dir.write_json(file_name, j);
  try {
    load_scene(path);
    ADD_FAILURE() << "no SceneError for " << j.dump();
  } catch (const SceneError& e) {
    const std::string msg = e.what();
    EXPECT_EQ(msg.rfind(path + ": ", 0), 0u) << "message does not start with the file: " << msg;
    for (const std::string& part : parts)
      EXPECT_NE(msg.find(part), std::string::npos) << "'" << part << "' not in: " << msg;
  }
}

}  // namespace tactile::test
