#include "record/mcap.hpp"

#include <fcntl.h>
#include <unistd.h>
#include <zlib.h>
#include <zstd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>

namespace tactile::mcap {
namespace {

// The most a chunk may say it holds uncompressed [bytes]: the recorder's
// close at a few MiB.
constexpr uint64_t kLargestChunk = uint64_t(1) << 30;
constexpr uint8_t kMagic[8] = {0x89, 'M', 'C', 'A', 'P', '0', '\r', '\n'};

enum Op : uint8_t {
  kHeader = 0x01,
  kFooter = 0x02,
  kSchema = 0x03,
  kChannel = 0x04,
  kMessage = 0x05,
  kChunk = 0x06,
  kMessageIndex = 0x07,
  kChunkIndex = 0x08,
  kStatistics = 0x0B,
  kMetadata = 0x0C,
  kMetadataIndex = 0x0D,
  kSummaryOffset = 0x0E,
  kDataEnd = 0x0F,
};

uint32_t crc32_of(const uint8_t* p, size_t n, uint32_t crc = 0) {
  // zlib's crc32 takes a uInt length: feed it in pieces.
  while (n > 0) {
    const uInt part = uInt(std::min<size_t>(n, size_t(1) << 30));
    crc = uint32_t(::crc32(crc, p, part));
    p += part;
    n -= part;
  }
  return crc;
}

// Little-endian encoding into a byte vector.
struct Out {
  std::vector<uint8_t>& b;
  void u8(uint8_t v) { b.push_back(v); }
  void u16(uint16_t v) { put(v, 2); }
  void u32(uint32_t v) { put(v, 4); }
  void u64(uint64_t v) { put(v, 8); }
  void put(uint64_t v, int n) {
    for (int i = 0; i < n; ++i) b.push_back(uint8_t(v >> (8 * i)));
  }
  void str(const std::string& s) {
    u32(uint32_t(s.size()));
    b.insert(b.end(), s.begin(), s.end());
  }
  void bytes(std::span<const uint8_t> d) { b.insert(b.end(), d.begin(), d.end()); }
  void map(const Map& m) {
    const size_t at = begin_u32();
    for (const auto& [k, v] : m) {
      str(k);
      str(v);
    }
    end_u32(at);
  }
  // A record: opcode, then a u64 length patched when it ends.
  size_t begin_record(uint8_t op) {
    u8(op);
    const size_t at = b.size();
    u64(0);
    return at;
  }
  void end_record(size_t at) { patch(at, b.size() - at - 8, 8); }
  size_t begin_u32() {
    const size_t at = b.size();
    u32(0);
    return at;
  }
  void end_u32(size_t at) { patch(at, b.size() - at - 4, 4); }
  void patch(size_t at, uint64_t v, int n) {
    for (int i = 0; i < n; ++i) b[at + size_t(i)] = uint8_t(v >> (8 * i));
  }
};

}  // namespace

// ---- Writer -----------------------------------------------------------------------------

Writer::Writer(const std::string& path, const std::string& profile, const std::string& library, Compression compression)
    : path_(path), compression_(compression) {
  if (compression_ == Compression::Zstd && !(zstd_ = ZSTD_createCCtx()))
    throw McapError("cannot write recording '" + path + "': no memory for its compressor");
  fd_ = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd_ < 0) throw McapError("cannot write recording '" + path + "': " + std::strerror(errno));
  out_.clear();
  Out o{out_};
  for (uint8_t c : kMagic) o.u8(c);  // (not insert(): GCC 12 warns, wrongly, of an overflow)
  const size_t r = o.begin_record(kHeader);
  o.str(profile);
  o.str(library);
  o.end_record(r);
  emit(out_);
}

Writer::~Writer() {
  try {
    if (fd_ >= 0) finish();
  } catch (const McapError&) {
  }
  if (fd_ >= 0) ::close(fd_);
  ZSTD_freeCCtx(zstd_);
}

