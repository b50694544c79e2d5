// The rules of one client connection (net/connection.hpp), without a socket:
// bytes and times in, what it would write and what it asks of the server out.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "net/connection.hpp"

// Hellos are written with designated initializers naming only the fields a
// test changes; GCC 12 warns about the others, which keep their defaults.
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"

namespace tactile {
namespace {

namespace fb = flatbuffers;
using proto::ErrorCode;
using proto::Message;
using proto::Role;
using namespace std::chrono_literals;

// The server around the connection: a scene with channels "stylus" and
// "mouse", and a record of everything asked of it.
struct FakeHost : ConnectionHost {
  Bytes scene = [] {
    fb::FlatBufferBuilder b;
    return seal(b, Message::SceneDescription, proto::CreateSceneDescriptionDirect(b, "plate", 1));
  }();
  std::vector<std::string> channels{"stylus", "mouse"};
  std::string name = "plate";
  bool live = true;
  uint64_t other_driver = 0;  // a connection that drives every channel, 0 for none
  Connection* controller = nullptr;
  std::vector<DeviceSample> inputs;
  std::vector<std::pair<Bytes, OutKind>> relayed;
  std::vector<Topic> recorded;
  std::vector<uint32_t> controls;  // request ids
  int greetings = 0;
  int fields_changes = 0;  // view_fields_changed() calls

