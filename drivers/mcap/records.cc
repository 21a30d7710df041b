#include "drivers/mcap/records.h"

#include <cstdio>

#include "drivers/mcap/codec.h"

namespace stevi::mcap::internal {
namespace {

// Each record's field table, the one place that says how it goes on the wire (spec §Records):
//
//   struct XTable {
//     static constexpr Opcode kOpcode = ...;  // OpcodeName(kOpcode) names it in the problems
//     template <class Self, class V>
//     static void Fields(Self& r, V& v) { v.U64(r.member, "spec_field_name"); ... }
//   };
//
// in wire order. Self is the record or the const record; V is FieldWriter (Append) or FieldReader
// (Parse), with one method a wire type. The member's C++ type is the one the record keeps; the
// visitor method names the wire type, as the spec does. The fields that are more than a number
// are visitor methods too, each written once for both directions: maps and the Message Index's
// array (u32 byte length, checked against the record), u64-prefixed byte blobs (a Chunk's records,
// an Attachment's data), a Message's data (the rest of the record) and the Attachment's CRC over
// the fields before it (FieldsCrc). A chunk's records stay as stored here: the reader decompresses
// and walks them (reader.cc). Parse reads the table's fields and ignores any bytes after them
// (fields of later spec versions).

// Appends each field with an Encoder.
class FieldWriter {
 public:
  // `fields_start`: where the record's fields start in `out` (after the opcode and length).
  FieldWriter(std::string& out, size_t fields_start) : e_(out), out_(out), start_(fields_start) {}

  void U8(uint8_t v, const char*) { e_.U8(v); }
  void U16(uint16_t v, const char*) { e_.U16(v); }
  void U32(uint32_t v, const char*) { e_.U32(v); }
  void U64(uint64_t v, const char*) { e_.U64(v); }
  // u32-prefixed bytes (a string, or a Schema's data).
  void String(std::string_view v, const char*) { e_.String(v); }
  void StringMap(const std::map<std::string, std::string>& v, const char*) { e_.StringMap(v); }
  void U16U64Map(const std::map<uint16_t, uint64_t>& v, const char*) { e_.U16U64Map(v); }
  void U64PairArray(const std::vector<std::pair<uint64_t, uint64_t>>& v, const char*) {
    e_.U64PairArray(v);
  }
  // u64 byte length + bytes.
  void U64Bytes(std::string_view v, const char*) {
    e_.U64(v.size());
    e_.Raw(v);
  }
  // The record's last field: bytes up to its end, with no prefix.
  void RestBytes(std::string_view v, const char*) { e_.Raw(v); }
  // A u32 CRC-32 of the fields before it (not the opcode and length).
  void FieldsCrc(const char*) { e_.U32(Crc32(std::string_view(out_).substr(start_))); }

 private:
  Encoder e_;
  std::string& out_;
  size_t start_;
};

// Reads each field with a Decoder: the first problem sticks and names the field.
class FieldReader {
 public:
  explicit FieldReader(std::string_view content) : d_(content), content_(content) {}

  void U8(uint8_t& v, const char* field) { v = d_.U8(field); }
  void U16(uint16_t& v, const char* field) { v = d_.U16(field); }
  void U32(uint32_t& v, const char* field) { v = d_.U32(field); }
  void U64(uint64_t& v, const char* field) { v = d_.U64(field); }
  void String(std::string& v, const char* field) { v = d_.String(field); }
  void StringMap(std::map<std::string, std::string>& v, const char* field) {
    v = d_.StringMap(field);
  }
  void U16U64Map(std::map<uint16_t, uint64_t>& v, const char* field) { v = d_.U16U64Map(field); }
  void U64PairArray(std::vector<std::pair<uint64_t, uint64_t>>& v, const char* field) {
    v = d_.U64PairArray(field);
  }
  // Into a std::string (a copy) or a std::string_view (into the content).
  template <class Bytes>
  void U64Bytes(Bytes& v, const char* field) {
    const uint64_t n = d_.U64(field);
    v = Bytes(d_.View(n, field));
  }
  void RestBytes(std::string& v, const char*) { v = std::string(d_.Rest()); }
  // Checked when the record's CRC is not 0 (0: not computed).
  void FieldsCrc(const char* field);

  const Decoder& decoder() const { return d_; }