void Writer::emit(const std::vector<uint8_t>& bytes) {
  if (fd_ < 0) throw McapError("recording '" + path_ + "' is already finished");
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd_, bytes.data() + done, bytes.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      throw McapError("cannot write recording '" + path_ + "': " + std::strerror(errno));
    }
    done += size_t(n);
  }
  data_crc_ = crc32_of(bytes.data(), bytes.size(), data_crc_);
  offset_ += bytes.size();
}

// A schema's or a channel's record: written once at the start, and again in the summary.
void Writer::put(std::vector<uint8_t>& b, const SchemaInfo& s) {
  Out o{b};
  const size_t r = o.begin_record(kSchema);
  o.u16(s.id);
  o.str(s.name);
  o.str(s.encoding);
  o.u32(uint32_t(s.data.size()));
  o.bytes(s.data);
  o.end_record(r);
}
void Writer::put(std::vector<uint8_t>& b, const ChannelInfo& c) {
  Out o{b};
  const size_t r = o.begin_record(kChannel);
  o.u16(c.id);
  o.u16(c.schema);
  o.str(c.topic);
  o.str(c.encoding);
  o.map(c.metadata);
  o.end_record(r);
}

uint16_t Writer::add_schema(const std::string& name, const std::string& encoding, std::span<const uint8_t> data) {
  const uint16_t id = uint16_t(schemas_.size() + 1);
  schemas_.push_back({id, name, encoding, std::vector<uint8_t>(data.begin(), data.end())});
  out_.clear();
  put(out_, schemas_.back());
  emit(out_);
  return id;
}

uint16_t Writer::add_channel(uint16_t schema, const std::string& topic, const std::string& message_encoding,
                             const Map& metadata) {
  const uint16_t id = uint16_t(channels_.size() + 1);
  channels_.push_back({id, schema, topic, message_encoding, metadata, 0, 0, {}});
  out_.clear();
  put(out_, channels_.back());
  emit(out_);
  return id;
}

void Writer::add_metadata(const std::string& name, const Map& metadata) {
  close_chunk();  // outside chunks, in file order with the messages around it
  out_.clear();
  Out o{out_};
  const size_t r = o.begin_record(kMetadata);
  o.str(name);
  o.map(metadata);
  o.end_record(r);
  metadata_indexes_.push_back({offset_, out_.size(), name});
  emit(out_);
}

void Writer::write(uint16_t channel, uint64_t log_time, uint64_t publish_time, std::span<const uint8_t> data,
                   std::span<const uint8_t> prefix) {
  if (channel == 0 || channel > channels_.size()) throw McapError("no channel " + std::to_string(channel));
  ChannelInfo& c = channels_[channel - 1];
  c.index.emplace_back(log_time, chunk_.size());
  Out o{chunk_};
  const size_t r = o.begin_record(kMessage);
  o.u16(channel);
  o.u32(c.sequence++);
  o.u64(log_time);
  o.u64(publish_time);
  o.bytes(prefix);
  o.bytes(data);
  o.end_record(r);
  ++c.count;
  if (chunk_messages_++ == 0) chunk_start_ = chunk_end_ = log_time;
  chunk_start_ = std::min(chunk_start_, log_time);
  chunk_end_ = std::max(chunk_end_, log_time);
  ++message_count_;
  first_time_ = std::min(first_time_, log_time);
  last_time_ = std::max(last_time_, log_time);
}

