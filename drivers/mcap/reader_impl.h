// Internal to drivers/mcap: the reader's state, shared by reader_open.cc (Open(): the header,
// the summary, the linear read of the data section) and reader.cc (the iteration, the API).
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "drivers/mcap/mcap_reader.h"
#include "drivers/mcap/records.h"
#include "drivers/mcap/source.h"

namespace stevi::mcap {
namespace internal {

inline std::string Str(uint64_t v) { return std::to_string(v); }
inline bool Is(uint8_t opcode, Opcode op) { return opcode == static_cast<uint8_t>(op); }

// How the linear read of a data section ended.
struct ScanEnd {
  enum class Kind {
    kLimit,      // at the end of the range, between two records
    kDataEnd,    // at a Data End record (whose CRC held)
    kFooter,     // at a Footer record, without Data End
    kCutHeader,  // fewer than 9 bytes left
    kCutRecord,  // a record longer than the bytes left
    kDamaged,    // a record that does not parse, decompress or check
  };
  Kind kind = Kind::kLimit;
  uint64_t at = 0;  // where the record it stopped at starts (the end of what was kept)
  uint8_t opcode = 0;
  uint64_t record_bytes = 0;  // kCutRecord: its content length, as its header says
  std::string problem;        // kDamaged
};

}  // namespace internal

struct Reader::Impl {
  std::string name;
  ReaderOptions options;
  std::unique_ptr<internal::Source> source;

  Header header;
  std::map<uint16_t, Schema> schemas;
  std::map<uint16_t, Channel> channels;
  std::optional<Statistics> statistics;
  std::vector<ChunkIndex> chunk_indexes;
  std::vector<uint64_t> chunk_index_at;  // where each Chunk Index record is
  std::vector<internal::AttachmentIndex> attachment_indexes;
  std::vector<internal::MetadataIndex> metadata_indexes;
  std::vector<Metadata> metadata;
  std::vector<Attachment> attachments;
  bool indexed = false;
  std::string note;
  uint64_t recovered_messages = 0;
  uint64_t recovered_chunks = 0;
  uint64_t data_start = 0;    // the first record after the Header
  uint64_t data_end = 0;      // where the records to iterate end
  uint32_t data_end_crc = 0;  // an indexed file's Data End CRC

  // Open()'s linear read: the CRC of bytes [0, crc_pos), and what it saw where.
  uint64_t crc_pos = 0;
  uint32_t crc = 0;
  std::string scratch;
  std::string decoded;
  std::map<uint64_t, ChunkIndex> seen_chunks;     // by offset (no message index fields)
  std::map<uint64_t, uint64_t> seen_attachments;  // offset -> record length
  std::map<uint64_t, uint64_t> seen_metadata;

  // Next()'s position: in the data section, and inside the current chunk's records.
  uint64_t pos = 0;
  std::string iter_head;
  std::string iter_raw;
  std::string iter_decoded;
  std::string_view records;
  uint64_t record_pos = 0;
  uint64_t chunk_at = 0;
  std::optional<Error> iter_error;

  // kInvalidArgument: "NAME: byte AT: PROBLEM".
  Error Bad(uint64_t at, const std::string& problem) const {
    return InvalidArgument(name + ": byte " + internal::Str(at) + ": " + problem);
  }
  Status Load();
  Status LoadHeader(bool& cut);
  Result<bool> LoadSummary(std::string& why);
  Status SummaryRecord(uint64_t at, const internal::RecordView& record, uint64_t summary_start,
                       uint64_t group_limit);
  Status Scan(uint64_t limit, bool strict, internal::ScanEnd& end);
  Status ScanRecord(uint64_t at, uint8_t opcode, uint64_t length, bool strict);
  Status ScanChunk(uint64_t at, std::string_view content, bool decode);
  Status CheckIndexes() const;
  // note() for a file read linearly: why it has no summary, and how the read in `end` ended.
  void ComposeNote(const std::string& why, const internal::ScanEnd& end);
  // Reads [at, at + n) for the CRC (which must have reached `at`), returning it.
  Result<std::string_view> Take(uint64_t at, uint64_t n);
  // Streams [at, at + n) through the CRC without keeping it.
  Status Skip(uint64_t at, uint64_t n);
  // A Schema or Channel record: added to the tables, or refused when it contradicts one with the
  // same id. A Message: returned when its channel is known. Others: nothing.
  Result<std::optional<Message>> Interpret(uint8_t opcode, std::string_view content);
  Result<std::optional<Message>> NextMessage();
  Result<std::optional<Message>> NextInChunk();
};

}  // namespace stevi::mcap
