// MCAP (https://mcap.dev/spec), the recording format: a writer that closes
// chunks into the file as it goes, so that a process killed mid-recording
// leaves every chunk it closed readable, and a reader that reads such a
// file in order up to where it was cut, checking every chunk's CRC.
//
// Only what recordings use: one profile, schemas, channels, messages in
// chunks (zstd-compressed or not) with their message indexes, metadata, and
// the summary a closed file ends with (statistics, chunk and metadata
// indexes, summary offsets). No C++ MCAP library is packaged for Debian 12; the files are
// checked against the reference readers (`mcap` on PyPI, `@mcap/core` on
// npm) in tests/test_recording.py.
#pragma once

#include <cstdint>
#include <map>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

struct ZSTD_CCtx_s;  // zstd.h's compression context

namespace tactile::mcap {

struct McapError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

using Map = std::map<std::string, std::string>;

// How a chunk's records are stored: as they are, or compressed with zstd
// (what Foxglove recommends for MCAP files; every MCAP reader reads it).
enum class Compression { None, Zstd };

// Writes one file. Not thread-safe: one thread writes.
class Writer {
 public:
  // Creates (or truncates) `path` and writes the magic and header; throws
  // McapError naming the path and the reason.
  Writer(const std::string& path, const std::string& profile, const std::string& library,
         Compression compression = Compression::None);
  ~Writer();  // finish()es a file not yet finished, ignoring errors
  Writer(const Writer&) = delete;
  Writer& operator=(const Writer&) = delete;

  // Written at once, outside chunks (so that a reader has them before any
  // message), and again in the summary. Ids count from 1.
  uint16_t add_schema(const std::string& name, const std::string& encoding, std::span<const uint8_t> data);
  uint16_t add_channel(uint16_t schema, const std::string& topic, const std::string& message_encoding,
                       const Map& metadata = {});
  void add_metadata(const std::string& name, const Map& metadata);

  // Appends a message to the open chunk (sequence: per channel, from 0):
  // the bytes of `prefix`, then those of `data`.
  void write(uint16_t channel, uint64_t log_time, uint64_t publish_time, std::span<const uint8_t> data,
             std::span<const uint8_t> prefix = {});

  // Writes the open chunk (compressed as the writer was made to) and its
  // message indexes to the file (one write call), if it holds any message.
  void close_chunk();
  size_t chunk_bytes() const { return chunk_.size(); }
  bool chunk_empty() const { return chunk_messages_ == 0; }

  // Closes the chunk, then writes the data end, the summary and the footer.
  void finish();
  bool finished() const { return fd_ < 0; }

  uint64_t messages() const { return message_count_; }
  uint64_t bytes() const { return offset_ + chunk_.size(); }  // in the file, and in the open chunk
  uint64_t records_bytes() const { return records_bytes_; }   // of the closed chunks' records, uncompressed

 private:
  struct ChannelInfo {
    uint16_t id, schema;
    std::string topic, encoding;
    Map metadata;
    uint32_t sequence = 0;
    uint64_t count = 0;
    std::vector<std::pair<uint64_t, uint64_t>> index;  // (log time, offset in the chunk) in the open chunk
  };
  struct SchemaInfo {
    uint16_t id;
    std::string name, encoding;
    std::vector<uint8_t> data;
  };
  struct ChunkIndex {
    uint64_t start_time, end_time, offset, length;
    std::map<uint16_t, uint64_t> index_offsets;
    uint64_t index_length, records_size, stored_size;  // the records uncompressed, and as stored
  };
  struct MetadataIndex {
    uint64_t offset, length;
    std::string name;
  };
  void emit(const std::vector<uint8_t>& bytes);  // to the file, counting its CRC and offset
  static void put(std::vector<uint8_t>& b, const SchemaInfo& s);
  static void put(std::vector<uint8_t>& b, const ChannelInfo& c);

  int fd_ = -1;
  std::string path_;
  uint64_t offset_ = 0;
  uint32_t data_crc_ = 0;
  std::vector<SchemaInfo> schemas_;
  std::vector<ChannelInfo> channels_;
  std::vector<ChunkIndex> chunk_indexes_;
  std::vector<MetadataIndex> metadata_indexes_;
  std::vector<uint8_t> chunk_;  // records of the open chunk
  uint64_t chunk_messages_ = 0, chunk_start_ = 0, chunk_end_ = 0;
  uint64_t message_count_ = 0, first_time_ = UINT64_MAX, last_time_ = 0;
  std::vector<uint8_t> out_;  // staging for one write
  Compression compression_;
  ZSTD_CCtx_s* zstd_ = nullptr;  // reused for every chunk
  std::vector<uint8_t> packed_;  // a chunk's records, compressed
  uint64_t records_bytes_ = 0;
};

// ---- reading ----------------------------------------------------------------------

struct Message {
  uint16_t channel;
  uint32_t sequence;
  uint64_t log_time, publish_time;
  std::vector<uint8_t> data;
};

struct Channel {
  uint16_t id, schema;
  std::string topic, encoding;
  Map metadata;
};

// A whole file read in order, its chunks uncompressed or zstd-compressed.
// A file cut short (no footer) reads up to its last complete record; a
// chunk whose CRC does not match, that does not decompress, or that is
// compressed another way (lz4) is skipped. All are reported in `problems`,
// never thrown, each naming the chunk and why; a file that is not MCAP at
// all throws McapError.
struct Recording {
  std::string profile, library;
  std::map<uint16_t, Channel> channels;
  std::vector<std::pair<std::string, Map>> metadata;
  std::vector<Message> messages;  // in file order
  bool complete = false;          // read through its footer
  std::vector<std::string> problems;
  uint64_t chunks = 0;

  // The channel id of `topic`, or 0 when the file has none.
  uint16_t channel_of(const std::string& topic) const;
};
Recording read_file(const std::string& path);

}  // namespace tactile::mcap