void Writer::close_chunk() {
  if (chunk_messages_ == 0) return;
  out_.clear();
  Out o{out_};
  const uint64_t chunk_offset = offset_;
  std::span<const uint8_t> stored = chunk_;
  if (compression_ == Compression::Zstd) {
    // Level 3, zstd's default: higher levels barely shrink our chunks and
    // cost more (docs/perf.md, "Recordings"; server/bench/recording_bench.py).
    packed_.resize(ZSTD_compressBound(chunk_.size()));
    const size_t n = ZSTD_compressCCtx(zstd_, packed_.data(), packed_.size(), chunk_.data(), chunk_.size(), 3);
    if (ZSTD_isError(n))
      throw McapError("cannot compress a chunk of recording '" + path_ + "': " + ZSTD_getErrorName(n));
    stored = {packed_.data(), n};
  }
  const size_t r = o.begin_record(kChunk);
  o.u64(chunk_start_);
  o.u64(chunk_end_);
  o.u64(chunk_.size());                           // uncompressed size
  o.u32(crc32_of(chunk_.data(), chunk_.size()));  // uncompressed CRC
  o.str(compression_ == Compression::Zstd ? "zstd" : "");
  o.u64(stored.size());
  o.bytes(stored);
  o.end_record(r);
  ChunkIndex ci{chunk_start_, chunk_end_, chunk_offset, out_.size(), {}, 0, chunk_.size(), stored.size()};
  const size_t index_start = out_.size();
  for (ChannelInfo& c : channels_) {
    if (c.index.empty()) continue;
    ci.index_offsets[c.id] = chunk_offset + out_.size();
    const size_t m = o.begin_record(kMessageIndex);
    o.u16(c.id);
    const size_t a = o.begin_u32();
    for (const auto& [t, off] : c.index) {
      o.u64(t);
      o.u64(off);
    }
    o.end_u32(a);
    o.end_record(m);
    c.index.clear();
  }
  ci.index_length = out_.size() - index_start;
  emit(out_);  // one write: the chunk is in the file, or not at all
  chunk_indexes_.push_back(std::move(ci));
  records_bytes_ += chunk_.size();
  chunk_.clear();
  chunk_messages_ = 0;
}

void Writer::finish() {
  if (fd_ < 0) return;
  close_chunk();
  out_.clear();
  Out o{out_};
  size_t r = o.begin_record(kDataEnd);
  o.u32(data_crc_);  // of everything before this record
  o.end_record(r);
  const uint64_t summary_start = offset_ + out_.size();
  struct Group {
    uint8_t op;
    uint64_t start, length;
  };
  std::vector<Group> groups;
  auto group = [&](uint8_t op, auto&& body) {
    const uint64_t start = offset_ + out_.size();
    body();
    const uint64_t length = offset_ + out_.size() - start;
    if (length > 0) groups.push_back({op, start, length});
  };
  group(kSchema, [&] {
    for (const SchemaInfo& s : schemas_) put(out_, s);
  });
  group(kChannel, [&] {
    for (const ChannelInfo& c : channels_) put(out_, c);
  });
  group(kStatistics, [&] {
    const size_t q = o.begin_record(kStatistics);
    o.u64(message_count_);
    o.u16(uint16_t(schemas_.size()));
    o.u32(uint32_t(channels_.size()));
    o.u32(0);  // attachments
    o.u32(uint32_t(metadata_indexes_.size()));
    o.u32(uint32_t(chunk_indexes_.size()));
    o.u64(message_count_ ? first_time_ : 0);
    o.u64(message_count_ ? last_time_ : 0);
    const size_t a = o.begin_u32();
    for (const ChannelInfo& c : channels_) {
      o.u16(c.id);
      o.u64(c.count);
    }
    o.end_u32(a);
    o.end_record(q);
  });
  group(kChunkIndex, [&] {
    for (const ChunkIndex& ci : chunk_indexes_) {
      const size_t q = o.begin_record(kChunkIndex);
      o.u64(ci.start_time);
      o.u64(ci.end_time);
      o.u64(ci.offset);
      o.u64(ci.length);
      const size_t a = o.begin_u32();
      for (const auto& [id, off] : ci.index_offsets) {
        o.u16(id);
        o.u64(off);
      }
      o.end_u32(a);
      o.u64(ci.index_length);
      o.str(compression_ == Compression::Zstd ? "zstd" : "");
      o.u64(ci.stored_size);
      o.u64(ci.records_size);
      o.end_record(q);
    }
  });
  group(kMetadataIndex, [&] {
    for (const MetadataIndex& mi : metadata_indexes_) {
      const size_t q = o.begin_record(kMetadataIndex);
      o.u64(mi.offset);
      o.u64(mi.length);
      o.str(mi.name);
      o.end_record(q);
    }
  });
  const uint64_t summary_offset_start = offset_ + out_.size();
  for (const Group& g : groups) {
    const size_t q = o.begin_record(kSummaryOffset);
    o.u8(g.op);
    o.u64(g.start);
    o.u64(g.length);
    o.end_record(q);
  }
  o.u8(kFooter);
  o.u64(20);  // its fixed length, written before the CRC that covers it
  o.u64(summary_start);
  o.u64(summary_offset_start);
  // CRC of the summary section through the footer's summary_offset_start.
  const size_t summary_from = size_t(summary_start - offset_);
  o.u32(crc32_of(out_.data() + summary_from, out_.size() - summary_from));
  for (uint8_t c : kMagic) o.u8(c);
  emit(out_);
  ::fsync(fd_);
  ::close(fd_);
  fd_ = -1;
}

