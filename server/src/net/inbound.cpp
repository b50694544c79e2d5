#include "net/inbound.hpp"

#include <cmath>

namespace tactile {

Inbound read_inbound(const uint8_t* data, size_t size) {
  Inbound in;
  flatbuffers::Verifier v(data, size);
  if (!proto::VerifyEnvelopeBuffer(v)) {
    in.message = "not a tactile Envelope (" + std::to_string(size) + " bytes failed verification)";
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
  if (!std::isfinite(p.x()) || !std::isfinite(p.y()) || !std::isfinite(p.z())) return "DeviceInput with a non-finite position";
  const proto::Quatd& q = *in.orientation();
  const double n = std::sqrt(q.w() * q.w() + q.x() * q.x() + q.y() * q.y() + q.z() * q.z());
  if (!(n > 0.5 && n < 2.0)) return "DeviceInput with an orientation that is not a unit quaternion (|q| = " + std::to_string(n) + ")";
  return "";
}

}  // namespace tactile
