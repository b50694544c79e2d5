// Re-simulation: the device inputs of a recording fed to the simulator
// again, each before the same step of the loop as live (the recording's
// /applied), unpaced. With the recording's own scene and this build, every
// state and haptic frame comes out bit for bit as recorded; with another
// scene (material, mesh) the two runs can be compared side by side
// (`tactile-recording compare`), the re-simulation written as a recording
// of its own.
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>

namespace tactile {

struct ResimError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct ResimOptions {
  std::string recording;   // MCAP, recorded from its scene's start (tactile-server --record)
  std::string scene;       // another scene file to run the inputs on ("": the recorded one)
  std::string scene_text;  // that scene's JSON as given here (a sweep's overrides applied) instead of the
                           // file's; `scene` still names it and anchors its relative mesh paths
  std::string variant;     // of that scene ("": the recorded variant, or the first)
  std::string out;         // the re-simulation as a recording ("" for none)
};

struct ResimReport {
  std::string scene_name;
  int64_t steps = 0;                       // loop steps taken
  int64_t inputs = 0;                      // inputs applied
  int64_t states = 0, states_matched = 0;  // re-simulated states; those with a recorded one at the same time
  int64_t states_identical = 0;            // of those, equal field by field (server times aside)
  int64_t haptic = 0, haptic_matched = 0, haptic_identical = 0;
  double max_position_difference = 0;  // over matched states [m]
  double max_force_difference = 0;     // over matched haptic frames, any proxy [N]
  double first_difference_time = -1;   // simulated time of the first state that differs [s], -1 if none
  double peak_force = 0;               // largest proxy force of the re-simulation's haptic frames [N]
  double recorded_peak_force = 0;      // the same over the recording's haptic frames [N]
  std::string note;                    // what was left out (later scenes of the recording...)
};

// Throws ResimError (or mcap::McapError, SceneError, ModelError) naming
// what is wrong: not a recording, no scene in it, recorded from the middle
// of a session, an input the recording lacks...
ResimReport resimulate(const ResimOptions& options);

}  // namespace tactile
