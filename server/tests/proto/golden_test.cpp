// Golden vectors (proto/vectors/): each message type written once as JSON and
// encoded by flatc into <name>.tctl. Here, for every vector:
//   - the schema parser encodes the JSON to exactly the committed bytes (the
//     vectors are current with the schema);
//   - the generated C++ codec verifies and decodes them, and re-encodes what
//     it decoded into a message that reads back the same (as JSON text);
//   - a few fields per type are read through the generated accessors and
//     compared with the values written in the JSON.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <string>
#include <vector>

#include <flatbuffers/idl.h>
#include <flatbuffers/util.h>

#include "tactile_generated.h"

namespace tactile::proto {
namespace {

namespace fs = std::filesystem;

std::string read_file(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

std::vector<fs::path> vector_files() {
  std::vector<fs::path> out;
  for (const auto& e : fs::directory_iterator(TACTILE_PROTO_VECTORS))
    if (e.path().extension() == ".json") out.push_back(e.path());
  std::sort(out.begin(), out.end());
  return out;
}

// A parser that knows the schema.
std::unique_ptr<flatbuffers::Parser> make_parser() {
  flatbuffers::IDLOptions opts;
  opts.strict_json = true;
  auto parser = std::make_unique<flatbuffers::Parser>(opts);
  const std::string schema = read_file(TACTILE_PROTO_SCHEMA);
  EXPECT_TRUE(parser->Parse(schema.c_str())) << parser->error_;
  return parser;
}

std::string to_text(flatbuffers::Parser& parser, const uint8_t* bytes) {
  std::string text;
  EXPECT_TRUE(flatbuffers::GenerateText(parser, bytes, &text));
  return text;
}

TEST(ProtoGolden, EveryMessageTypeHasAVector) {
  std::vector<std::string> types;
  for (const fs::path& p : vector_files()) {
    const std::string json = read_file(p);
    const auto at = json.find("\"message_type\": \"");
    ASSERT_NE(at, std::string::npos) << p;
    types.push_back(json.substr(at + 17, json.find('"', at + 17) - at - 17));
  }
  for (int m = int(Message::MIN) + 1; m <= int(Message::MAX); ++m) {
    const std::string name = EnumNameMessage(Message(m));
    EXPECT_NE(std::find(types.begin(), types.end(), name), types.end()) << "no golden vector for " << name;
  }
  // Every control command too.
  for (int c = int(ControlCommand::MIN) + 1; c <= int(ControlCommand::MAX); ++c) {
    const std::string name = EnumNameControlCommand(ControlCommand(c));
    bool found = false;
    for (const fs::path& p : vector_files())
      found |= read_file(p).find("\"command_type\": \"" + name + "\"") != std::string::npos;
    EXPECT_TRUE(found) << "no golden vector for control command " << name;
  }
}

TEST(ProtoGolden, VectorsMatchTheSchemaAndRoundTripThroughTheCppCodec) {
  const std::vector<fs::path> files = vector_files();
  ASSERT_GE(files.size(), 18u);
  for (const fs::path& json_path : files) {
    SCOPED_TRACE(json_path.filename().string());
    std::unique_ptr<flatbuffers::Parser> p = make_parser();
    flatbuffers::Parser& parser = *p;
    ASSERT_TRUE(parser.Parse(read_file(json_path).c_str())) << parser.error_;
    const std::string encoded(reinterpret_cast<const char*>(parser.builder_.GetBufferPointer()),
                              parser.builder_.GetSize());
    fs::path bin_path = json_path;
    bin_path.replace_extension(".tctl");
    const std::string golden = read_file(bin_path);
    ASSERT_FALSE(golden.empty()) << "missing " << bin_path;
    EXPECT_EQ(encoded, golden) << "the committed vector is stale: regenerate with flatc -b (see proto/README.md)";

    // Decode with the generated codec, re-encode what it decoded, compare as text.
    const auto* bytes = reinterpret_cast<const uint8_t*>(golden.data());
    flatbuffers::Verifier v(bytes, golden.size());
    ASSERT_TRUE(VerifyEnvelopeBuffer(v));
    ASSERT_TRUE(EnvelopeBufferHasIdentifier(bytes));
    std::unique_ptr<EnvelopeT> object = UnPackEnvelope(bytes);
    flatbuffers::FlatBufferBuilder b;
    b.Finish(Envelope::Pack(b, object.get()), EnvelopeIdentifier());
    flatbuffers::Verifier v2(b.GetBufferPointer(), b.GetSize());
    ASSERT_TRUE(VerifyEnvelopeBuffer(v2));
    EXPECT_EQ(to_text(parser, b.GetBufferPointer()), to_text(parser, bytes));
  }
}

// Typed reads of the vectors: the generated accessors see the JSON's values.
TEST(ProtoGolden, GeneratedAccessorsReadTheWrittenValues) {
  auto load = [](const char* name) { return read_file(fs::path(TACTILE_PROTO_VECTORS) / name); };
  const std::string hello = load("hello.tctl");
  const Hello* h = GetEnvelope(hello.data())->message_as_Hello();
  ASSERT_NE(h, nullptr);
  EXPECT_EQ(h->protocol_major(), uint16_t(ProtocolMajor::Current));
  EXPECT_EQ(h->role(), Role::Device);
  EXPECT_STREQ(h->token()->c_str(), "s3cret-token");
  EXPECT_STREQ(h->devices()->Get(1)->c_str(), "right");
  ASSERT_EQ(h->device_limits()->size(), 2u);
  EXPECT_FLOAT_EQ(h->device_limits()->Get(0)->max_force_N(), 6.0f);
  EXPECT_FLOAT_EQ(h->device_limits()->Get(1)->stiffness_N_per_m(), 1200.0f);
  EXPECT_TRUE(h->device_limits()->Get(1)->direct());
  EXPECT_FALSE(h->device_limits()->Get(0)->direct());
  EXPECT_FLOAT_EQ(h->max_rate_hz(), 500.0f);  // (1.10)
  const std::string lagging = load("error_lagging.tctl");
  EXPECT_EQ(GetEnvelope(lagging.data())->message_as_Error()->code(), ErrorCode::Lagging);

  const std::string scene = load("scene_description.tctl");
  const SceneDescription* d = GetEnvelope(scene.data())->message_as_SceneDescription();
  ASSERT_NE(d, nullptr);
  ASSERT_EQ(d->bodies()->size(), 1u);  // (1.9)
  EXPECT_STREQ(d->bodies()->Get(0)->name()->c_str(), "beam");
  EXPECT_EQ(d->bodies()->Get(0)->vertex_end(), d->surface_nodes()->size());
  EXPECT_EQ(d->bodies()->Get(0)->triangle_end(), d->triangles()->size() / 3);

  const std::string state = load("state_frame.tctl");
  const StateFrame* s = GetEnvelope(state.data())->message_as_StateFrame();
  ASSERT_NE(s, nullptr);
  EXPECT_EQ(s->step(), 123456u);
  EXPECT_EQ(s->server_time_ns(), 987654321012);
  EXPECT_FLOAT_EQ(s->positions()->Get(4), -0.001f);
  EXPECT_FLOAT_EQ(s->proxies()->Get(1)->orientation().x(), 0.5f);

  const std::string haptic = load("haptic_frame.tctl");
  const HapticFrame* hf = GetEnvelope(haptic.data())->message_as_HapticFrame();
  ASSERT_NE(hf, nullptr);
  EXPECT_FLOAT_EQ(hf->proxies()->Get(0)->stiffness().m12(), 5.0f);
  EXPECT_EQ(hf->devices()->Get(0)->contacts(), 12u);
  ASSERT_EQ(hf->device_poses()->size(), 2u);
  EXPECT_FLOAT_EQ(hf->device_poses()->Get(1)->position().y(), 0.4f);
  EXPECT_FLOAT_EQ(hf->device_poses()->Get(1)->orientation().z(), 0.5f);
  ASSERT_EQ(hf->device_input_sequences()->size(), 2u);
  EXPECT_EQ(hf->device_input_sequences()->Get(1), 977u);
  ASSERT_EQ(hf->device_couplings()->size(), 2u);
  EXPECT_TRUE(hf->device_couplings()->Get(0)->coupled());
  EXPECT_FALSE(hf->device_couplings()->Get(1)->coupled());
  EXPECT_FLOAT_EQ(hf->device_couplings()->Get(0)->body().position().y(), 0.4875f);
  EXPECT_FLOAT_EQ(hf->device_couplings()->Get(0)->max_torque_Nm(), 0.125f);
  ASSERT_EQ(hf->device_models()->size(), 2u);  // (1.11)
  EXPECT_FLOAT_EQ(hf->device_models()->Get(0)->damping().m12(), -0.0125f);
  EXPECT_FLOAT_EQ(hf->device_models()->Get(0)->velocity().y(), -0.0625f);
  EXPECT_FLOAT_EQ(hf->device_models()->Get(0)->normal().y(), 0.9921875f);
  EXPECT_FLOAT_EQ(hf->device_models()->Get(0)->release_m(), 0.0025f);
  EXPECT_FLOAT_EQ(hf->device_models()->Get(0)->radius_m(), 0.005f);
  EXPECT_FLOAT_EQ(hf->device_models()->Get(1)->radius_m(), 0.0f);

  const std::string safety = load("safety_event.tctl");
  const SafetyEvent* se = GetEnvelope(safety.data())->message_as_SafetyEvent();
  ASSERT_NE(se, nullptr);
  EXPECT_STREQ(se->device()->c_str(), "stylus");
  EXPECT_EQ(se->kind(), SafetyKind::Clipped);
  EXPECT_EQ(se->device_time_ns(), 5000250123);
  EXPECT_EQ(se->server_time_ns(), 987654521012);
  EXPECT_FLOAT_EQ(se->force_N(), 5.0f);

  const std::string input = load("device_input.tctl");
  const DeviceInput* in = GetEnvelope(input.data())->message_as_DeviceInput();
  ASSERT_NE(in, nullptr);
  EXPECT_DOUBLE_EQ(in->orientation()->w(), 0.7071067811865476);

  const std::string control = load("control_set_parameter.tctl");
  const Control* c = GetEnvelope(control.data())->message_as_Control();
  ASSERT_NE(c, nullptr);
  EXPECT_DOUBLE_EQ(c->command_as_SetParameter()->value(), 2.5);

  const std::string error = load("error.tctl");
  const Error* e = GetEnvelope(error.data())->message_as_Error();
  ASSERT_NE(e, nullptr);
  EXPECT_EQ(e->code(), ErrorCode::VersionMismatch);
}

}  // namespace
}  // namespace tactile::proto
