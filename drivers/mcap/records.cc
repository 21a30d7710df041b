#include "drivers/mcap/records.h"

#include <cstdio>

#include "drivers/mcap/codec.h"

namespace stevi::mcap::internal {
namespace {

// The parse result: the value, or the decoder's problem under the record's name.
template <typename T>
Result<T> Finish(const Decoder& d, const char* record, T value) {
  if (!d.ok()) return InvalidArgument(std::string(record) + ": " + d.problem());
  return value;
}

}  // namespace

// ---- Writing ------------------------------------------------------------------------------------

void AppendHeader(std::string& out, const Header& header) {
  Encoder e(out);
  const size_t start = e.BeginRecord(Opcode::kHeader);
  e.String(header.profile);
  e.String(header.library);
  e.EndRecord(start);
}

void AppendSchema(std::string& out, const Schema& schema) {
  Encoder e(out);
  const size_t start = e.BeginRecord(Opcode::kSchema);
  e.U16(schema.id);
  e.String(schema.name);
  e.String(schema.encoding);
  e.String(schema.data);  // u32-prefixed bytes, like a string
  e.EndRecord(start);
}

void AppendChannel(std::string& out, const Channel& channel) {
  Encoder e(out);
  const size_t start = e.BeginRecord(Opcode::kChannel);
  e.U16(channel.id);
  e.U16(channel.schema_id);
  e.String(channel.topic);
  e.String(channel.message_encoding);
  e.StringMap(channel.metadata);
  e.EndRecord(start);
}

void AppendMessage(std::string& out, uint16_t channel_id, uint32_t sequence, uint64_t log_time_ns,
                   uint64_t publish_time_ns, std::string_view data) {
  Encoder e(out);
  const size_t start = e.BeginRecord(Opcode::kMessage);
  e.U16(channel_id);
  e.U32(sequence);
  e.U64(log_time_ns);
  e.U64(publish_time_ns);
  e.Raw(data);
  e.EndRecord(start);
}

void AppendChunk(std::string& out, const ChunkRecord& chunk) {
  Encoder e(out);
  const size_t start = e.BeginRecord(Opcode::kChunk);
  e.U64(chunk.message_start_time_ns);
  e.U64(chunk.message_end_time_ns);
  e.U64(chunk.uncompressed_size);
  e.U32(chunk.uncompressed_crc);
  e.String(chunk.compression);
  e.U64(chunk.records.size());
  e.Raw(chunk.records);
  e.EndRecord(start);
}

void AppendMessageIndex(std::string& out, const MessageIndex& index) {
  Encoder e(out);
  const size_t start = e.BeginRecord(Opcode::kMessageIndex);
  e.U16(index.channel_id);
  e.U32(static_cast<uint32_t>(index.entries.size() * 16));
  for (const auto& [log_time, offset] : index.entries) {
    e.U64(log_time);
    e.U64(offset);
  }
  e.EndRecord(start);
}

void AppendChunkIndex(std::string& out, const ChunkIndex& index) {
  Encoder e(out);
  const size_t start = e.BeginRecord(Opcode::kChunkIndex);
  e.U64(index.message_start_time_ns);
  e.U64(index.message_end_time_ns);
  e.U64(index.chunk_start_offset);
  e.U64(index.chunk_length);
  e.U16U64Map(index.message_index_offsets);
  e.U64(index.message_index_length);
  e.String(index.compression);
  e.U64(index.compressed_size);
  e.U64(index.uncompressed_size);
  e.EndRecord(start);
}

void AppendAttachment(std::string& out, const Attachment& attachment) {
  Encoder e(out);
  const size_t start = e.BeginRecord(Opcode::kAttachment);
  e.U64(attachment.log_time_ns);
  e.U64(attachment.create_time_ns);
  e.String(attachment.name);
  e.String(attachment.media_type);
  e.U64(attachment.data.size());
  e.Raw(attachment.data);
  // The CRC covers the fields before it, not the opcode and length.
  const size_t fields = start + kRecordPrefixBytes;
  e.U32(Crc32(std::string_view(out).substr(fields)));
  e.EndRecord(start);
}

void AppendAttachmentIndex(std::string& out, const AttachmentIndex& index) {
  Encoder e(out);
  const size_t start = e.BeginRecord(Opcode::kAttachmentIndex);
  e.U64(index.offset);
  e.U64(index.length);
  e.U64(index.log_time_ns);
  e.U64(index.create_time_ns);
  e.U64(index.data_size);
  e.String(index.name);
  e.String(index.media_type);
  e.EndRecord(start);
}

void AppendStatistics(std::string& out, const Statistics& statistics) {
  Encoder e(out);
  const size_t start = e.BeginRecord(Opcode::kStatistics);
  e.U64(statistics.message_count);
  e.U16(statistics.schema_count);
  e.U32(statistics.channel_count);
  e.U32(statistics.attachment_count);
  e.U32(statistics.metadata_count);
  e.U32(statistics.chunk_count);
  e.U64(statistics.message_start_time_ns);
  e.U64(statistics.message_end_time_ns);
  e.U16U64Map(statistics.channel_message_counts);
  e.EndRecord(start);
}

void AppendMetadata(std::string& out, const Metadata& metadata) {
  Encoder e(out);
  const size_t start = e.BeginRecord(Opcode::kMetadata);
  e.String(metadata.name);
  e.StringMap(metadata.values);
  e.EndRecord(start);
}

void AppendMetadataIndex(std::string& out, const MetadataIndex& index) {
  Encoder e(out);
  const size_t start = e.BeginRecord(Opcode::kMetadataIndex);
  e.U64(index.offset);
  e.U64(index.length);
  e.String(index.name);
  e.EndRecord(start);
}

void AppendSummaryOffset(std::string& out, const SummaryOffset& offset) {
  Encoder e(out);
  const size_t start = e.BeginRecord(Opcode::kSummaryOffset);
  e.U8(offset.group_opcode);
  e.U64(offset.group_start);
  e.U64(offset.group_length);
  e.EndRecord(start);
}

void AppendDataEnd(std::string& out, uint32_t data_section_crc) {
  Encoder e(out);
  const size_t start = e.BeginRecord(Opcode::kDataEnd);
  e.U32(data_section_crc);
  e.EndRecord(start);
}

void AppendFooter(std::string& out, const Footer& footer) {
  Encoder e(out);
  const size_t start = e.BeginRecord(Opcode::kFooter);
  e.U64(footer.summary_start);
  e.U64(footer.summary_offset_start);
  e.U32(footer.summary_crc);
  e.EndRecord(start);
}

// ---- Parsing ------------------------------------------------------------------------------------

Result<Header> ParseHeader(std::string_view content) {
  Decoder d(content);
  Header header;
  header.profile = d.String("profile");
  header.library = d.String("library");
  return Finish(d, "Header", std::move(header));
}

Result<Schema> ParseSchema(std::string_view content) {
  Decoder d(content);
  Schema schema;
  schema.id = d.U16("id");
  schema.name = d.String("name");
  schema.encoding = d.String("encoding");
  schema.data = d.String("data");
  return Finish(d, "Schema", std::move(schema));
}

Result<Channel> ParseChannel(std::string_view content) {
  Decoder d(content);
  Channel channel;
  channel.id = d.U16("id");
  channel.schema_id = d.U16("schema_id");
  channel.topic = d.String("topic");
  channel.message_encoding = d.String("message_encoding");
  channel.metadata = d.StringMap("metadata");
  return Finish(d, "Channel", std::move(channel));
}

Result<Message> ParseMessage(std::string_view content) {
  Decoder d(content);
  Message message;
  message.channel_id = d.U16("channel_id");
  message.sequence = d.U32("sequence");
  message.log_time_ns = d.U64("log_time");
  message.publish_time_ns = d.U64("publish_time");
  message.data = std::string(d.Rest());
  return Finish(d, "Message", std::move(message));
}

Result<ChunkRecord> ParseChunk(std::string_view content) {
  Decoder d(content);
  ChunkRecord chunk;
  chunk.message_start_time_ns = d.U64("message_start_time");
  chunk.message_end_time_ns = d.U64("message_end_time");
  chunk.uncompressed_size = d.U64("uncompressed_size");
  chunk.uncompressed_crc = d.U32("uncompressed_crc");
  chunk.compression = d.String("compression");
  const uint64_t n = d.U64("records");
  chunk.records = d.View(n, "records");
  return Finish(d, "Chunk", std::move(chunk));
}

Result<MessageIndex> ParseMessageIndex(std::string_view content) {
  Decoder d(content);
  MessageIndex index;
  index.channel_id = d.U16("channel_id");
  index.entries = d.U64PairArray("records");
  return Finish(d, "Message Index", std::move(index));
}

Result<ChunkIndex> ParseChunkIndex(std::string_view content) {
  Decoder d(content);
  ChunkIndex index;
  index.message_start_time_ns = d.U64("message_start_time");
  index.message_end_time_ns = d.U64("message_end_time");
  index.chunk_start_offset = d.U64("chunk_start_offset");
  index.chunk_length = d.U64("chunk_length");
  index.message_index_offsets = d.U16U64Map("message_index_offsets");
  index.message_index_length = d.U64("message_index_length");
  index.compression = d.String("compression");
  index.compressed_size = d.U64("compressed_size");
  index.uncompressed_size = d.U64("uncompressed_size");
  return Finish(d, "Chunk Index", std::move(index));
}

Result<Attachment> ParseAttachment(std::string_view content) {
  Decoder d(content);
  Attachment attachment;
  attachment.log_time_ns = d.U64("log_time");
  attachment.create_time_ns = d.U64("create_time");
  attachment.name = d.String("name");
  attachment.media_type = d.String("media_type");
  const uint64_t n = d.U64("data");
  attachment.data = std::string(d.View(n, "data"));
  const uint64_t covered = d.position();
  const uint32_t crc = d.U32("crc");
  if (d.ok() && crc != 0) {
    const uint32_t actual = Crc32(content.substr(0, covered));
    if (actual != crc) {
      char text[96];
      std::snprintf(text, sizeof(text), "crc: the record says 0x%08X, its fields give 0x%08X", crc,
                    actual);
      d.Fail(text);
    }
  }
  return Finish(d, "Attachment", std::move(attachment));
}

Result<AttachmentIndex> ParseAttachmentIndex(std::string_view content) {
  Decoder d(content);
  AttachmentIndex index;
  index.offset = d.U64("offset");
  index.length = d.U64("length");
  index.log_time_ns = d.U64("log_time");
  index.create_time_ns = d.U64("create_time");
  index.data_size = d.U64("data_size");
  index.name = d.String("name");
  index.media_type = d.String("media_type");
  return Finish(d, "Attachment Index", std::move(index));
}

Result<Statistics> ParseStatistics(std::string_view content) {
  Decoder d(content);
  Statistics s;
  s.message_count = d.U64("message_count");
  s.schema_count = d.U16("schema_count");
  s.channel_count = d.U32("channel_count");
  s.attachment_count = d.U32("attachment_count");
  s.metadata_count = d.U32("metadata_count");
  s.chunk_count = d.U32("chunk_count");
  s.message_start_time_ns = d.U64("message_start_time");
  s.message_end_time_ns = d.U64("message_end_time");
  s.channel_message_counts = d.U16U64Map("channel_message_counts");
  return Finish(d, "Statistics", std::move(s));
}

Result<Metadata> ParseMetadata(std::string_view content) {
  Decoder d(content);
  Metadata metadata;
  metadata.name = d.String("name");
  metadata.values = d.StringMap("metadata");
  return Finish(d, "Metadata", std::move(metadata));
}

Result<MetadataIndex> ParseMetadataIndex(std::string_view content) {
  Decoder d(content);
  MetadataIndex index;
  index.offset = d.U64("offset");
  index.length = d.U64("length");
  index.name = d.String("name");
  return Finish(d, "Metadata Index", std::move(index));
}

Result<SummaryOffset> ParseSummaryOffset(std::string_view content) {
  Decoder d(content);
  SummaryOffset offset;
  offset.group_opcode = d.U8("group_opcode");
  offset.group_start = d.U64("group_start");
  offset.group_length = d.U64("group_length");
  return Finish(d, "Summary Offset", offset);
}

Result<uint32_t> ParseDataEnd(std::string_view content) {
  Decoder d(content);
  const uint32_t crc = d.U32("data_section_crc");
  return Finish(d, "Data End", crc);
}

Result<Footer> ParseFooter(std::string_view content) {
  Decoder d(content);
  Footer footer;
  footer.summary_start = d.U64("summary_start");
  footer.summary_offset_start = d.U64("summary_offset_start");
  footer.summary_crc = d.U32("summary_crc");
  return Finish(d, "Footer", footer);
}

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
