// The MCAP container's format (https://mcap.dev/spec, major version 0): the magic, the opcodes,
// the compressions, the limits our writer and reader keep, and the records the reader hands out.
// The writer is in mcap_writer.h, the reader in mcap_reader.h; mcap.h includes both.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <string_view>

namespace stevi::mcap {

// ---- The format ---------------------------------------------------------------------------------

// The 8 bytes an MCAP file starts and ends with: 0x89 "MCAP" '0' '\r' '\n'.
inline constexpr std::string_view kMagic{"\x89MCAP0\r\n", 8};

// Record opcodes (the spec's "op=" values).
enum class Opcode : uint8_t {
  kHeader = 0x01,
  kFooter = 0x02,
  kSchema = 0x03,
  kChannel = 0x04,
  kMessage = 0x05,
  kChunk = 0x06,
  kMessageIndex = 0x07,
  kChunkIndex = 0x08,
  kAttachment = 0x09,
  kAttachmentIndex = 0x0A,
  kStatistics = 0x0B,
  kMetadata = 0x0C,
  kMetadataIndex = 0x0D,
  kSummaryOffset = 0x0E,
  kDataEnd = 0x0F,
};

// Chunk compression.
enum class Compression { kNone, kZstd, kLz4 };
// The name in the MCAP registry: "", "zstd" or "lz4" (lz4 is the LZ4 frame format).
std::string_view CompressionName(Compression c);
// The compression called `name`; nullopt for a name outside the registry.
std::optional<Compression> CompressionFromName(std::string_view name);

// Limits that keep a damaged or hostile file from making the reader allocate absurd amounts; the
// writer stays inside them, so every file it writes is readable.
inline constexpr uint64_t kMaxChunkBytes = uint64_t{512} << 20;       // uncompressed chunk records
inline constexpr uint64_t kMaxMessageBytes = uint64_t{256} << 20;     // one message's data
inline constexpr uint64_t kMaxSchemaBytes = uint64_t{16} << 20;       // one schema's data
inline constexpr uint64_t kMaxRecordFieldsBytes = uint64_t{1} << 20;  // names, topics, maps
inline constexpr uint64_t kMaxAttachmentBytes = uint64_t{256} << 20;  // one attachment's data

// The records a reader hands out. Times are nanoseconds since the Unix epoch.
struct Header {
  std::string profile;  // "" for ours (no well-known profile)
  std::string library;  // who wrote the file
};

struct Schema {
  uint16_t id = 0;  // >= 1
  std::string name;
  std::string encoding;  // "protobuf", "jsonschema", ... ("" for none)
  std::string data;
  bool operator==(const Schema&) const = default;
};

struct Channel {
  uint16_t id = 0;
  uint16_t schema_id = 0;  // 0: no schema
  std::string topic;
  std::string message_encoding;
  std::map<std::string, std::string> metadata;
  bool operator==(const Channel&) const = default;
};

struct Message {
  uint16_t channel_id = 0;
  uint32_t sequence = 0;  // per channel, from 0, as our writer numbers them
  uint64_t log_time_ns = 0;
  uint64_t publish_time_ns = 0;
  std::string data;
  bool operator==(const Message&) const = default;
};

// Where a chunk is and what it holds (the summary's Chunk Index record).
struct ChunkIndex {
  uint64_t message_start_time_ns = 0;
  uint64_t message_end_time_ns = 0;
  uint64_t chunk_start_offset = 0;  // file offset of the Chunk record's opcode
  uint64_t chunk_length = 0;        // the whole Chunk record, opcode and length included
  std::map<uint16_t, uint64_t> message_index_offsets;  // channel -> file offset of its index
  uint64_t message_index_length = 0;  // bytes of the Message Index records after the chunk
  std::string compression;            // "", "zstd" or "lz4"
  uint64_t compressed_size = 0;       // of the chunk's records field as stored
  uint64_t uncompressed_size = 0;
  bool operator==(const ChunkIndex&) const = default;
};

// Counts and time range of a whole file (the summary's Statistics record).
struct Statistics {
  uint64_t message_count = 0;
  uint16_t schema_count = 0;
  uint32_t channel_count = 0;
  uint32_t attachment_count = 0;
  uint32_t metadata_count = 0;
  uint32_t chunk_count = 0;
  uint64_t message_start_time_ns = 0;  // 0 when there are no messages
  uint64_t message_end_time_ns = 0;
  std::map<uint16_t, uint64_t> channel_message_counts;  // channels with messages only
  bool operator==(const Statistics&) const = default;
};

// A Metadata record: a name and a string map (e.g. the calibration's numbers).
struct Metadata {
  std::string name;
  std::map<std::string, std::string> values;
};

// An Attachment record: a named file (e.g. the calibration YAML).
struct Attachment {
  uint64_t log_time_ns = 0;
  uint64_t create_time_ns = 0;  // 0: unknown
  std::string name;
  std::string media_type;  // "application/yaml", "text/plain", ...
  std::string data;
};

}  // namespace stevi::mcap
