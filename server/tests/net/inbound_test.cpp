// What the server checks in a client's message before it acts on it
// (net/inbound.hpp): here, a SafetyEvent a device wants relayed.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>

#include "net/inbound.hpp"

namespace tactile {
namespace {

struct EventFields {
  const char* device = "stylus";
  std::string message = "force over the limit: scaled to 5 N";
  proto::SafetyKind kind = proto::SafetyKind::Clipped;
  float force_N = 5.0f;
  bool with_device = true;
};

// Encodes the event into `b`, reads it back as the server does, and returns
// what check_safety_event says of it.
std::string check(const EventFields& f) {
  flatbuffers::FlatBufferBuilder b;
  const auto device = f.with_device ? b.CreateString(f.device) : flatbuffers::Offset<flatbuffers::String>();
  const auto message = b.CreateString(f.message);
  b.Finish(proto::CreateEnvelope(b, proto::Message::SafetyEvent,
                                 proto::CreateSafetyEvent(b, device, 123, 0, f.kind, message, f.force_N).Union()),
           proto::EnvelopeIdentifier());
  const Inbound in = read_inbound(b.GetBufferPointer(), b.GetSize());
  EXPECT_TRUE(in) << in.message;
  if (!in) return "unreadable";
  const proto::SafetyEvent* ev = in.envelope->message_as_SafetyEvent();
  EXPECT_NE(ev, nullptr);
  return ev ? check_safety_event(*ev) : "not a SafetyEvent";
}

bool says(const std::string& what, const char* part) { return what.find(part) != std::string::npos; }

// A client in a new language that finishes its buffer without "TCTL" is told
// so by name; bytes that are no Envelope at all are told that instead.
TEST(Inbound, AnEnvelopeWithoutTheFileIdentifierIsRefusedNamingIt) {
  flatbuffers::FlatBufferBuilder b;
  const auto name = b.CreateString("pytest");
  proto::HelloBuilder hello(b);
  hello.add_protocol_major(1);
  hello.add_client_name(name);
  const auto h = hello.Finish();
  b.Finish(proto::CreateEnvelope(b, proto::Message::Hello, h.Union()));  // no file identifier
  const Inbound in = read_inbound(b.GetBufferPointer(), b.GetSize());
  EXPECT_FALSE(in);
  EXPECT_TRUE(says(in.message, "without the file identifier \"TCTL\"")) << in.message;
  const uint8_t junk[16] = {12, 0, 0, 0, 'T', 'C', 'T', 'L', 1, 2, 3, 4, 5, 6, 7, 8};
  const Inbound bad = read_inbound(junk, sizeof junk);
  EXPECT_FALSE(bad);
  EXPECT_TRUE(says(bad.message, "not a tactile Envelope")) << bad.message;
}

TEST(Inbound, AWellFormedSafetyEventPasses) {
  EXPECT_EQ(check({}), "");
  EventFields f;
  f.message = "";  // a kind can say enough
  f.kind = proto::SafetyKind::Other;
  f.force_N = 0;
  EXPECT_EQ(check(f), "");
  f.message = "Kraft über der Grenze";  // UTF-8 beyond ASCII
  EXPECT_EQ(check(f), "");
}

TEST(Inbound, SafetyEventValuesAreChecked) {
  EventFields f;
  f.with_device = false;
  EXPECT_TRUE(says(check(f), "without a device channel"));
  f = {};
  f.device = "";
  EXPECT_TRUE(says(check(f), "without a device channel"));
  f = {};
  const std::string long_name(kMaxSafetyDeviceBytes + 1, 'd');
  f.device = long_name.c_str();
  EXPECT_TRUE(says(check(f), "device channel of 129 bytes"));
  f = {};
  f.message = std::string(kMaxSafetyMessageBytes + 1, 'm');
  EXPECT_TRUE(says(check(f), "message of 513 bytes"));
  f.message = std::string(kMaxSafetyMessageBytes, 'm');  // at the bound
  EXPECT_EQ(check(f), "");
  f.message = "cut \xC3";  // a two-byte sequence cut short
  EXPECT_TRUE(says(check(f), "not UTF-8"));
  f.message = "over\xC0\xAFlong";  // an overlong '/'
  EXPECT_TRUE(says(check(f), "not UTF-8"));
  f = {};
  f.device = "sty\xFFlus";
  EXPECT_TRUE(says(check(f), "channel that is not UTF-8"));
  f = {};
  f.kind = proto::SafetyKind(12);  // past Other
  EXPECT_TRUE(says(check(f), "unknown kind 12"));
  f = {};
  f.force_N = std::numeric_limits<float>::quiet_NaN();
  EXPECT_TRUE(says(check(f), "finite"));
  f.force_N = std::numeric_limits<float>::infinity();
  EXPECT_TRUE(says(check(f), "finite"));
  f.force_N = -1.0f;
  EXPECT_TRUE(says(check(f), ">= 0"));
}

// What leaves the server quoting a client is valid UTF-8 with no control
// characters: valid text passes as it is; a stray byte, an overlong form, a
// surrogate, a sequence cut short and a NUL each become \xNN, and the text
// around them stays.
TEST(Inbound, TextQuotedBackIsValidUtf8) {
  EXPECT_EQ(utf8_text("stylus"), "stylus");
  EXPECT_EQ(utf8_text("caf\xc3\xa9 \xe2\x82\xac \xf0\x9f\x96\x90"), "caf\xc3\xa9 \xe2\x82\xac \xf0\x9f\x96\x90");
  EXPECT_EQ(utf8_text("two\nlines\tand a tab"), "two\nlines\tand a tab");
  EXPECT_EQ(utf8_text(std::string("a\0b", 3)), "a\\x00b");           // NUL: would cut the text
  EXPECT_EQ(utf8_text("\xff\xfe"), "\\xff\\xfe");                    // never valid
  EXPECT_EQ(utf8_text("\xc0\xaf"), "\\xc0\\xaf");                    // overlong '/'
  EXPECT_EQ(utf8_text("\xed\xa0\x80"), "\\xed\\xa0\\x80");           // a UTF-16 surrogate
  EXPECT_EQ(utf8_text("ok\xe2\x82"), "ok\\xe2\\x82");                // cut short at the end
  EXPECT_EQ(utf8_text("\xf4\x90\x80\x80"), "\\xf4\\x90\\x80\\x80");  // past U+10FFFF
  EXPECT_EQ(utf8_text("\x1b[31m"), "\\x1b[31m");                     // a terminal escape
}

}  // namespace
}  // namespace tactile
