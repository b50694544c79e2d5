#include "net/scene_switch.hpp"

#include <cstdio>

namespace tactile {

Director::Change SceneSwitch::change_of(const proto::Control& c) {
  Director::Change ask;
  switch (c.command_type()) {
    case proto::ControlCommand::LoadScene:
      ask.kind = Director::Change::Kind::Load;
      if (const proto::LoadScene* l = c.command_as_LoadScene(); l && l->path()) ask.scene = l->path()->str();
      break;
    case proto::ControlCommand::SetParameter: {
      ask.kind = Director::Change::Kind::Parameter;
      if (const proto::SetParameter* p = c.command_as_SetParameter()) {
        ask.parameter = p->name() ? p->name()->str() : "";
        ask.value = p->value();
      }
      break;
    }
    default: ask.kind = Director::Change::Kind::Reset;
  }
  return ask;
}

void SceneSwitch::ask(const Director::Change& change, uint32_t request_id) {
  if (changing_)
    return port_.answer(
        make_error(proto::ErrorCode::Busy, "a scene change is under way: wait for its SceneDescription", request_id));
  start(change, request_id);
}

bool SceneSwitch::after_telemetry() {
  if (!reset_on_fault_ || changing_ || port_.fault().empty()) return false;
  ++fault_resets_;
  std::fprintf(stderr, "tactile-server: resetting the scene after the fault (--on-fault reset; %u so far)\n",
               fault_resets_);
  start(Director::Change{}, 0);
  return true;
}

void SceneSwitch::start(const Director::Change& change, uint32_t request_id) {
  bool busy = false;
  changing_ = true;
  const std::string refused = port_.request(
      change,
      [this, request_id](std::shared_ptr<LiveScene> installed, const std::string& error) {
        changing_ = false;
        if (installed) return port_.serve_installed(std::move(installed));
        port_.answer(make_error(proto::ErrorCode::BadRequest, error, request_id));
      },
      &busy);
  if (refused.empty()) return;
  changing_ = false;
  port_.answer(make_error(busy ? proto::ErrorCode::Busy : proto::ErrorCode::BadRequest, refused, request_id));
}

}  // namespace tactile
