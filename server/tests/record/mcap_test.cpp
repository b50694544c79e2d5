// The MCAP writer and reader: what is written reads back; a file cut short
// anywhere reads back every chunk closed before the cut; a damaged chunk is
// reported and skipped, never read as data. (The same files against the
// reference readers: tests/test_recording.py.)
#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <thread>

#include "record/mcap.hpp"
#include "record/recorder.hpp"
#include "tactile_generated.h"
#include "temp_dir.hpp"

namespace tactile {
namespace {

std::vector<uint8_t> payload(int i) {
  std::vector<uint8_t> p(size_t(5 + i % 37));
  for (size_t k = 0; k < p.size(); ++k) p[k] = uint8_t(i * 31 + int(k));
  return p;
}

// An Envelope of the message type `topic` carries, numbered i (its step),
// with `floats` surface positions for a StateFrame.
std::vector<uint8_t> envelope(Topic topic, int i, size_t floats = 0) {
  proto::EnvelopeT e;
  switch (topic) {
    case Topic::Input: {
      proto::DeviceInputT m;
      m.device = "stylus";
      m.sequence = uint64_t(i);
      e.message.Set(std::move(m));
      break;
    }
    case Topic::Haptic: {
      proto::HapticFrameT m;
      m.step = uint64_t(i);
      e.message.Set(std::move(m));
      break;
    }
    case Topic::State: {
      proto::StateFrameT m;
      m.step = uint64_t(i);
      m.positions.assign(floats, 0.5f);
      e.message.Set(std::move(m));
      break;
    }
    default: {
      proto::TelemetryT m;
      m.step = uint64_t(i);
      e.message.Set(std::move(m));
      break;
    }
  }
  flatbuffers::FlatBufferBuilder fbb;
  proto::FinishEnvelopeBuffer(fbb, proto::Envelope::Pack(fbb, &e));
  return {fbb.GetBufferPointer(), fbb.GetBufferPointer() + fbb.GetSize()};
}

std::vector<uint8_t> read_bytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}
void write_bytes(const std::string& path, const std::vector<uint8_t>& b) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  f.write(reinterpret_cast<const char*>(b.data()), std::streamsize(b.size()));
}

// 200 messages on two channels, a chunk closed every 20; returns the byte
// offset in the file where each chunk ends (after its message indexes).
std::vector<uint64_t> write_sample(const std::string& path, bool finish = true,
                                   mcap::Compression compression = mcap::Compression::None) {
  mcap::Writer w(path, "", "test", compression);
  const uint8_t schema_data[3] = {1, 2, 3};
  const uint16_t s = w.add_schema("tactile.proto.Envelope", "flatbuffer", schema_data);
  const uint16_t a = w.add_channel(s, "/a", "flatbuffer");
  const uint16_t b = w.add_channel(s, "/b", "flatbuffer", {{"k", "v"}});
  w.add_metadata("tactile", {{"scene_name", "block"}});
  std::vector<uint64_t> ends;
  for (int i = 0; i < 200; ++i) {
    w.write(i % 3 == 0 ? b : a, uint64_t(1000 + i), uint64_t(2000 + i), payload(i));
    if (i % 20 == 19) {
      w.close_chunk();
      ends.push_back(w.bytes());
    }
  }
  if (finish) w.finish();
  return ends;
}

constexpr mcap::Compression kBoth[] = {mcap::Compression::None, mcap::Compression::Zstd};