  int64_t now_ns() const override { return 42; }
  const Bytes& description() const override { return scene; }
  const std::vector<std::string>& devices() const override { return channels; }
  const std::string& scene_name() const override { return name; }
  bool workspace(Vec3& lo, Vec3& hi) const override {
    lo = Vec3(-1.0);
    hi = Vec3(1.0);
    return live;
  }
  uint64_t driver_of(const std::string&, const Connection&) const override { return other_driver; }
  bool claim_controller(Connection& s) override {
    if (controller) return false;
    controller = &s;
    return true;
  }
  void post_input(const DeviceSample& s) override {
    inputs.push_back(s);
    recorded.push_back(Topic::Applied);  // (marks where in the order the input went)
  }
  void relay(const Bytes& m, OutKind kind) override { relayed.emplace_back(m, kind); }
  void record(Topic t, std::span<const uint8_t>, int64_t) override { recorded.push_back(t); }
  void control(const proto::Control& c, Connection&) override { controls.push_back(c.request_id()); }
  void greeted(Connection&) override { ++greetings; }
  void view_fields_changed() override { ++fields_changes; }
};

const ConnectionClock::time_point t0{};

template <class T>
std::vector<uint8_t> wrap(fb::FlatBufferBuilder& b, Message type, fb::Offset<T> body) {
  b.Finish(proto::CreateEnvelope(b, type, body.Union()), proto::EnvelopeIdentifier());
  return {b.GetBufferPointer(), b.GetBufferPointer() + b.GetSize()};
}

struct HelloFields {
  Role role = Role::Viewer;
  const char* token = "secret";
  std::vector<std::string> devices;
  uint16_t major = uint16_t(proto::ProtocolMajor::Current);
  uint16_t minor = uint16_t(proto::ProtocolMinor::Current);
  float max_force_N = 5;
  std::vector<std::string> fields;  // Hello.fields (1.8)
  float max_rate_hz = 0;            // Hello.max_rate_hz (1.10)
};

std::vector<uint8_t> hello(const HelloFields& f) {
  fb::FlatBufferBuilder b;
  std::vector<fb::Offset<fb::String>> names;
  std::vector<fb::Offset<proto::DeviceLimits>> limits;
  for (const std::string& d : f.devices) {
    names.push_back(b.CreateString(d));
    limits.push_back(proto::CreateDeviceLimits(b, f.max_force_N, 0.0f, 1000.0f));
  }
  std::vector<fb::Offset<fb::String>> fields;
  for (const std::string& x : f.fields) fields.push_back(b.CreateString(x));
  return wrap(b, Message::Hello,
              proto::CreateHelloDirect(b, f.major, f.minor, f.role, f.token, "test",
                                       f.devices.empty() ? nullptr : &names, f.devices.empty() ? nullptr : &limits,
                                       f.fields.empty() ? nullptr : &fields, f.max_rate_hz));
}

std::vector<uint8_t> view_fields(const std::vector<std::string>& names) {
  fb::FlatBufferBuilder b;
  std::vector<fb::Offset<fb::String>> v;
  for (const std::string& x : names) v.push_back(b.CreateString(x));
  return wrap(b, Message::ViewFields, proto::CreateViewFieldsDirect(b, &v));
}

std::vector<uint8_t> input(const char* channel, double x = 0.1) {
  fb::FlatBufferBuilder b;
  const proto::Vec3d p(x, 0.2, 0.3);
  const proto::Quatd q(1, 0, 0, 0);
  return wrap(b, Message::DeviceInput, proto::CreateDeviceInput(b, b.CreateString(channel), 1, 7, &p, &q));
}

std::vector<uint8_t> safety(const char* channel = "stylus") {
  fb::FlatBufferBuilder b;
  return wrap(b, Message::SafetyEvent,
              proto::CreateSafetyEventDirect(b, channel, 7, 0, proto::SafetyKind::Clipped, "over the limit", 5.0f));
}

std::vector<uint8_t> status(const char* channel = "stylus") {
  fb::FlatBufferBuilder b;
  return wrap(b, Message::DeviceStatus,
              proto::CreateDeviceStatusDirect(b, channel, 7, 0, 1000, 20, 80, 0, 3, 1, 1, "coupled", 1.5f));
}

std::vector<uint8_t> control(uint32_t request_id) {
  fb::FlatBufferBuilder b;
  return wrap(b, Message::Control,
              proto::CreateControl(b, request_id, proto::ControlCommand::Pause, proto::CreatePause(b).Union()));
}

std::vector<uint8_t> ping() {
  fb::FlatBufferBuilder b;
  return wrap(b, Message::Ping, proto::CreatePing(b, 9, 100));
}

// A connection and what it writes.
struct Client {
  FakeHost host;
  ConnectionLimits limits;
  Connection connection;
  explicit Client(bool loopback = true, ConnectionLimits l = with_token())
      : limits(l), connection(host, limits, loopback, "10.0.0.7", 3, t0) {}
  static ConnectionLimits with_token() {
    ConnectionLimits l;
    l.token = "secret";
    return l;
  }
  void receive(const std::vector<uint8_t>& bytes, ConnectionClock::time_point now = t0) {
    connection.receive({bytes.data(), bytes.size()}, true, now);
  }
  // Everything queued, written in order.
  std::vector<Bytes> drain() {
    std::vector<Bytes> out;
    while (const Bytes* m = connection.next_write()) {
      out.push_back(*m);
      connection.written();
    }
    return out;
  }
};

Message type_of(const Bytes& m) { return proto::GetEnvelope(m->data())->message_type(); }
const proto::Error* error_of(const Bytes& m) { return proto::GetEnvelope(m->data())->message_as_Error(); }

// The one message written, an Error: its code and its text.
void expect_error(Client& c, ErrorCode code, const std::string& part) {
  const std::vector<Bytes> out = c.drain();
  ASSERT_EQ(out.size(), 1u);
  const proto::Error* e = error_of(out[0]);
  ASSERT_NE(e, nullptr) << proto::EnumNameMessage(type_of(out[0]));
  EXPECT_EQ(e->code(), code) << e->message()->str();
  EXPECT_NE(e->message()->str().find(part), std::string::npos) << e->message()->str();
}

// ---- Hello -----------------------------------------------------------------------------------

TEST(SessionHello, AcceptedWithWelcomeThenTheScene) {
  Client c;
  c.receive(hello({}));
  const std::vector<Bytes> out = c.drain();
  ASSERT_EQ(out.size(), 2u);
  const proto::Welcome* w = proto::GetEnvelope(out[0]->data())->message_as_Welcome();
  ASSERT_NE(w, nullptr);
  EXPECT_EQ(w->role(), Role::Viewer);
  EXPECT_EQ(w->session_id(), 3u);
  EXPECT_EQ(out[1], c.host.scene);
  EXPECT_TRUE(c.connection.greeted());
  EXPECT_EQ(c.host.greetings, 1);
  EXPECT_FALSE(c.connection.close_after_write());
}

TEST(SessionHello, OnlyHelloOrPingMayComeFirst) {
  Client c;
  c.receive(ping());
  ASSERT_EQ(c.drain().size(), 1u);  // a Pong
  c.receive(input("stylus"));
  expect_error(c, ErrorCode::WrongRole, "the first message must be Hello, got DeviceInput");
  EXPECT_TRUE(c.connection.close_after_write());
  EXPECT_TRUE(c.connection.idle());
}

TEST(SessionHello, AnotherMajorVersionIsRefused) {
  Client c;
  c.receive(hello({.major = 9, .minor = 1}));
  expect_error(c, ErrorCode::VersionMismatch, "client speaks protocol 9.1");
  EXPECT_TRUE(c.connection.close_after_write());
  EXPECT_FALSE(c.connection.greeted());
}

TEST(SessionHello, ARoleOutOfRangeIsRefused) {
  Client c;
  c.receive(hello({.role = Role(7)}));
  expect_error(c, ErrorCode::BadRequest, "Hello.role 7 is not a role");
}

TEST(SessionHello, TheTokenIsNeededByEveryRoleButALoopbackViewer) {
  {
    Client c;  // loopback viewer, no token: in
    c.receive(hello({.token = nullptr}));
    EXPECT_TRUE(c.connection.greeted());
  }
  {
    Client c(false);  // off loopback, even a viewer
    c.receive(hello({.token = nullptr}));
    expect_error(c, ErrorCode::Unauthorized, "off loopback every role needs it");
  }
  {
    Client c;
    c.receive(hello({.role = Role::Device, .token = "guess", .devices = {"stylus"}}));
    expect_error(c, ErrorCode::Unauthorized, "a wrong or missing token for the Device role");
  }
  {
    Client c(true, ConnectionLimits{});  // a server without a token lets in no device
    c.receive(hello({.role = Role::Device, .devices = {"stylus"}}));
    expect_error(c, ErrorCode::Unauthorized, "this server has no token set");
  }
}

TEST(SessionHello, OneControllerAtATime) {
  Client first, second;
  second.host.controller = &first.connection;  // the server already has one
  second.receive(hello({.role = Role::Controller}));
  expect_error(second, ErrorCode::Busy, "another controller is connected");
  first.receive(hello({.role = Role::Controller}));
  EXPECT_EQ(first.host.controller, &first.connection);
}

TEST(SessionHello, ADeviceNamesChannelsTheSceneHasAndNoOtherDeviceDrives) {
  {
    Client c;
    c.receive(hello({.role = Role::Device, .devices = {"stylus", "pedal"}}));
    expect_error(c, ErrorCode::BadRequest, "no device channel 'pedal' in this scene");
  }
  {
    Client c;
    c.host.other_driver = 11;
    c.receive(hello({.role = Role::Device, .devices = {"stylus"}}));
    expect_error(c, ErrorCode::Busy, "device channel 'stylus' is driven by another device (connection 11)");
  }
  {
    Client c;
    c.receive(hello({.role = Role::Device, .devices = {"stylus"}, .max_force_N = -1}));
    expect_error(c, ErrorCode::BadRequest, "max_force_N");
  }
  Client c;
  c.receive(hello({.role = Role::Device, .devices = {"mouse"}}));
  EXPECT_TRUE(c.connection.drives("mouse"));
  EXPECT_FALSE(c.connection.drives("stylus"));
}

TEST(SessionHello, TwiceIsAnErrorButNotAClose) {
  Client c;
  c.receive(hello({}));
  c.drain();
  c.receive(hello({}));
  expect_error(c, ErrorCode::BadRequest, "Hello sent twice");
  EXPECT_FALSE(c.connection.close_after_write());
}

// The fields a client asks for: in its Hello, then by ViewFields, each
// change told to the server (which computes what its viewers ask, and no
// more); a name the server does not know is named, in a Hello with a close.
TEST(SessionHello, FieldsAskedForAreKeptAndAnUnknownOneIsNamed) {
  Client c;
  c.receive(hello({.fields = {"von_mises", "stretch_max"}}));
  ASSERT_EQ(c.drain().size(), 2u);
  EXPECT_EQ(c.connection.view_fields(), view_field_bit(ViewField::VonMises) | view_field_bit(ViewField::StretchMax));
  EXPECT_EQ(c.host.fields_changes, 1);
  c.receive(view_fields({"energy_density"}));
  EXPECT_TRUE(c.drain().empty());
  EXPECT_EQ(c.connection.view_fields(), view_field_bit(ViewField::EnergyDensity));
  EXPECT_EQ(c.host.fields_changes, 2);
  c.receive(view_fields({"energy_density", "pressure"}));
  expect_error(c, ErrorCode::BadRequest, "ViewFields.fields: no field 'pressure' (this server sends von_mises,");
  EXPECT_EQ(c.connection.view_fields(), view_field_bit(ViewField::EnergyDensity)) << "an error changes nothing";
  EXPECT_FALSE(c.connection.close_after_write());
  c.receive(view_fields({}));
  EXPECT_EQ(c.connection.view_fields(), 0u);
  EXPECT_EQ(c.host.fields_changes, 3);

  Client plain;
  plain.receive(hello({}));
  plain.drain();
  EXPECT_EQ(plain.connection.view_fields(), 0u);
  EXPECT_EQ(plain.host.fields_changes, 0) << "a viewer that asks nothing changes nothing";

  Client bad;
  bad.receive(hello({.fields = {"vonmises"}}));
  expect_error(bad, ErrorCode::BadRequest, "Hello.fields: no field 'vonmises'");
  EXPECT_TRUE(bad.connection.close_after_write());
  EXPECT_FALSE(bad.connection.greeted());
}

TEST(SessionHello, NoHelloInTimeIsRefusedOnceGreetedNothing) {
  Client late;
  late.connection.hello_timed_out();
  expect_error(late, ErrorCode::BadRequest, "no Hello within the hello timeout");
  EXPECT_TRUE(late.connection.close_after_write());
  Client c;
  c.receive(hello({}));
  c.drain();
  c.connection.hello_timed_out();
  EXPECT_TRUE(c.drain().empty());
}

// ---- what comes in ---------------------------------------------------------------------------

TEST(SessionInbound, MessagesOverTheRateAreRefusedAndClose) {
  ConnectionLimits l = Client::with_token();
  l.max_messages_per_s = 10;
  Client c(true, l);
  for (int k = 0; k < 10; ++k) c.receive(ping(), t0 + 1ms);  // a second's burst
  EXPECT_EQ(c.drain().size(), 10u);
  c.receive(ping(), t0 + 1ms);
  expect_error(c, ErrorCode::RateLimited, "more than 10 messages per second");
  EXPECT_TRUE(c.connection.close_after_write());
}

// A 10 kHz device against a rate of 5000 messages a second: before, cut
// off after 1.65 s. Now its inputs over the rate are coalesced (the latest
// of its channel waits for a token), and its newest pose is never lost.
TEST(SessionInbound, ADevicesInputsOverTheRateAreCoalescedNotRefused) {
  ConnectionLimits l = Client::with_token();
  l.max_messages_per_s = 400;
  Client c(true, l);
  const FakeHost& host = c.host;
  c.receive(hello({.role = Role::Device, .devices = {"stylus"}}), t0);
  c.drain();
  // Two seconds at 1 kHz against 400 a second (2.5 times the rate, as 10 kHz against the default 5000 is 2).
  for (int k = 0; k < 2000; ++k) {
    const ConnectionClock::time_point now = t0 + k * 1ms;
    if (c.connection.flush_due() && c.connection.flush_at() <= now) c.connection.flush(now);
    c.receive(input("stylus", 1e-4 * k), now);
  }
  EXPECT_FALSE(c.connection.close_after_write());
  EXPECT_TRUE(c.drain().empty());
  // The last input waits; a flush at its time takes it.
  ASSERT_TRUE(c.connection.flush_due());
  c.connection.flush(c.connection.flush_at());
  EXPECT_FALSE(c.connection.flush_due());
  ASSERT_FALSE(host.inputs.empty());
  EXPECT_DOUBLE_EQ(host.inputs.back().pose.position.x, 1e-4 * 1999);
  EXPECT_NEAR(double(host.inputs.size()), 400 + 2 * 400, 20);  // the burst and the rate over two seconds
  EXPECT_EQ(int64_t(host.inputs.size()) + c.connection.inputs_coalesced(), 2000);
}

TEST(SessionInbound, PastThreeTimesTheRateEvenInputsAreAFlood) {
  ConnectionLimits l = Client::with_token();
  l.max_messages_per_s = 10;
  Client c(true, l);
  c.receive(hello({.role = Role::Device, .devices = {"stylus"}}), t0);
  c.drain();
  for (int k = 0; k < 9 + 30; ++k) c.receive(input("stylus"), t0);  // the burst, then three times more
  EXPECT_FALSE(c.connection.close_after_write());
  c.receive(input("stylus"), t0);
  expect_error(c, ErrorCode::RateLimited, "more than 10 messages per second");
  EXPECT_TRUE(c.connection.close_after_write());
}

TEST(SessionInbound, TheBucketRefillsAtItsRate) {
  ConnectionLimits l = Client::with_token();
  l.max_messages_per_s = 10;
  Client c(true, l);
  for (int k = 0; k < 10; ++k) c.receive(ping(), t0);
  c.receive(ping(), t0 + 100ms);  // one more token after a tenth of a second
  EXPECT_FALSE(c.connection.close_after_write());
  EXPECT_EQ(c.drain().size(), 11u);
}

TEST(SessionInbound, TextAndDamagedBytesGetErrorsAndTheConnectionStays) {
  Client c;
  const std::vector<uint8_t> bytes = ping();
  c.connection.receive({bytes.data(), bytes.size()}, false, t0);
  expect_error(c, ErrorCode::Malformed, "text message: the protocol is binary FlatBuffers");
  const std::vector<uint8_t> junk{1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12};
  c.receive(junk);
  expect_error(c, ErrorCode::Malformed, "not a tactile Envelope");
  EXPECT_FALSE(c.connection.close_after_write());
}

TEST(SessionInbound, AViewerMayNotSendDeviceOrControlMessages) {
  Client c;
  c.receive(hello({}));
  c.drain();
  c.receive(input("stylus"));
  expect_error(c, ErrorCode::WrongRole, "DeviceInput needs the device role");
  c.receive(safety());
  expect_error(c, ErrorCode::WrongRole, "SafetyEvent needs the Device role; this connection has the Viewer role");
  c.receive(control(77));
  const std::vector<Bytes> out = c.drain();
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(error_of(out[0])->code(), ErrorCode::WrongRole);
  EXPECT_EQ(error_of(out[0])->request_id(), 77u);
  EXPECT_TRUE(c.host.controls.empty());
}

struct Device : Client {
  Device() {
    receive(hello({.role = Role::Device, .devices = {"mouse"}}));
    drain();
  }
};

TEST(SessionInbound, ADevicesInputIsRecordedThenPostedForItsChannel) {
  Device d;
  d.receive(input("mouse"));
  ASSERT_EQ(d.host.inputs.size(), 1u);
  EXPECT_EQ(d.host.inputs[0].device, 1);  // "mouse" is the scene's second channel
  EXPECT_EQ(d.host.recorded, (std::vector<Topic>{Topic::Input, Topic::Applied}));
  EXPECT_TRUE(d.drain().empty());
  d.receive(input("stylus"));
  expect_error(d, ErrorCode::BadRequest, "channel 'stylus', which this connection did not name in its Hello");
  d.receive(input("mouse", std::nan("")));
  expect_error(d, ErrorCode::BadRequest, "position");
  EXPECT_EQ(d.host.inputs.size(), 1u);
}

TEST(SessionInbound, AnInputOutsideTheWorkspaceIsSaidOncePerExcursion) {
  Device d;
  d.receive(input("mouse", 5.0));
  expect_error(d, ErrorCode::BadRequest, "is outside the scene's workspace");
  d.receive(input("mouse", 6.0));
  EXPECT_TRUE(d.drain().empty());  // still out: not said again
  d.receive(input("mouse", 0.0));
  d.receive(input("mouse", 5.0));
  EXPECT_EQ(d.drain().size(), 1u);      // out again
  EXPECT_EQ(d.host.inputs.size(), 4u);  // every one posted: the loop holds the proxy at the edge
}

TEST(SessionInbound, AChannelTheNewSceneLacksIsSaidAndItsInputsDropped) {
  Device d;
  d.host.channels = {"stylus"};
  d.host.name = "other";
  d.connection.bind_devices();
  expect_error(d, ErrorCode::BadRequest, "scene 'other' has no device channel 'mouse'");
  d.receive(input("mouse"));
  EXPECT_TRUE(d.host.inputs.empty());
  EXPECT_TRUE(d.drain().empty());
}

TEST(SessionInbound, SafetyEventsAreStampedRelayedRecordedAndRateLimited) {
  ConnectionLimits l = Client::with_token();
  l.max_safety_events_per_s = 3;
  Client c(true, l);
  c.receive(hello({.role = Role::Device, .devices = {"stylus"}}));
  c.drain();
  for (int k = 0; k < 3; ++k) c.receive(safety(), t0 + 1ms);
  ASSERT_EQ(c.host.relayed.size(), 3u);
  EXPECT_EQ(c.host.relayed[0].second, OutKind::Event);
  const proto::SafetyEvent* ev = proto::GetEnvelope(c.host.relayed[0].first->data())->message_as_SafetyEvent();
  EXPECT_EQ(ev->server_time_ns(), 42);  // the server's stamp
  EXPECT_EQ(ev->device_time_ns(), 7);
  c.receive(safety(), t0 + 1ms);
  c.receive(safety(), t0 + 1ms);
  expect_error(c, ErrorCode::RateLimited, "more than 3 safety events per second: dropped, not relayed (1 so far)");
  EXPECT_EQ(c.connection.safety_dropped(), 2);
  c.receive(safety(), t0 + 1001ms);  // refilled: relayed again
  EXPECT_EQ(c.host.relayed.size(), 4u);
  c.receive(safety("mouse"), t0 + 1001ms);
  expect_error(c, ErrorCode::BadRequest, "SafetyEvent for channel 'mouse'");
}

TEST(SessionInbound, DeviceStatusesBeyondTenASecondAreDroppedSilently) {
  Device d;
  for (int k = 0; k < 15; ++k) d.receive(status("mouse"), t0 + 1ms);
  EXPECT_EQ(d.host.relayed.size(), 10u);
  EXPECT_EQ(d.host.relayed[0].second, OutKind::Status);
  EXPECT_TRUE(d.drain().empty());
}

TEST(SessionInbound, AControllersCommandIsRecordedAndCarriedOut) {
  Client c;
  c.receive(hello({.role = Role::Controller}));
  c.drain();
  c.receive(control(5));
  EXPECT_EQ(c.host.controls, (std::vector<uint32_t>{5}));
  EXPECT_EQ(c.host.recorded, (std::vector<Topic>{Topic::Control}));
  // An Error to a controller is kept in the recording.
  c.connection.send(make_error(ErrorCode::BadRequest, "no scene 'x'", 5), OutKind::Control);
  EXPECT_EQ(c.host.recorded.back(), Topic::Error);
}

// ---- what goes out ---------------------------------------------------------------------------

TEST(SessionOutbound, StatesAreLatestWinsAtTheViewerRate) {
  Client c;
  c.receive(hello({}));
  c.drain();
  const Bytes a = make_error(ErrorCode::Internal, "state a"), b = make_error(ErrorCode::Internal, "state b");
  c.connection.send(a, OutKind::State, t0 + 1s);
  c.connection.send(b, OutKind::State, t0 + 1s + 1ms);  // replaces a, not yet written
  EXPECT_EQ(c.drain(), (std::vector<Bytes>{b}));
  // After a pause the next is due at once (the average rate allows it), then a period (1/30 s) on.
  c.connection.send(a, OutKind::State, t0 + 1s + 5ms);
  EXPECT_EQ(c.drain().size(), 1u);
  c.connection.send(a, OutKind::State, t0 + 1s + 10ms);  // before the next is due: dropped
  EXPECT_TRUE(c.drain().empty());
  c.connection.send(a, OutKind::State, t0 + 1s + 30ms);  // a little early (jitter) still passes
  EXPECT_EQ(c.drain().size(), 1u);
  // At exactly 30 Hz for a second, none is lost.
  int passed = 0;
  for (int k = 1; k <= 30; ++k) {
    c.connection.send(a, OutKind::State, t0 + 2s + k * std::chrono::microseconds(33'333));
    passed += int(c.drain().size());
  }
  EXPECT_EQ(passed, 30);
}

// A device that reads slower than frames come: an unread frame is replaced
// by the next, so what it reads is the newest; one that, over a second,
// lets more than half of them be replaced is told so, once (1.10).
TEST(SessionOutbound, ASlowDeviceReadsTheNewestHapticFrameAndIsToldOnce) {
  Client c;
  c.receive(hello({.role = Role::Device, .devices = {"stylus"}}));
  c.drain();
  std::vector<Bytes> frames;
  for (int k = 0; k < 10; ++k) frames.push_back(make_error(ErrorCode::Internal, "frame " + std::to_string(k)));
  for (int k = 0; k < 7; ++k) c.connection.send(frames[size_t(k)], OutKind::Haptic, t0 + 1s);
  EXPECT_EQ(c.connection.haptics_dropped(), 6);
  EXPECT_EQ(c.drain(), (std::vector<Bytes>{frames[6]})) << "the newest; a moment's lag is not told";
  // For two seconds it reads one frame in four.
  std::vector<Bytes> told;
  for (int k = 0; k < 2000; ++k) {
    c.connection.send(frames[size_t(k % 10)], OutKind::Haptic, t0 + 2s + std::chrono::milliseconds(k));
    if (k % 4 == 3)
      for (const Bytes& m : c.drain())
        if (error_of(m)->code() == ErrorCode::Lagging) told.push_back(m);
  }
  ASSERT_EQ(told.size(), 1u) << "told once";
  EXPECT_EQ(error_of(told[0])->code(), ErrorCode::Lagging);
  EXPECT_NE(error_of(told[0])->message()->str().find("haptic frames"), std::string::npos);
  EXPECT_FALSE(c.connection.disconnect());
}

// One that reads every frame is never told, however many come.
TEST(SessionOutbound, ADeviceThatReadsEveryFrameIsNotTold) {
  Client c;
  c.receive(hello({.role = Role::Device, .devices = {"stylus"}}));
  c.drain();
  const Bytes f = make_error(ErrorCode::Internal, "frame");
  int errors = 0;
  for (int k = 0; k < 20000; ++k) {
    c.connection.send(f, OutKind::Haptic, t0 + std::chrono::microseconds(100 * k));
    for (const Bytes& m : c.drain()) errors += m != f;
  }
  EXPECT_EQ(errors, 0);
}

// A 1.9 client has no Lagging code to read: it is not told.
TEST(SessionOutbound, AnOlderDeviceIsNotToldItLags) {
  Client c;
  c.receive(hello({.role = Role::Device, .devices = {"stylus"}, .minor = 9}));
  c.drain();
  const Bytes f0 = make_error(ErrorCode::Internal, "0"), f1 = make_error(ErrorCode::Internal, "1");
  for (int k = 0; k < 2000; ++k) {
    c.connection.send(f0, OutKind::Haptic, t0 + std::chrono::milliseconds(k));
    c.connection.send(f1, OutKind::Haptic, t0 + std::chrono::milliseconds(k));
    EXPECT_EQ(c.drain(), (std::vector<Bytes>{f1}));
  }
}

TEST(SessionOutbound, TheMessageBeingWrittenIsNeverTheOneReplaced) {
  Client c;
  c.receive(hello({.role = Role::Device, .devices = {"stylus"}, .minor = 9}));
  c.drain();
  const Bytes f0 = make_error(ErrorCode::Internal, "0"), f1 = make_error(ErrorCode::Internal, "1"),
              f2 = make_error(ErrorCode::Internal, "2");
  c.connection.send(f0, OutKind::Haptic);
  const Bytes* writing = c.connection.next_write();
  ASSERT_NE(writing, nullptr);
  EXPECT_EQ(*writing, f0);
  c.connection.send(f1, OutKind::Haptic);
  c.connection.send(f2, OutKind::Haptic);  // replaces f1, not f0 which is on the wire
  EXPECT_EQ(*writing, f0);
  c.connection.written();
  EXPECT_EQ(c.drain(), (std::vector<Bytes>{f2}));
}

// A device asking for 250 Hz, offered a frame every millisecond for two
// seconds and reading each at once, gets 250 of them in the second second,
// evenly spread.
TEST(SessionOutbound, ADeviceAskingFor250HzGetsAtMost250FramesASecond) {
  Client c;
  c.receive(hello({.role = Role::Device, .devices = {"stylus"}, .max_rate_hz = 250}));
  c.drain();
  EXPECT_EQ(c.connection.max_rate_hz(), 250.0);
  const Bytes f = make_error(ErrorCode::Internal, "frame");
  int got = 0, longest_gap = 0, since = 0;
  for (int k = 0; k < 2000; ++k) {
    c.connection.send(f, OutKind::Haptic, t0 + std::chrono::milliseconds(k));
    const int n = int(c.drain().size());
    if (k < 1000) continue;
    got += n;
    since = n ? 0 : since + 1;
    longest_gap = std::max(longest_gap, since);
  }
  EXPECT_LE(got, 250);
  EXPECT_GE(got, 249);
  EXPECT_LE(longest_gap, 4);  // [ms]
  EXPECT_EQ(c.connection.haptics_dropped(), 0) << "held back by the rate, not replaced";
}

// A viewer's state frames: at the rate it asks for, never above the server's.
TEST(SessionOutbound, AViewerGetsStatesAtTheRateItAsksUpToTheServers) {
  for (const auto& [asked, expected] : {std::pair{10.0f, 10}, std::pair{100.0f, 30}, std::pair{0.0f, 30}}) {
    Client c;
    c.receive(hello({.max_rate_hz = asked}));
    c.drain();
    const Bytes f = make_error(ErrorCode::Internal, "state");
    int got = 0;
    for (int k = 0; k < 1000; ++k) {
      c.connection.send(f, OutKind::State, t0 + std::chrono::milliseconds(k));
      got += int(c.drain().size());
    }
    EXPECT_NEAR(got, expected, 1) << "asked " << asked;
  }
}

TEST(SessionHello, ARateBelowZeroIsRefusedNamingTheField) {
  Client c;
  c.receive(hello({.role = Role::Device, .devices = {"stylus"}, .max_rate_hz = -5}));
  const std::vector<Bytes> out = c.drain();
  ASSERT_FALSE(out.empty());
  const proto::Error* e = error_of(out.back());
  ASSERT_NE(e, nullptr);
  EXPECT_EQ(e->code(), ErrorCode::BadRequest);
  EXPECT_NE(e->message()->str().find("Hello.max_rate_hz"), std::string::npos) << e->message()->str();
  EXPECT_FALSE(c.connection.greeted());
}

TEST(SessionOutbound, AReaderThatLetsControlMessagesPileUpIsDisconnected) {
  ConnectionLimits l = Client::with_token();
  l.control_queue = 3;
  Client c(true, l);
  for (int k = 0; k < 3; ++k) c.connection.send(make_error(ErrorCode::Internal, "t"), OutKind::Control);
  EXPECT_FALSE(c.connection.disconnect());
  c.connection.send(make_error(ErrorCode::Internal, "t"), OutKind::Control);
  EXPECT_TRUE(c.connection.disconnect());
  EXPECT_FALSE(c.connection.waiting());
}

TEST(SessionOutbound, WhoReadsSafetyEventsAndStatuses) {
  Client viewer, device, old;
  viewer.receive(hello({}));
  device.receive(hello({.role = Role::Device, .devices = {"stylus"}}));
  old.receive(hello({.minor = 1}));
  EXPECT_TRUE(viewer.connection.reads(OutKind::Event) && viewer.connection.reads(OutKind::Status));
  EXPECT_FALSE(device.connection.reads(OutKind::Event) || device.connection.reads(OutKind::Status));
  EXPECT_FALSE(old.connection.reads(OutKind::Event) || old.connection.reads(OutKind::Status));  // a 1.1 codec
  EXPECT_FALSE(old.connection.reads_replay_status());
}

TEST(SessionOutbound, NothingIsQueuedOnceTheSocketIsClosed) {
  Client c;
  c.connection.mark_closed();
  c.connection.send(make_error(ErrorCode::Internal, "late"), OutKind::Control);
  EXPECT_TRUE(c.connection.idle());
  EXPECT_EQ(c.connection.next_write(), nullptr);
}

}  // namespace
}  // namespace tactile
