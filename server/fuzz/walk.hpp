// What the server does with a client's bytes, minus the sockets: check them
// (net/inbound.hpp), then read every field a handler could read. Shared by
// the libFuzzer target and the corpus replay in the test suite. Returns a
// checksum of what it read, so that nothing is optimised away.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string_view>

#include "net/inbound.hpp"
#include "scene/parameters.hpp"
#include "scene/scene.hpp"

namespace tactile::fuzz {

inline uint64_t read_string(const flatbuffers::String* s) {
  if (!s) return 0;
  uint64_t h = s->size();
  for (char c : s->string_view()) h = h * 31 + uint8_t(c);
  return h;
}

// A SetParameter as the server applies it: to a scene's spec (here two
// materials and a proxy), set or refused with a message.
inline uint64_t apply_parameter_to_a_spec(const proto::SetParameter& c) {
  ModelSpec spec;
  spec.materials.resize(2);
  spec.proxies.resize(1);
  try {
    apply_parameter(spec, c.name() ? c.name()->str() : "", c.value());
    return 1;
  } catch (const SceneError& e) {
    return std::string_view(e.what()).size();
  }
}

inline uint64_t walk_inbound(const uint8_t* data, size_t size) {
  const Inbound in = read_inbound(data, size);
  if (!in) return in.message.size();
  const proto::Envelope& e = *in.envelope;
  uint64_t h = uint64_t(e.message_type());
  switch (e.message_type()) {
    case proto::Message::Hello: {
      const proto::Hello* m = e.message_as_Hello();
      h += m->protocol_major() + uint64_t(m->role()) + read_string(m->token()) + read_string(m->client_name());
      if (m->devices())
        for (const flatbuffers::String* d : *m->devices()) h += read_string(d);
      break;
    }
    case proto::Message::DeviceInput: {
      const proto::DeviceInput* m = e.message_as_DeviceInput();
      h += read_string(m->device()) + m->sequence() + check_device_input(*m).size();
      break;
    }
    case proto::Message::Control: {
      const proto::Control* m = e.message_as_Control();
      h += m->request_id() + uint64_t(m->command_type());
      if (const proto::LoadScene* c = m->command_as_LoadScene()) h += read_string(c->path());
      if (const proto::SetParameter* c = m->command_as_SetParameter())
        h += read_string(c->name()) + apply_parameter_to_a_spec(*c);
      if (const proto::StartRecording* c = m->command_as_StartRecording()) h += read_string(c->path());
      break;
    }
    case proto::Message::SafetyEvent: {
      const proto::SafetyEvent* m = e.message_as_SafetyEvent();
      h += read_string(m->device()) + read_string(m->message()) + uint64_t(m->kind()) + uint64_t(m->device_time_ns()) +
           check_safety_event(*m).size();
      break;
    }
    case proto::Message::Ping: h += e.message_as_Ping()->id(); break;
    case proto::Message::StateFrame: {  // (servers send these; read them anyway: bytes are bytes)
      const proto::StateFrame* m = e.message_as_StateFrame();
      if (m->positions())
        for (float x : *m->positions()) h += uint64_t(x != x);
      if (m->proxies())
        for (const proto::ProxyPose* p : *m->proxies()) h += uint64_t(p->position().x() != 0);
      break;
    }
    default: break;
  }
  return h;
}

}  // namespace tactile::fuzz
