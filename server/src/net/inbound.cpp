#include "net/inbound.hpp"

#include <cmath>
#include <utility>

#include <flatbuffers/util.h>

namespace tactile {

Inbound read_inbound(const uint8_t* data, size_t size) {
  Inbound in;
  flatbuffers::Verifier v(data, size);
  if (!proto::VerifyEnvelopeBuffer(v)) {
    // A client that builds Envelopes from the schema but finishes the buffer
    // without the file identifier (flatbuffers' Finish, not FinishEnvelope-
    // Buffer) is the common case in a new language: name what is missing.
    flatbuffers::Verifier again(data, size);
    const bool no_identifier = again.VerifyBuffer<proto::Envelope>(nullptr) &&
                               !flatbuffers::BufferHasIdentifier(data, proto::EnvelopeIdentifier());
    in.message = no_identifier
                     ? std::string("an Envelope without the file identifier \"") + proto::EnvelopeIdentifier() +
                           "\" at bytes 4-7: finish the buffer with it (FinishEnvelopeBuffer in C++, "
                           "finishEnvelopeBuffer in JavaScript, FinishWithFileIdentifier in Go; proto/README.md)"
                     : "not a tactile Envelope (" + std::to_string(size) + " bytes failed verification)";
    return in;
  }
  const proto::Envelope* e = proto::GetEnvelope(data);
  if (e->message_type() == proto::Message::NONE || !e->message()) {
    in.message = "an Envelope with no message";
    return in;
  }
  in.envelope = e;
  return in;
}

std::string check_device_input(const proto::DeviceInput& in) {
  if (!in.position() || !in.orientation()) return "DeviceInput without position or orientation";
  const proto::Vec3d& p = *in.position();
  if (!std::isfinite(p.x()) || !std::isfinite(p.y()) || !std::isfinite(p.z()))
    return "DeviceInput with a non-finite position";
  const proto::Quatd& q = *in.orientation();
  const double n = std::sqrt(q.w() * q.w() + q.x() * q.x() + q.y() * q.y() + q.z() * q.z());
  if (!(n > 0.5 && n < 2.0))
    return "DeviceInput with an orientation that is not a unit quaternion (|q| = " + std::to_string(n) + ")";
  return "";
}

std::string check_device_limits(const proto::Hello& h) {
  if (!h.device_limits()) return "";
  const uint32_t devices = h.devices() ? h.devices()->size() : 0;
  if (h.device_limits()->size() > devices)
    return "Hello.device_limits has " + std::to_string(h.device_limits()->size()) + " entries for " +
           std::to_string(devices) + " device channel(s)";
  for (uint32_t i = 0; i < h.device_limits()->size(); ++i) {
    const proto::DeviceLimits* l = h.device_limits()->Get(i);
    if (!l) return "Hello.device_limits[" + std::to_string(i) + "] is missing";
    const std::pair<const char*, float> fields[] = {{"max_force_N", l->max_force_N()},
                                                    {"max_torque_Nm", l->max_torque_Nm()},
                                                    {"stiffness_N_per_m", l->stiffness_N_per_m()}};
    for (const auto& [name, value] : fields)
      if (!std::isfinite(value) || value < 0)
        return "Hello.device_limits[" + std::to_string(i) + "]." + name + " must be a finite number >= 0, got " +
               std::to_string(value);
  }
  return "";
}

namespace {

bool is_utf8(const flatbuffers::String& s) {
  const char* p = s.c_str();
  const char* end = p + s.size();
  // (A sequence cut short at the end meets the string's 0, which ends it as invalid.)
  while (p < end)
    if (flatbuffers::FromUTF8(&p) < 0) return false;
  return p == end;
}

}  // namespace

std::string check_safety_event(const proto::SafetyEvent& ev) {
  if (!ev.device() || ev.device()->size() == 0) return "SafetyEvent without a device channel";
  if (ev.device()->size() > kMaxSafetyDeviceBytes)
    return "SafetyEvent with a device channel of " + std::to_string(ev.device()->size()) + " bytes (at most " +
           std::to_string(kMaxSafetyDeviceBytes) + ")";
  if (!is_utf8(*ev.device())) return "SafetyEvent with a device channel that is not UTF-8";
  if (ev.message() && ev.message()->size() > kMaxSafetyMessageBytes)
    return "SafetyEvent with a message of " + std::to_string(ev.message()->size()) + " bytes (at most " +
           std::to_string(kMaxSafetyMessageBytes) + ")";
  if (ev.message() && !is_utf8(*ev.message())) return "SafetyEvent with a message that is not UTF-8";
  if (ev.kind() > proto::SafetyKind::MAX)
    return "SafetyEvent of unknown kind " + std::to_string(int(ev.kind())) + " (this server knows 0 to " +
           std::to_string(int(proto::SafetyKind::MAX)) + ")";
  if (!std::isfinite(ev.force_N()) || ev.force_N() < 0)
    return "SafetyEvent with force_N = " + std::to_string(ev.force_N()) +
           ": a force magnitude is finite and >= 0 (send the last finite one)";
  return "";
}

std::string check_device_status(const proto::DeviceStatus& st) {
  if (!st.device() || st.device()->size() == 0) return "DeviceStatus without a device channel";
  if (st.device()->size() > kMaxSafetyDeviceBytes || !is_utf8(*st.device()))
    return "DeviceStatus with a device channel that is not UTF-8 of at most " + std::to_string(kMaxSafetyDeviceBytes) +
           " bytes";
  const std::string mode = st.mode() ? st.mode()->str() : "";
  if (mode != "model" && mode != "coupled" && mode != "delay" && mode != "hold" && mode != "extrapolate")
    return "DeviceStatus with mode '" +
           (st.mode() && is_utf8(*st.mode()) && mode.size() <= 32 ? mode : std::string("?")) +
           "' (model, coupled, delay, hold or extrapolate)";
  const std::pair<const char*, float> figures[] = {{"tick_rate_hz", st.tick_rate_hz()},
                                                   {"lateness_p99_us", st.lateness_p99_us()},
                                                   {"lateness_max_us", st.lateness_max_us()},
                                                   {"display_delay_ms", st.display_delay_ms()},
                                                   {"state_interval_ms", st.state_interval_ms()},
                                                   {"jitter_allowance_ms", st.jitter_allowance_ms()},
                                                   {"force_N", st.force_N()}};
  for (const auto& [name, value] : figures)
    if (!std::isfinite(value) || value < 0)
      return std::string("DeviceStatus with ") + name + " = " + std::to_string(value) + ": finite and >= 0";
  return "";
}

std::string utf8_text(std::string_view in) {
  // flatbuffers::FromUTF8 reads one sequence up to a NUL, refusing overlong
  // forms, surrogates and code points past U+10FFFF; a sequence cut short at
  // the end of the copy meets its terminating NUL.
  const std::string text(in);
  std::string out;
  out.reserve(text.size());
  const char* p = text.c_str();
  const char* const end = p + text.size();
  while (p < end) {
    const uint8_t c = uint8_t(*p);
    const char* next = p;
    const bool control = (c < 0x20 && c != '\n' && c != '\t') || c == 0x7f;
    if (!control && flatbuffers::FromUTF8(&next) >= 0 && next <= end) {
      out.append(p, next);
      p = next;
      continue;
    }
    static const char* hex = "0123456789abcdef";
    out += "\\x";
    out += hex[c >> 4];
    out += hex[c & 15];
    ++p;
  }
  return out;
}

}  // namespace tactile
