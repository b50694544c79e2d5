// The rules of changing the scene a live server serves, on the network
// thread: a controller's Reset, LoadScene or SetParameter, and the reset the
// server makes after a fault (ServerOptions::reset_on_fault). One change at a
// time: another asked while one is under way is answered Busy. The director
// checks each, builds and installs it (live/director.hpp), and answers once:
// the scene installed is then served, or the controller gets an Error naming
// what went wrong. A reset after a fault is due once a telemetry has named
// the fault, when no change is under way. The rules act through a Port: the
// live host (net/live_host.hpp), or a fake in server/tests/net/scene_switch_test.cpp.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "live/director.hpp"
#include "net/connection.hpp"

namespace tactile {

class SceneSwitch {
 public:
  struct Port {
    virtual ~Port() = default;
    // Director::request, with `done` called once on the network thread.
    virtual std::string request(const Director::Change& change, Director::Done done, bool* busy) = 0;
    virtual std::string fault() const = 0;  // what stopped the running scene, "" while it runs
    virtual void serve_installed(std::shared_ptr<LiveScene> scene) = 0;  // a change's scene, now running
    virtual void answer(const Bytes& error) = 0;                         // to the controller, if any
  };

  SceneSwitch(Port& port, bool reset_on_fault) : port_(port), reset_on_fault_(reset_on_fault) {}

  // What a controller's Reset, LoadScene or SetParameter asks for.
  static Director::Change change_of(const proto::Control& c);
  // A controller's change (its Control's request id answers it).
  void ask(const Director::Change& change, uint32_t request_id);
  // After each telemetry: starts a reset when a fault stopped the scene,
  // the server resets on faults, and no change is under way. True when it did.
  bool after_telemetry();

  bool changing() const { return changing_; }
  uint32_t fault_resets() const { return fault_resets_; }  // resets made after a fault

 private:
  void start(const Director::Change& change, uint32_t request_id);

  Port& port_;
  bool reset_on_fault_;
  bool changing_ = false;  // asked, not yet answered
  uint32_t fault_resets_ = 0;
};

}  // namespace tactile
