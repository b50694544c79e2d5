// The C++ codec generated from proto/tactile.fbs: every message type encodes,
// verifies and decodes to what was put in; float arrays are read in place;
// damaged buffers are refused by the verifier, never read as data.
#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <random>
#include <vector>

#include "tactile_generated.h"

namespace tactile::proto {
namespace {

using flatbuffers::FlatBufferBuilder;

// Finishes an envelope around one message and returns its bytes.
template <class T>
std::vector<uint8_t> seal(FlatBufferBuilder& b, Message type, flatbuffers::Offset<T> body) {
  b.Finish(CreateEnvelope(b, type, body.Union()), EnvelopeIdentifier());
  return std::vector<uint8_t>(b.GetBufferPointer(), b.GetBufferPointer() + b.GetSize());
}

// Verifies the bytes and returns the envelope (null when they are not one).
const Envelope* open(const std::vector<uint8_t>& bytes) {
  flatbuffers::Verifier v(bytes.data(), bytes.size());
  if (!VerifyEnvelopeBuffer(v)) return nullptr;
  return GetEnvelope(bytes.data());
}

TEST(ProtoCodec, HelloCarriesVersionRoleTokenAndDevices) {
  FlatBufferBuilder b;
  const std::vector<flatbuffers::Offset<flatbuffers::String>> devices = {b.CreateString("left"),
                                                                         b.CreateString("right")};
  const auto hello = CreateHelloDirect(b, uint16_t(ProtocolMajor::Current), uint16_t(ProtocolMinor::Current),
                                       Role::Device, "s3cret", "bridge@lab", &devices);
  const std::vector<uint8_t> bytes = seal(b, Message::Hello, hello);
  const Envelope* e = open(bytes);
  ASSERT_NE(e, nullptr);
  ASSERT_EQ(e->message_type(), Message::Hello);
  const Hello* h = e->message_as_Hello();
  EXPECT_EQ(h->protocol_major(), 1);
  EXPECT_EQ(h->protocol_minor(), 11);
  EXPECT_EQ(h->role(), Role::Device);
  EXPECT_STREQ(h->token()->c_str(), "s3cret");
  EXPECT_STREQ(h->client_name()->c_str(), "bridge@lab");
  ASSERT_EQ(h->devices()->size(), 2u);
  EXPECT_STREQ(h->devices()->Get(1)->c_str(), "right");
}

TEST(ProtoCodec, SceneDescriptionArraysReadInPlace) {
  FlatBufferBuilder b;
  const std::vector<float> rest = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
  const std::vector<uint32_t> tris = {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3};
  const std::vector<uint32_t> nodes = {7, 8, 9, 10};
  const Vec3f half(0.01f, 0.02f, 0.03f);
  std::vector<flatbuffers::Offset<ProxyInfo>> proxies = {
      CreateProxyInfoDirect(b, "tip", "stylus", "", ProxyShape::Sphere, 0.01f, 0.0f, &half, 0.3f)};
  const std::vector<flatbuffers::Offset<flatbuffers::String>> devs = {b.CreateString("stylus")};
  const auto scene =
      CreateSceneDescriptionDirect(b, "poke", 42, 1e-4, &rest, &tris, &nodes, "displacement_m", &proxies, &devs);
  const std::vector<uint8_t> bytes = seal(b, Message::SceneDescription, scene);
  const SceneDescription* s = open(bytes)->message_as_SceneDescription();
  ASSERT_NE(s, nullptr);
  EXPECT_EQ(s->scene_id(), 42u);
  EXPECT_DOUBLE_EQ(s->dt(), 1e-4);
  ASSERT_EQ(s->rest_positions()->size(), rest.size());
  // In place: the vector's data points into the message bytes, no copy.
  const auto* data = reinterpret_cast<const uint8_t*>(s->rest_positions()->data());
  EXPECT_GE(data, bytes.data());
  EXPECT_LT(data, bytes.data() + bytes.size());
  EXPECT_EQ(std::memcmp(s->rest_positions()->data(), rest.data(), rest.size() * sizeof(float)), 0);
  EXPECT_EQ(s->triangles()->Get(4), 1u);
  EXPECT_EQ(s->surface_nodes()->Get(3), 10u);
  ASSERT_EQ(s->proxies()->size(), 1u);
  const ProxyInfo* p = s->proxies()->Get(0);
  EXPECT_EQ(p->shape(), ProxyShape::Sphere);
  EXPECT_STREQ(p->device()->c_str(), "stylus");
  EXPECT_FLOAT_EQ(p->half_extents()->z(), 0.03f);
  EXPECT_STREQ(s->devices()->Get(0)->c_str(), "stylus");
}

TEST(ProtoCodec, StateAndHapticFramesRoundTrip) {
  FlatBufferBuilder b;
  std::vector<float> positions(3 * 1000), scalar(1000);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
  for (float& x : positions) x = unit(rng);
  for (float& x : scalar) x = unit(rng);
  const std::vector<ProxyPose> poses = {ProxyPose(Vec3f(0.1f, 0.2f, 0.3f), Quatf(1, 0, 0, 0))};
  const std::vector<Vec3f> forces = {Vec3f(0.0f, 1.5f, 0.0f)};
  const auto state =
      CreateStateFrameDirect(b, 7, 123456789ull, 12.3456, 987654321012ll, &positions, &scalar, &poses, &forces);
  const std::vector<uint8_t> bytes = seal(b, Message::StateFrame, state);
  const StateFrame* s = open(bytes)->message_as_StateFrame();
  ASSERT_NE(s, nullptr);
  EXPECT_EQ(s->step(), 123456789ull);
  EXPECT_EQ(s->server_time_ns(), 987654321012ll);
  EXPECT_EQ(std::memcmp(s->positions()->data(), positions.data(), positions.size() * sizeof(float)), 0);
  EXPECT_EQ(std::memcmp(s->scalar()->data(), scalar.data(), scalar.size() * sizeof(float)), 0);
  EXPECT_FLOAT_EQ(s->proxies()->Get(0)->position().y(), 0.2f);
  EXPECT_FLOAT_EQ(s->contact_forces()->Get(0)->y(), 1.5f);
  // About 12 bytes per surface vertex and 4 per scalar: the arrays are the message.
  EXPECT_LT(bytes.size(), positions.size() * 4 + scalar.size() * 4 + 256);

  FlatBufferBuilder hb;
  const Mat3f k(-700, 0, 0, 0, -700, 0, 0, 0, -700);
  const std::vector<ProxyHaptics> ph = {
      ProxyHaptics(Vec3f(0, 2, 0), Vec3f(0, 0, 0.01f), ProxyPose(Vec3f(0, 0.05f, 0), Quatf(1, 0, 0, 0)), k, 12)};
  const std::vector<DeviceHaptics> dh = {DeviceHaptics(Vec3f(0, 2, 0), Vec3f(0, 0, 0.01f), k, 12)};
  const std::vector<ProxyPose> device_poses = {ProxyPose(Vec3f(0, 0.05f, 0), Quatf(1, 0, 0, 0))};
  const std::vector<uint64_t> sequences = {98};
  const auto haptic = CreateHapticFrameDirect(hb, 7, 99, 0.0099, 5, 98, &ph, &dh, &device_poses, &sequences);
  const std::vector<uint8_t> hbytes = seal(hb, Message::HapticFrame, haptic);
  const HapticFrame* h = open(hbytes)->message_as_HapticFrame();
  ASSERT_NE(h, nullptr);
  EXPECT_EQ(h->last_input_sequence(), 98u);
  EXPECT_FLOAT_EQ(h->proxies()->Get(0)->force().y(), 2.0f);
  EXPECT_FLOAT_EQ(h->proxies()->Get(0)->stiffness().m11(), -700.0f);
  EXPECT_EQ(h->devices()->Get(0)->contacts(), 12u);
  EXPECT_FLOAT_EQ(h->device_poses()->Get(0)->position().y(), 0.05f);
  EXPECT_EQ(h->device_input_sequences()->Get(0), 98u);

  // A 1.1 peer's frame, without the fields 1.2 added: it verifies, and they read as absent.
  FlatBufferBuilder old;
  const std::vector<uint8_t> obytes =
      seal(old, Message::HapticFrame, CreateHapticFrameDirect(old, 7, 99, 0.0099, 5, 98, &ph, &dh));
  const HapticFrame* o = open(obytes)->message_as_HapticFrame();
  ASSERT_NE(o, nullptr);
  EXPECT_EQ(o->device_poses(), nullptr);
  EXPECT_EQ(o->device_input_sequences(), nullptr);
}

TEST(ProtoCodec, DeviceStatusRoundTrips) {
  FlatBufferBuilder b;
  const std::vector<uint8_t> bytes = seal(b, Message::DeviceStatus,
                                          CreateDeviceStatusDirect(b, "stylus", 7000123456ll, 0, 1000.0f, 42.5f, 310.0f,
                                                                   3, 1.25f, 0.5f, 0.75f, "delay", 0.875f));
  const DeviceStatus* st = open(bytes)->message_as_DeviceStatus();
  ASSERT_NE(st, nullptr);
  EXPECT_STREQ(st->device()->c_str(), "stylus");
  EXPECT_EQ(st->device_time_ns(), 7000123456ll);
  EXPECT_FLOAT_EQ(st->tick_rate_hz(), 1000.0f);
  EXPECT_FLOAT_EQ(st->lateness_p99_us(), 42.5f);
  EXPECT_EQ(st->missed_ticks(), 3u);
  EXPECT_FLOAT_EQ(st->display_delay_ms(), st->state_interval_ms() + st->jitter_allowance_ms());
  EXPECT_STREQ(st->mode()->c_str(), "delay");
  // Added in 1.3, after SafetyEvent (1.2): the older numbers stay.
  EXPECT_EQ(int(Message::SafetyEvent), 12);
  EXPECT_EQ(int(Message::DeviceStatus), 13);
}

TEST(ProtoCodec, SafetyEventRoundTrips) {
  FlatBufferBuilder b;
  const std::vector<uint8_t> bytes = seal(
      b, Message::SafetyEvent,
      CreateSafetyEventDirect(b, "stylus", 5000250123ll, 0, SafetyKind::Stale, "no state for 12 ms: fading", 1.25f));
  const SafetyEvent* ev = open(bytes)->message_as_SafetyEvent();
  ASSERT_NE(ev, nullptr);
  EXPECT_STREQ(ev->device()->c_str(), "stylus");
  EXPECT_EQ(ev->device_time_ns(), 5000250123ll);
  EXPECT_EQ(ev->server_time_ns(), 0);
  EXPECT_EQ(ev->kind(), SafetyKind::Stale);
  EXPECT_STREQ(ev->message()->c_str(), "no state for 12 ms: fading");
  EXPECT_FLOAT_EQ(ev->force_N(), 1.25f);
  // The kinds the bridge's safety layer numbers the same way (device-bridge: safety.Kind).
  EXPECT_EQ(int(SafetyKind::Engaged), 0);
  EXPECT_EQ(int(SafetyKind::Passivity), 10);
  EXPECT_EQ(int(SafetyKind::Other), 11);
  EXPECT_EQ(SafetyKind::MAX, SafetyKind::Other);
  // New message types go last: the 1.1 numbers stay.
  EXPECT_EQ(int(Message::Error), 11);
  EXPECT_EQ(int(Message::SafetyEvent), 12);
}

TEST(ProtoCodec, InputControlTelemetrySyncAndError) {
  {
    FlatBufferBuilder b;
    const Vec3d p(0.01, 0.02, -0.03);
    const Quatd q(0.7071067811865476, 0.0, 0.7071067811865476, 0.0);
    const std::vector<uint8_t> bytes =
        seal(b, Message::DeviceInput, CreateDeviceInputDirect(b, "stylus", 17, 1000000, &p, &q, 0b101));
    const DeviceInput* in = open(bytes)->message_as_DeviceInput();
    ASSERT_NE(in, nullptr);
    EXPECT_EQ(in->sequence(), 17u);
    EXPECT_DOUBLE_EQ(in->position()->z(), -0.03);
    EXPECT_DOUBLE_EQ(in->orientation()->y(), 0.7071067811865476);
    EXPECT_EQ(in->buttons(), 5u);
  }
  {
    FlatBufferBuilder b;
    const auto set = CreateSetParameterDirect(b, "damping.alpha", 2.5);
    const std::vector<uint8_t> bytes =
        seal(b, Message::Control, CreateControl(b, 3, ControlCommand::SetParameter, set.Union()));
    const Control* c = open(bytes)->message_as_Control();
    ASSERT_NE(c, nullptr);
    EXPECT_EQ(c->request_id(), 3u);
    ASSERT_EQ(c->command_type(), ControlCommand::SetParameter);
    EXPECT_STREQ(c->command_as_SetParameter()->name()->c_str(), "damping.alpha");
    EXPECT_DOUBLE_EQ(c->command_as_SetParameter()->value(), 2.5);
  }
  {
    FlatBufferBuilder b;
    std::vector<flatbuffers::Offset<EffectCost>> costs = {CreateEffectCostDirect(b, "elastic", 52000.0f),
                                                          CreateEffectCostDirect(b, "contact", 4100.0f)};
    std::vector<flatbuffers::Offset<flatbuffers::String>> faults = {b.CreateString("none")};
    const auto t = CreateTelemetryDirect(b, 5, 6, 0.5, 60.0f, 80.0f, 0.98f, 2, &costs, 3, 1, 0, &faults, false);
    const Telemetry* tm = open(seal(b, Message::Telemetry, t))->message_as_Telemetry();
    ASSERT_NE(tm, nullptr);
    EXPECT_FLOAT_EQ(tm->real_time_factor(), 0.98f);
    EXPECT_STREQ(tm->effect_costs()->Get(1)->name()->c_str(), "contact");
    EXPECT_EQ(tm->viewers(), 3u);
  }
  {
    FlatBufferBuilder b;
    const Pong* pong = open(seal(b, Message::Pong, CreatePong(b, 9, 100, 150, 160)))->message_as_Pong();
    ASSERT_NE(pong, nullptr);
    EXPECT_EQ(pong->server_send_ns() - pong->server_receive_ns(), 10);
  }
  {
    FlatBufferBuilder b;
    const Error* err =
        open(seal(b, Message::Error, CreateErrorDirect(b, ErrorCode::VersionMismatch, "protocol 2.0, server 1.0", 0)))
            ->message_as_Error();
    ASSERT_NE(err, nullptr);
    EXPECT_EQ(err->code(), ErrorCode::VersionMismatch);
    EXPECT_STREQ(EnumNameErrorCode(err->code()), "VersionMismatch");
  }
}

// Damaged bytes: the verifier refuses truncation, another file identifier,
// and offsets pointing outside the buffer, so a receiver answers Malformed
// instead of reading garbage.
TEST(ProtoCodec, DamagedBuffersAreRefused) {
  FlatBufferBuilder b;
  std::vector<float> positions(300, 0.5f);
  const auto state = CreateStateFrameDirect(b, 1, 2, 3.0, 4, &positions, nullptr, nullptr, nullptr);
  const std::vector<uint8_t> good = seal(b, Message::StateFrame, state);
  ASSERT_NE(open(good), nullptr);

  std::vector<uint8_t> truncated(good.begin(), good.begin() + long(good.size() / 2));
  EXPECT_EQ(open(truncated), nullptr);

  std::vector<uint8_t> wrong_id = good;
  std::memcpy(wrong_id.data() + 4, "XXXX", 4);  // the identifier follows the root offset
  EXPECT_EQ(open(wrong_id), nullptr);

  std::vector<uint8_t> bad_root = good;
  const uint32_t far = uint32_t(good.size() * 4);
  std::memcpy(bad_root.data(), &far, 4);
  EXPECT_EQ(open(bad_root), nullptr);

  // Random corruption of the body never crashes the verifier; what it accepts decodes.
  std::mt19937 rng(11);
  int refused = 0;
  for (int k = 0; k < 2000; ++k) {
    std::vector<uint8_t> bytes = good;
    for (int flips = 0; flips < 4; ++flips) bytes[rng() % bytes.size()] ^= uint8_t(1u << (rng() % 8));
    const Envelope* e = open(bytes);
    if (!e) {
      ++refused;
      continue;
    }
    if (const StateFrame* s = e->message_as_StateFrame(); s && s->positions()) {
      volatile float sum = 0;
      for (float x : *s->positions()) sum = sum + x;
    }
  }
  EXPECT_GT(refused, 0);
}

}  // namespace
}  // namespace tactile::proto