TEST(Mcap, WhatIsWrittenReadsBack) {
  for (const mcap::Compression compression : kBoth) {
    SCOPED_TRACE(compression == mcap::Compression::Zstd ? "zstd" : "uncompressed");
    test::TempDir dir;
    const std::string path = dir.file("a.mcap");
    write_sample(path, true, compression);
    const mcap::Recording r = mcap::read_file(path);
    EXPECT_TRUE(r.complete);
    EXPECT_TRUE(r.problems.empty()) << r.problems.front();
    EXPECT_EQ(r.library, "test");
    ASSERT_EQ(r.messages.size(), 200u);
    EXPECT_EQ(r.chunks, 10u);
    for (int i = 0; i < 200; ++i) {
      const mcap::Message& m = r.messages[size_t(i)];
      EXPECT_EQ(r.channels.at(m.channel).topic, i % 3 == 0 ? "/b" : "/a");
      EXPECT_EQ(m.log_time, uint64_t(1000 + i));
      EXPECT_EQ(m.publish_time, uint64_t(2000 + i));
      EXPECT_EQ(m.data, payload(i)) << i;
    }
    // Sequences count per channel.
    EXPECT_EQ(r.messages[3].sequence, 1u);  // the second on /b
    EXPECT_EQ(r.messages[2].sequence, 1u);  // the second on /a
    ASSERT_EQ(r.metadata.size(), 1u);
    EXPECT_EQ(r.metadata[0].second.at("scene_name"), "block");
    EXPECT_EQ(r.channels.at(r.channel_of("/b")).metadata.at("k"), "v");
  }
}

TEST(Mcap, AFileCutAnywhereReadsBackEveryChunkBeforeTheCut) {
  for (const mcap::Compression compression : kBoth) {
    SCOPED_TRACE(compression == mcap::Compression::Zstd ? "zstd" : "uncompressed");
    test::TempDir dir;
    const std::string path = dir.file("a.mcap");
    const std::vector<uint64_t> ends = write_sample(path, true, compression);
    const std::vector<uint8_t> whole = read_bytes(path);
    const std::string cut = dir.file("cut.mcap");
    int cuts = 0;
    for (size_t n = 8; n < whole.size(); n += 7) {
      write_bytes(cut, std::vector<uint8_t>(whole.begin(), whole.begin() + std::ptrdiff_t(n)));
      const mcap::Recording r = mcap::read_file(cut);
      size_t chunks_before = 0;
      while (chunks_before < ends.size() && ends[chunks_before] <= n) ++chunks_before;
      // Every message of each chunk that ends before the cut (the message
      // indexes after a chunk are not needed to read it: >= its records).
      EXPECT_GE(r.messages.size(), 20 * chunks_before) << "cut at " << n;
      EXPECT_LE(r.messages.size(), 20 * (chunks_before + 1)) << "cut at " << n;
      for (size_t i = 0; i < r.messages.size(); ++i) ASSERT_EQ(r.messages[i].data, payload(int(i))) << n;
      EXPECT_FALSE(r.complete);
      EXPECT_FALSE(r.problems.empty()) << "cut at " << n << " went unreported";
      ++cuts;
    }
    EXPECT_GT(cuts, 100);
  }
}

TEST(Mcap, ZstdChunksHoldTheSameMessagesInFewerBytes) {
  test::TempDir dir;
  write_sample(dir.file("plain.mcap"));
  write_sample(dir.file("zstd.mcap"), true, mcap::Compression::Zstd);
  const mcap::Recording plain = mcap::read_file(dir.file("plain.mcap")), zstd = mcap::read_file(dir.file("zstd.mcap"));
  ASSERT_EQ(zstd.messages.size(), plain.messages.size());
  for (size_t i = 0; i < plain.messages.size(); ++i) EXPECT_EQ(zstd.messages[i].data, plain.messages[i].data) << i;
  EXPECT_LT(std::filesystem::file_size(dir.file("zstd.mcap")), std::filesystem::file_size(dir.file("plain.mcap")));
}