 private:
  Decoder d_;
  std::string_view content_;
};

void FieldReader::FieldsCrc(const char* field) {
  const uint64_t covered = d_.position();
  const uint32_t crc = d_.U32(field);
  if (!d_.ok() || crc == 0) return;
  const uint32_t actual = Crc32(content_.substr(0, covered));
  if (actual == crc) return;
  char text[96];
  std::snprintf(text, sizeof(text), "%s: the record says 0x%08X, its fields give 0x%08X", field,
                crc, actual);
  d_.Fail(text);
}

// One whole record: the opcode, the length and the fields of `Table`.
template <class Table, class Record>
void Append(std::string& out, const Record& record) {
  Encoder e(out);
  const size_t start = e.BeginRecord(Table::kOpcode);
  FieldWriter writer(out, start + kRecordPrefixBytes);
  Table::Fields(record, writer);
  e.EndRecord(start);
}

// The record from its content, or the first problem under the record's name.
template <class Table, class Record>
Result<Record> Parse(std::string_view content) {
  FieldReader reader(content);
  Record record;
  Table::Fields(record, reader);
  const Decoder& d = reader.decoder();
  if (!d.ok()) {
    return InvalidArgument(OpcodeName(static_cast<uint8_t>(Table::kOpcode)) + ": " + d.problem());
  }
  return record;
}

// ---- The field tables ---------------------------------------------------------------------------

struct HeaderTable {
  static constexpr Opcode kOpcode = Opcode::kHeader;
  template <class Self, class V>
  static void Fields(Self& r, V& v) {
    v.String(r.profile, "profile");
    v.String(r.library, "library");
  }
};

struct SchemaTable {
  static constexpr Opcode kOpcode = Opcode::kSchema;
  template <class Self, class V>
  static void Fields(Self& r, V& v) {
    v.U16(r.id, "id");
    v.String(r.name, "name");
    v.String(r.encoding, "encoding");
    v.String(r.data, "data");  // u32-prefixed bytes, like a string
  }
};

struct ChannelTable {
  static constexpr Opcode kOpcode = Opcode::kChannel;
  template <class Self, class V>
  static void Fields(Self& r, V& v) {
    v.U16(r.id, "id");
    v.U16(r.schema_id, "schema_id");
    v.String(r.topic, "topic");
    v.String(r.message_encoding, "message_encoding");
    v.StringMap(r.metadata, "metadata");
  }
};

// A Message to write: its data stays where the caller has it.
struct MessageView {
  uint16_t channel_id = 0;
  uint32_t sequence = 0;
  uint64_t log_time_ns = 0;
  uint64_t publish_time_ns = 0;
  std::string_view data;
};

// Self: Message (read) or MessageView (written). The fields before the data are
// kMessageFieldsBytes.
struct MessageTable {
  static constexpr Opcode kOpcode = Opcode::kMessage;
  template <class Self, class V>
  static void Fields(Self& r, V& v) {
    v.U16(r.channel_id, "channel_id");
    v.U32(r.sequence, "sequence");
    v.U64(r.log_time_ns, "log_time");
    v.U64(r.publish_time_ns, "publish_time");
    v.RestBytes(r.data, "data");
  }
};

// The records stay as stored: a chunk is not decompressed here.
struct ChunkTable {
  static constexpr Opcode kOpcode = Opcode::kChunk;
  template <class Self, class V>
  static void Fields(Self& r, V& v) {
    v.U64(r.message_start_time_ns, "message_start_time");
    v.U64(r.message_end_time_ns, "message_end_time");
    v.U64(r.uncompressed_size, "uncompressed_size");
    v.U32(r.uncompressed_crc, "uncompressed_crc");
    v.String(r.compression, "compression");
    v.U64Bytes(r.records, "records");
  }
};

struct MessageIndexTable {
  static constexpr Opcode kOpcode = Opcode::kMessageIndex;
  template <class Self, class V>
  static void Fields(Self& r, V& v) {
    v.U16(r.channel_id, "channel_id");
    v.U64PairArray(r.entries, "records");
  }
};

struct ChunkIndexTable {
  static constexpr Opcode kOpcode = Opcode::kChunkIndex;
  template <class Self, class V>
  static void Fields(Self& r, V& v) {
    v.U64(r.message_start_time_ns, "message_start_time");
    v.U64(r.message_end_time_ns, "message_end_time");
    v.U64(r.chunk_start_offset, "chunk_start_offset");
    v.U64(r.chunk_length, "chunk_length");
    v.U16U64Map(r.message_index_offsets, "message_index_offsets");
    v.U64(r.message_index_length, "message_index_length");
    v.String(r.compression, "compression");
    v.U64(r.compressed_size, "compressed_size");
    v.U64(r.uncompressed_size, "uncompressed_size");
  }
};

struct AttachmentTable {
  static constexpr Opcode kOpcode = Opcode::kAttachment;
  template <class Self, class V>
  static void Fields(Self& r, V& v) {
    v.U64(r.log_time_ns, "log_time");
    v.U64(r.create_time_ns, "create_time");
    v.String(r.name, "name");
    v.String(r.media_type, "media_type");
    v.U64Bytes(r.data, "data");
    v.FieldsCrc("crc");
  }
};

struct AttachmentIndexTable {
  static constexpr Opcode kOpcode = Opcode::kAttachmentIndex;
  template <class Self, class V>
  static void Fields(Self& r, V& v) {
    v.U64(r.offset, "offset");
    v.U64(r.length, "length");
    v.U64(r.log_time_ns, "log_time");
    v.U64(r.create_time_ns, "create_time");
    v.U64(r.data_size, "data_size");
    v.String(r.name, "name");
    v.String(r.media_type, "media_type");
  }
};

struct StatisticsTable {
  static constexpr Opcode kOpcode = Opcode::kStatistics;
  template <class Self, class V>
  static void Fields(Self& r, V& v) {
    v.U64(r.message_count, "message_count");
    v.U16(r.schema_count, "schema_count");
    v.U32(r.channel_count, "channel_count");
    v.U32(r.attachment_count, "attachment_count");
    v.U32(r.metadata_count, "metadata_count");
    v.U32(r.chunk_count, "chunk_count");
    v.U64(r.message_start_time_ns, "message_start_time");
    v.U64(r.message_end_time_ns, "message_end_time");
    v.U16U64Map(r.channel_message_counts, "channel_message_counts");
  }
};

struct MetadataTable {
  static constexpr Opcode kOpcode = Opcode::kMetadata;
  template <class Self, class V>
  static void Fields(Self& r, V& v) {
    v.String(r.name, "name");
    v.StringMap(r.values, "metadata");
  }
};

struct MetadataIndexTable {
  static constexpr Opcode kOpcode = Opcode::kMetadataIndex;
  template <class Self, class V>
  static void Fields(Self& r, V& v) {
    v.U64(r.offset, "offset");
    v.U64(r.length, "length");
    v.String(r.name, "name");
  }
};

struct SummaryOffsetTable {
  static constexpr Opcode kOpcode = Opcode::kSummaryOffset;
  template <class Self, class V>
  static void Fields(Self& r, V& v) {
    v.U8(r.group_opcode, "group_opcode");
    v.U64(r.group_start, "group_start");
    v.U64(r.group_length, "group_length");
  }
};

struct DataEnd {
  uint32_t data_section_crc = 0;
};

struct DataEndTable {
  static constexpr Opcode kOpcode = Opcode::kDataEnd;
  template <class Self, class V>
  static void Fields(Self& r, V& v) {
    v.U32(r.data_section_crc, "data_section_crc");
  }
};

struct FooterTable {
  static constexpr Opcode kOpcode = Opcode::kFooter;
  template <class Self, class V>
  static void Fields(Self& r, V& v) {
    v.U64(r.summary_start, "summary_start");
    v.U64(r.summary_offset_start, "summary_offset_start");
    v.U32(r.summary_crc, "summary_crc");
  }
};

}  // namespace

// ---- Writing ------------------------------------------------------------------------------------

void AppendHeader(std::string& out, const Header& header) { Append<HeaderTable>(out, header); }
void AppendSchema(std::string& out, const Schema& schema) { Append<SchemaTable>(out, schema); }
void AppendChannel(std::string& out, const Channel& channel) { Append<ChannelTable>(out, channel); }
void AppendMessage(std::string& out, uint16_t channel_id, uint32_t sequence, uint64_t log_time_ns,
                   uint64_t publish_time_ns, std::string_view data) {
  Append<MessageTable>(out, MessageView{channel_id, sequence, log_time_ns, publish_time_ns, data});
}
void AppendChunk(std::string& out, const ChunkRecord& chunk) { Append<ChunkTable>(out, chunk); }
void AppendMessageIndex(std::string& out, const MessageIndex& index) {
  Append<MessageIndexTable>(out, index);
}
void AppendChunkIndex(std::string& out, const ChunkIndex& index) {
  Append<ChunkIndexTable>(out, index);
}
void AppendAttachment(std::string& out, const Attachment& attachment) {
  Append<AttachmentTable>(out, attachment);
}
void AppendAttachmentIndex(std::string& out, const AttachmentIndex& index) {
  Append<AttachmentIndexTable>(out, index);
}
void AppendStatistics(std::string& out, const Statistics& statistics) {
  Append<StatisticsTable>(out, statistics);
}
void AppendMetadata(std::string& out, const Metadata& metadata) {
  Append<MetadataTable>(out, metadata);
}
void AppendMetadataIndex(std::string& out, const MetadataIndex& index) {
  Append<MetadataIndexTable>(out, index);
}
void AppendSummaryOffset(std::string& out, const SummaryOffset& offset) {
  Append<SummaryOffsetTable>(out, offset);
}
void AppendDataEnd(std::string& out, uint32_t data_section_crc) {
  Append<DataEndTable>(out, DataEnd{data_section_crc});
}
void AppendFooter(std::string& out, const Footer& footer) { Append<FooterTable>(out, footer); }

// ---- Parsing ------------------------------------------------------------------------------------

Result<Header> ParseHeader(std::string_view c) { return Parse<HeaderTable, Header>(c); }
Result<Schema> ParseSchema(std::string_view c) { return Parse<SchemaTable, Schema>(c); }
Result<Channel> ParseChannel(std::string_view c) { return Parse<ChannelTable, Channel>(c); }
Result<Message> ParseMessage(std::string_view c) { return Parse<MessageTable, Message>(c); }
Result<ChunkRecord> ParseChunk(std::string_view c) { return Parse<ChunkTable, ChunkRecord>(c); }
Result<MessageIndex> ParseMessageIndex(std::string_view c) {
  return Parse<MessageIndexTable, MessageIndex>(c);
}
Result<ChunkIndex> ParseChunkIndex(std::string_view c) {
  return Parse<ChunkIndexTable, ChunkIndex>(c);
}
Result<Attachment> ParseAttachment(std::string_view c) {
  return Parse<AttachmentTable, Attachment>(c);
}
Result<AttachmentIndex> ParseAttachmentIndex(std::string_view c) {
  return Parse<AttachmentIndexTable, AttachmentIndex>(c);
}
Result<Statistics> ParseStatistics(std::string_view c) {
  return Parse<StatisticsTable, Statistics>(c);
}
Result<Metadata> ParseMetadata(std::string_view c) { return Parse<MetadataTable, Metadata>(c); }
Result<MetadataIndex> ParseMetadataIndex(std::string_view c) {
  return Parse<MetadataIndexTable, MetadataIndex>(c);
}
Result<SummaryOffset> ParseSummaryOffset(std::string_view c) {
  return Parse<SummaryOffsetTable, SummaryOffset>(c);
}
Result<uint32_t> ParseDataEnd(std::string_view c) {
  Result<DataEnd> data_end = Parse<DataEndTable, DataEnd>(c);
  if (!data_end.ok()) return data_end.error();
  return data_end->data_section_crc;
}
Result<Footer> ParseFooter(std::string_view c) { return Parse<FooterTable, Footer>(c); }

std::string OpcodeName(uint8_t opcode) {
  static constexpr const char* kNames[] = {
      "Header",     "Footer",        "Schema",         "Channel",        "Message",
      "Chunk",      "Message Index", "Chunk Index",    "Attachment",     "Attachment Index",
      "Statistics", "Metadata",      "Metadata Index", "Summary Offset", "Data End"};
  if (opcode >= 0x01 && opcode <= 0x0F) return kNames[opcode - 1];
  char text[24];
  std::snprintf(text, sizeof(text), "opcode 0x%02X", opcode);
  return text;
}

}  // namespace stevi::mcap::internal
