// Internal to drivers/mcap: each record's bytes (field order is the wire order, spec §Records),
// written and parsed. Parsers take a record's content (the bytes after its opcode and length),
// check every length against it, ignore fields appended by later spec versions, and return
// kInvalidArgument naming the record and field; the caller adds the file and the byte offset.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "core/common/error.h"
#include "drivers/mcap/mcap_format.h"

namespace stevi::mcap::internal {

// Opcode (1) and content length (8).
inline constexpr uint64_t kRecordPrefixBytes = 9;
// The Footer's content is always 20 bytes, the DataEnd's 4.
inline constexpr uint64_t kFooterContentBytes = 20;
inline constexpr uint64_t kDataEndContentBytes = 4;
// A Message's fields before its data: channel_id, sequence, log_time, publish_time.
inline constexpr uint64_t kMessageFieldsBytes = 2 + 4 + 8 + 8;

struct ChunkRecord {
  uint64_t message_start_time_ns = 0;
  uint64_t message_end_time_ns = 0;
  uint64_t uncompressed_size = 0;
  uint32_t uncompressed_crc = 0;  // 0: not computed
  std::string compression;
  std::string_view records;  // as stored (compressed unless compression is "")
};

struct MessageIndex {
  uint16_t channel_id = 0;
  std::vector<std::pair<uint64_t, uint64_t>> entries;  // (log_time, offset in the records)
};

struct AttachmentIndex {
  uint64_t offset = 0;
  uint64_t length = 0;
  uint64_t log_time_ns = 0;
  uint64_t create_time_ns = 0;
  uint64_t data_size = 0;
  std::string name;
  std::string media_type;
};

struct MetadataIndex {
  uint64_t offset = 0;
  uint64_t length = 0;
  std::string name;
};

struct SummaryOffset {
  uint8_t group_opcode = 0;
  uint64_t group_start = 0;
  uint64_t group_length = 0;
};

struct Footer {
  uint64_t summary_start = 0;
  uint64_t summary_offset_start = 0;
  uint32_t summary_crc = 0;
};

// ---- Writing (each appends one whole record to `out`) -------------------------------------------

void AppendHeader(std::string& out, const Header& header);
void AppendSchema(std::string& out, const Schema& schema);
void AppendChannel(std::string& out, const Channel& channel);
void AppendMessage(std::string& out, uint16_t channel_id, uint32_t sequence, uint64_t log_time_ns,
                   uint64_t publish_time_ns, std::string_view data);
void AppendChunk(std::string& out, const ChunkRecord& chunk);
void AppendMessageIndex(std::string& out, const MessageIndex& index);
void AppendChunkIndex(std::string& out, const ChunkIndex& index);
// Computes and appends the attachment's CRC.
void AppendAttachment(std::string& out, const Attachment& attachment);
void AppendAttachmentIndex(std::string& out, const AttachmentIndex& index);
void AppendStatistics(std::string& out, const Statistics& statistics);
void AppendMetadata(std::string& out, const Metadata& metadata);
void AppendMetadataIndex(std::string& out, const MetadataIndex& index);
void AppendSummaryOffset(std::string& out, const SummaryOffset& offset);
void AppendDataEnd(std::string& out, uint32_t data_section_crc);
void AppendFooter(std::string& out, const Footer& footer);

// ---- Parsing (`content`: the bytes after the opcode and length) ---------------------------------

Result<Header> ParseHeader(std::string_view content);
// An id of 0 is returned as is: the spec says to ignore such a schema.
Result<Schema> ParseSchema(std::string_view content);
Result<Channel> ParseChannel(std::string_view content);
Result<Message> ParseMessage(std::string_view content);
// `records` points into `content`.
Result<ChunkRecord> ParseChunk(std::string_view content);
Result<MessageIndex> ParseMessageIndex(std::string_view content);
Result<ChunkIndex> ParseChunkIndex(std::string_view content);
// Checks the CRC when it is not 0.
Result<Attachment> ParseAttachment(std::string_view content);
Result<AttachmentIndex> ParseAttachmentIndex(std::string_view content);
Result<Statistics> ParseStatistics(std::string_view content);
Result<Metadata> ParseMetadata(std::string_view content);
Result<MetadataIndex> ParseMetadataIndex(std::string_view content);
Result<SummaryOffset> ParseSummaryOffset(std::string_view content);
Result<uint32_t> ParseDataEnd(std::string_view content);
Result<Footer> ParseFooter(std::string_view content);

// "Chunk", "Message Index", ... or "opcode 0x80" for one the spec does not define.
std::string OpcodeName(uint8_t opcode);

}  // namespace stevi::mcap::internal