TEST(Mcap, AChunkCompressedAnotherWayIsNamedAndSkipped) {
  test::TempDir dir;
  const std::string path = dir.file("a.mcap");
  const std::vector<uint64_t> ends = write_sample(path, true, mcap::Compression::Zstd);
  std::vector<uint8_t> bytes = read_bytes(path);
  // The second chunk's compression, renamed (same length) to one this reader does not read.
  const size_t at = size_t(ends[0]) + 9 + 28 + 4;
  ASSERT_EQ(std::string(bytes.begin() + std::ptrdiff_t(at), bytes.begin() + std::ptrdiff_t(at + 4)), "zstd");
  std::memcpy(bytes.data() + at, "lzma", 4);
  write_bytes(path, bytes);
  const mcap::Recording r = mcap::read_file(path);
  ASSERT_EQ(r.problems.size(), 1u);
  EXPECT_NE(r.problems[0].find("is compressed with 'lzma', which this reader does not read"), std::string::npos)
      << r.problems[0];
  EXPECT_EQ(r.messages.size(), 180u);
}

TEST(Mcap, ADamagedChunkIsReportedAndSkipped) {
  for (const mcap::Compression compression : kBoth) {
    SCOPED_TRACE(compression == mcap::Compression::Zstd ? "zstd" : "uncompressed");
    test::TempDir dir;
    const std::string path = dir.file("a.mcap");
    const std::vector<uint64_t> ends = write_sample(path, true, compression);
    std::vector<uint8_t> bytes = read_bytes(path);
    // A byte of the fourth chunk's records (as stored): behind the chunk
    // record's opcode and length (9 bytes), its times, size and CRC (28),
    // its compression's name (4 + n) and the records' length (8).
    const size_t name = compression == mcap::Compression::Zstd ? 4 : 0;
    const size_t at = size_t(ends[2]) + 9 + 28 + 4 + name + 8 + 10;
    ASSERT_LT(at, size_t(ends[3]));
    bytes[at] ^= 0x40;
    write_bytes(path, bytes);
    const mcap::Recording r = mcap::read_file(path);
    ASSERT_EQ(r.problems.size(), 1u);
    const bool said = r.problems[0].find("fails its CRC") != std::string::npos ||
                      (name && r.problems[0].find("does not decompress (zstd: ") != std::string::npos);
    EXPECT_TRUE(said) << r.problems[0];
    ASSERT_EQ(r.messages.size(), 180u);
    for (const mcap::Message& m : r.messages) {
      EXPECT_FALSE(m.log_time >= 1060 && m.log_time < 1080) << "a message of the damaged chunk was read";
    }
    EXPECT_TRUE(r.complete);
  }
}

TEST(Mcap, NotAnMcapFileIsRefusedByName) {
  test::TempDir dir;
  const std::string path = dir.write("x.mcap", "{\"not\": \"mcap\"}");
  try {
    mcap::read_file(path);
    FAIL() << "read a JSON file as MCAP";
  } catch (const mcap::McapError& e) {
    EXPECT_NE(std::string(e.what()).find("not an MCAP file"), std::string::npos) << e.what();
  }
  EXPECT_THROW(mcap::Writer(dir.file("no/such/folder/a.mcap"), "", "t"), mcap::McapError);
}