// ---- reading ------------------------------------------------------------------------------

namespace {

// Little-endian reads from a span; `ok` turns false on reading past its end.
struct In {
  const uint8_t* p;
  size_t n, at = 0;
  bool ok = true;
  bool need(size_t k) {
    if (!ok || n - at < k) ok = false;
    return ok;
  }
  uint64_t get(int k) {
    if (!need(size_t(k))) return 0;
    uint64_t v = 0;
    for (int i = 0; i < k; ++i) v |= uint64_t(p[at + size_t(i)]) << (8 * i);
    at += size_t(k);
    return v;
  }
  uint8_t u8() { return uint8_t(get(1)); }
  uint16_t u16() { return uint16_t(get(2)); }
  uint32_t u32() { return uint32_t(get(4)); }
  uint64_t u64() { return get(8); }
  std::string str() {
    const uint32_t k = u32();
    if (!need(k)) return {};
    std::string s(reinterpret_cast<const char*>(p + at), k);
    at += k;
    return s;
  }
  Map map() {
    Map m;
    const uint32_t k = u32();
    if (!need(k)) return m;
    const size_t end = at + k;
    while (ok && at < end) {
      std::string key = str();
      m[key] = str();
    }
    return m;
  }
};

void read_records(Recording& rec, const uint8_t* p, size_t n, uint64_t base, bool in_chunk);

// One record's content: adds what it holds to `rec`.
void read_record(Recording& rec, uint8_t op, In in, uint64_t at) {
  switch (op) {
    case kHeader:
      rec.profile = in.str();
      rec.library = in.str();
      break;
    case kChannel: {
      Channel c;
      c.id = in.u16();
      c.schema = in.u16();
      c.topic = in.str();
      c.encoding = in.str();
      c.metadata = in.map();
      if (in.ok) rec.channels[c.id] = std::move(c);
      break;
    }
    case kMessage: {
      Message m;
      m.channel = in.u16();
      m.sequence = in.u32();
      m.log_time = in.u64();
      m.publish_time = in.u64();
      if (!in.ok) break;
      m.data.assign(in.p + in.at, in.p + in.n);
      rec.messages.push_back(std::move(m));
      break;
    }
    case kChunk: {
      in.u64();
      in.u64();
      const uint64_t size = in.u64();
      const uint32_t crc = in.u32();
      const std::string compression = in.str();
      const uint64_t length = in.u64();
      if (!in.ok || !in.need(size_t(length))) break;
      ++rec.chunks;
      const std::string where = "chunk at byte " + std::to_string(at);
      const uint8_t* data = in.p + in.at;
      std::vector<uint8_t> unpacked;
      if (compression == "zstd") {
        // (A size no chunk of ours comes near is damage, not a chunk to make room for.)
        if (size > kLargestChunk) {
          rec.problems.push_back(where + " says it holds " + std::to_string(size) + " bytes: skipped");
          break;
        }
        unpacked.resize(size_t(size));
        const size_t got = ZSTD_decompress(unpacked.data(), unpacked.size(), data, size_t(length));
        if (ZSTD_isError(got) || got != size) {
          rec.problems.push_back(where + " does not decompress (zstd: " +
                                 (ZSTD_isError(got) ? ZSTD_getErrorName(got) : "a size other than it says") +
                                 "): skipped");
          break;
        }
        data = unpacked.data();
      } else if (!compression.empty()) {
        rec.problems.push_back(where + " is compressed with '" + compression +
                               "', which this reader does not read (it reads zstd and uncompressed chunks): skipped");
        break;
      } else if (length != size) {
        rec.problems.push_back(where + " fails its CRC: skipped");
        break;
      }
      if (crc != 0 && crc32_of(data, size_t(size)) != crc) {
        rec.problems.push_back(where + " fails its CRC: skipped");
        break;
      }
      read_records(rec, data, size_t(size), at, true);
      break;
    }
    case kMetadata: {
      std::string name = in.str();
      Map m = in.map();
      if (in.ok) rec.metadata.emplace_back(std::move(name), std::move(m));
      break;
    }
    case kFooter: rec.complete = true; break;
    default: break;  // schemas, indexes, statistics: this reader does not need them
  }
}

void read_records(Recording& rec, const uint8_t* p, size_t n, uint64_t base, bool in_chunk) {
  size_t at = 0;
  while (at < n) {
    if (n - at < 9) {
      rec.problems.push_back((in_chunk ? "chunk at byte " + std::to_string(base) + ": a record is cut short"
                                       : "the file ends inside a record at byte " + std::to_string(base + at)));
      return;
    }
    const uint8_t op = p[at];
    uint64_t len = 0;
    for (int i = 0; i < 8; ++i) len |= uint64_t(p[at + 1 + size_t(i)]) << (8 * i);
    if (len > n - at - 9) {
      rec.problems.push_back(in_chunk ? "chunk at byte " + std::to_string(base) + ": a record is cut short"
                                      : "the file ends inside a record at byte " + std::to_string(base + at) +
                                            " (cut short: a recorder that was killed)");
      return;
    }
    read_record(rec, op, In{p + at + 9, size_t(len)}, base + at);
    at += 9 + size_t(len);
    if (!in_chunk && op == kFooter) return;
  }
}

}  // namespace

uint16_t Recording::channel_of(const std::string& topic) const {
  for (const auto& [id, c] : channels)
    if (c.topic == topic) return id;
  return 0;
}

Recording read_file(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    throw McapError("cannot read recording '" + path +
                    "': " + (std::filesystem::exists(path, ec) ? "not a file" : "no such file"));
  std::ifstream f(path, std::ios::binary);
  if (!f) throw McapError("cannot read recording '" + path + "'");
  const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  if (bytes.size() < 8 || std::memcmp(bytes.data(), kMagic, 8) != 0)
    throw McapError("'" + path + "' is not an MCAP file (no MCAP magic at its start)");
  Recording rec;
  read_records(rec, bytes.data() + 8, bytes.size() - 8, 8, false);
  if (rec.complete && (bytes.size() < 16 || std::memcmp(bytes.data() + bytes.size() - 8, kMagic, 8) != 0)) {
    rec.complete = false;
    rec.problems.push_back("the file ends after its footer without the closing magic (cut short)");
  }
  if (!rec.complete && rec.problems.empty())
    rec.problems.push_back("the file ends without a footer (cut short: a recorder that was killed)");
  return rec;
}

}  // namespace tactile::mcap
