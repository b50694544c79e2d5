// The fuzzer's corpus (server/fuzz/corpus/) and the golden vectors, replayed
// through what the server does with a client's bytes (server/fuzz/walk.hpp):
// each input is either refused with a message or read without fault. Under
// the sanitizers of a fuzz build this is where a regression would show; here
// it keeps every input the fuzzer found interesting in the suite.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <vector>

#include "walk.hpp"

namespace tactile {
namespace {

namespace fs = std::filesystem;

std::vector<uint8_t> read_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::vector<uint8_t>(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

TEST(FuzzCorpus, EveryInputIsRefusedWithAReasonOrRead) {
  int refused = 0, read = 0;
  for (const char* dir : {TACTILE_FUZZ_CORPUS, TACTILE_PROTO_VECTORS}) {
    for (const auto& entry : fs::directory_iterator(dir)) {
      if (entry.path().extension() == ".json" || entry.path().filename() == "README.md") continue;
      const std::vector<uint8_t> bytes = read_bytes(entry.path());
      const Inbound in = read_inbound(bytes.data(), bytes.size());
      if (!in) {
        ++refused;
        EXPECT_FALSE(in.message.empty()) << entry.path();
      } else {
        ++read;
      }
      fuzz::walk_inbound(bytes.data(), bytes.size());
    }
  }
  EXPECT_GE(read, 18);    // the golden vectors at least
  EXPECT_GE(refused, 3);  // the malformed seeds at least
}

TEST(FuzzCorpus, DeviceInputValuesAreChecked) {
  flatbuffers::FlatBufferBuilder b;
  const proto::Vec3d bad_p(std::nan(""), 0, 0);
  const proto::Quatd q(1, 0, 0, 0), zero_q(0, 0, 0, 0);
  const proto::Vec3d p(0.01, 0.02, 0.03);
  auto check = [&](const proto::Vec3d* pos, const proto::Quatd* ori) {
    b.Clear();
    b.Finish(proto::CreateEnvelope(b, proto::Message::DeviceInput,
                                   proto::CreateDeviceInputDirect(b, "stylus", 1, 2, pos, ori, 0).Union()),
             proto::EnvelopeIdentifier());
    const Inbound in = read_inbound(b.GetBufferPointer(), b.GetSize());
    EXPECT_TRUE(in);
    return check_device_input(*in.envelope->message_as_DeviceInput());
  };
  EXPECT_EQ(check(&p, &q), "");
  EXPECT_NE(check(&bad_p, &q).find("non-finite"), std::string::npos);
  EXPECT_NE(check(&p, &zero_q).find("unit quaternion"), std::string::npos);
  EXPECT_NE(check(nullptr, &q).find("without position"), std::string::npos);
}

}  // namespace
}  // namespace tactile