TEST(Recorder, EveryPostedMessageIsWrittenInOrderPerTopic) {
  test::TempDir dir;
  const std::string path = dir.file("r.mcap");
  auto topic_of = [](int i) { return i % 2 ? Topic::Haptic : Topic::Input; };
  {
    Recorder rec(path, {{"scene_name", "block"}}, {.chunk_bytes = 4096, .chunk_seconds = 0.25});
    for (int i = 0; i < 3000; ++i)
      ASSERT_TRUE(rec.post(topic_of(i), 1'000'000 + i, i % 2 ? 500 + i : 0, envelope(topic_of(i), i)));
    rec.stop();
    rec.wait();
    const RecorderStats st = rec.stats();
    EXPECT_TRUE(st.finished);
    EXPECT_EQ(st.messages, 3000u);
    EXPECT_EQ(st.late, 0u);
    EXPECT_TRUE(st.fault.empty()) << st.fault;
    EXPECT_FALSE(rec.post(Topic::Input, 0, 0, envelope(Topic::Input, 0)));  // stopped: takes no more
  }
  mcap::Recording r = mcap::read_file(path);
  ASSERT_TRUE(r.complete);
  ASSERT_EQ(r.messages.size(), 3000u);
  EXPECT_GT(r.chunks, 10u);  // closed by size
  const uint16_t haptic = r.channel_of("/haptic"), input = r.channel_of("/input");
  ASSERT_NE(haptic, 0);
  ASSERT_NE(input, 0);
  EXPECT_EQ(r.channels.size(), size_t(kTopicCount) + 4);  // and /foxglove/body, /surface, /log, /transform
  EXPECT_EQ(r.channels.at(haptic).metadata.at("envelope_offset"), "8");
  const uint64_t offset = r.messages[0].log_time - 1'000'000;  // steady -> Unix: a constant
  EXPECT_GT(offset, uint64_t(1.6e18));
  // As written: each message is its type's root (what Foxglove reads), behind
  // which the Envelope sits whole.
  for (int i = 0; i < 3000; ++i) {
    const mcap::Message& m = r.messages[size_t(i)];
    ASSERT_EQ(m.channel, i % 2 ? haptic : input);
    EXPECT_EQ(m.log_time, offset + uint64_t(1'000'000 + i));
    EXPECT_EQ(m.publish_time, i % 2 ? offset + uint64_t(500 + i) : m.log_time);
    ASSERT_GT(m.data.size(), kEnvelopeOffset);
    EXPECT_EQ(std::string(m.data.begin() + 4, m.data.begin() + 8), "TCTL");
    if (i % 2) {
      flatbuffers::Verifier v(m.data.data(), m.data.size());
      ASSERT_TRUE(v.VerifyBuffer<proto::HapticFrame>(nullptr)) << "message " << i;
      EXPECT_EQ(flatbuffers::GetRoot<proto::HapticFrame>(m.data.data())->step(), uint64_t(i));
    } else {
      flatbuffers::Verifier v(m.data.data(), m.data.size());
      ASSERT_TRUE(v.VerifyBuffer<proto::DeviceInput>(nullptr)) << "message " << i;
      EXPECT_EQ(flatbuffers::GetRoot<proto::DeviceInput>(m.data.data())->sequence(), uint64_t(i));
    }
  }
  // Read back as Envelopes: the bytes posted.
  restore_envelopes(r);
  for (int i = 0; i < 3000; ++i) EXPECT_EQ(r.messages[size_t(i)].data, envelope(topic_of(i), i)) << "message " << i;
  ASSERT_EQ(r.metadata.size(), 1u);
  EXPECT_EQ(r.metadata[0].second.at("scene_name"), "block");
  EXPECT_EQ(r.metadata[0].second.count("started_unix_ns"), 1u);
}

TEST(Recorder, MessagesPostedOutOfOrderAreWrittenInLogTimeOrder) {
  test::TempDir dir;
  const std::string path = dir.file("r.mcap");
  {
    Recorder rec(path, {}, {.chunk_bytes = 4096, .chunk_seconds = 0.25});
    // Two sources stamped 30 ms apart, as frames and network messages come
    // under load, stamped from now on (the live recorder holds a message
    // until the clock is 0.2 s past it).
    const int64_t now =
        std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
            .count();
    for (int i = 0; i < 1000; ++i) {
      const int64_t t = now + int64_t(i) * 100'000;
      ASSERT_TRUE(rec.post(Topic::Haptic, t, 0, envelope(Topic::Haptic, i)));
      ASSERT_TRUE(rec.post(Topic::Input, t - 30'000'000, 0, envelope(Topic::Input, i)));
    }
    rec.stop();
    rec.wait();
    EXPECT_EQ(rec.stats().late, 0u);
  }
  const mcap::Recording r = mcap::read_file(path);
  ASSERT_EQ(r.messages.size(), 2000u);
  for (size_t k = 1; k < r.messages.size(); ++k)
    ASSERT_LE(r.messages[k - 1].log_time, r.messages[k].log_time) << "message " << k;
}

TEST(Recorder, BytesThatAreNoEnvelopeAreLeftOutAndCounted) {
  test::TempDir dir;
  const std::string path = dir.file("r.mcap");
  Recorder rec(path, {}, {});
  ASSERT_TRUE(rec.post(Topic::Haptic, 1, 0, payload(3)));
  ASSERT_TRUE(rec.post(Topic::Haptic, 2, 0, envelope(Topic::Haptic, 2)));
  rec.stop();
  rec.wait();
  EXPECT_EQ(rec.stats().unreadable, 1u);
  EXPECT_EQ(mcap::read_file(path).messages.size(), 1u);
}

TEST(Recorder, AChunkClosesWithinItsTimeEvenWhenTheSessionIsQuiet) {
  test::TempDir dir;
  const std::string path = dir.file("r.mcap");
  Recorder rec(path, {}, {.chunk_bytes = 1 << 20, .chunk_seconds = 0.05});
  ASSERT_TRUE(rec.post(Topic::Telemetry, 1, 0, envelope(Topic::Telemetry, 1)));
  // Without a footer yet, the file already holds the message once its chunk
  // has closed by time (a kill now would keep it).
  mcap::Recording r;
  for (int i = 0; i < 200 && r.messages.empty(); ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    r = mcap::read_file(path);
  }
  ASSERT_EQ(r.messages.size(), 1u);
  EXPECT_FALSE(r.complete);
  rec.stop();
  rec.wait();
  EXPECT_TRUE(mcap::read_file(path).complete);
}

TEST(Recorder, AQueueOverItsBoundIsAFaultAndTheFileStaysReadable) {
  test::TempDir dir;
  const std::string path = dir.file("r.mcap");
  Recorder rec(path, {}, {.chunk_bytes = 1 << 20, .chunk_seconds = 0.25, .queue_bytes = 64 << 10});
  const std::vector<uint8_t> big = envelope(Topic::State, 0, 4 << 10);
  int accepted = 0;
  for (int i = 0; i < 1000; ++i)
    if (rec.post(Topic::State, i, 0, big))
      ++accepted;
    else
      break;
  rec.wait();
  const RecorderStats st = rec.stats();
  EXPECT_LT(accepted, 1000);
  EXPECT_NE(st.fault.find("could not keep up"), std::string::npos) << st.fault;
  EXPECT_TRUE(st.finished);
  const mcap::Recording r = mcap::read_file(path);
  EXPECT_TRUE(r.complete);
  EXPECT_EQ(r.messages.size(), size_t(accepted));
}

}  // namespace
}  // namespace tactile

namespace tactile {
namespace {

// RFC 4648's test vectors, both ways; text that is not base64 gives nothing.
TEST(Base64, RoundTripsTheRfcVectorsAndRefusesWhatIsNotBase64) {
  const std::pair<std::string, std::string> vectors[] = {{"", ""},
                                                         {"f", "Zg=="},
                                                         {"fo", "Zm8="},
                                                         {"foo", "Zm9v"},
                                                         {"foob", "Zm9vYg=="},
                                                         {"fooba", "Zm9vYmE="},
                                                         {"foobar", "Zm9vYmFy"}};
  for (const auto& [plain, coded] : vectors) {
    const std::vector<uint8_t> bytes(plain.begin(), plain.end());
    EXPECT_EQ(to_base64(bytes), coded);
    EXPECT_EQ(from_base64(coded), bytes) << coded;
  }
  std::vector<uint8_t> all(256);
  for (size_t k = 0; k < all.size(); ++k) all[k] = uint8_t(k);
  EXPECT_EQ(from_base64(to_base64(all)), all);
  EXPECT_TRUE(from_base64("Zm9").empty());   // not a multiple of 4
  EXPECT_TRUE(from_base64("Zm9*").empty());  // not in the alphabet
  EXPECT_TRUE(from_base64("Z=9v").empty());  // padding inside
}

}  // namespace
}  // namespace tactile
