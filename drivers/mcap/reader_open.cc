// Reader::Open() and Reader::FromBytes(): checking a whole file once (see reader.cc for the
// order of the checks).
#include <algorithm>
#include <utility>

#include "drivers/mcap/codec.h"
#include "drivers/mcap/reader_impl.h"

namespace stevi::mcap {
namespace {

using internal::Decoder;
using internal::Hex32;
using internal::Is;
using internal::kRecordPrefixBytes;
using internal::RecordView;
using internal::ScanEnd;
using internal::Str;

constexpr uint64_t kFooterRecordBytes = kRecordPrefixBytes + internal::kFooterContentBytes;
constexpr uint64_t kDataEndRecordBytes = kRecordPrefixBytes + internal::kDataEndContentBytes;
// The Footer's bytes the summary CRC covers: opcode, length, summary_start, summary_offset_start.
constexpr uint64_t kFooterCrcBytes = kRecordPrefixBytes + 16;
constexpr uint64_t kCrcBlockBytes = uint64_t{1} << 20;

// "1 message", "7 messages".
std::string Count(uint64_t n, const std::string& thing) {
  return Str(n) + " " + thing + (n == 1 ? "" : "s");
}

// The largest record content Open() reads whole, by opcode (others are only streamed through the
// CRC, whatever their size).
uint64_t MaxContentBytes(uint8_t opcode, uint64_t max_chunk_bytes) {
  if (Is(opcode, Opcode::kChunk)) return max_chunk_bytes + max_chunk_bytes / 64 + (64 << 10);
  if (Is(opcode, Opcode::kMessage)) return kMaxMessageBytes + internal::kMessageFieldsBytes;
  if (Is(opcode, Opcode::kAttachment)) return kMaxAttachmentBytes + kMaxRecordFieldsBytes + 64;
  return kMaxSchemaBytes + kMaxRecordFieldsBytes;
}

// Whether Open() reads the record whole (to parse it) rather than streaming it through the CRC.
bool ReadWhole(uint8_t opcode) {
  return Is(opcode, Opcode::kSchema) || Is(opcode, Opcode::kChannel) ||
         Is(opcode, Opcode::kMessage) || Is(opcode, Opcode::kChunk) ||
         Is(opcode, Opcode::kAttachment) || Is(opcode, Opcode::kMetadata);
}

}  // namespace

Result<std::string_view> Reader::Impl::Take(uint64_t at, uint64_t n) {
  Result<std::string_view> bytes = source->Read(at, n, scratch);
  if (bytes.ok() && at == crc_pos) {
    crc = internal::Crc32(*bytes, crc);
    crc_pos += n;
  }
  return bytes;
}

Status Reader::Impl::Skip(uint64_t at, uint64_t n) {
  for (uint64_t done = 0; done < n;) {
    const uint64_t piece = std::min(kCrcBlockBytes, n - done);
    if (Result<std::string_view> bytes = Take(at + done, piece); !bytes.ok()) return bytes.error();
    done += piece;
  }
  return {};
}

Result<std::optional<Message>> Reader::Impl::Interpret(uint8_t opcode, std::string_view content) {
  if (Is(opcode, Opcode::kSchema)) {
    Result<Schema> schema = internal::ParseSchema(content);
    if (!schema.ok()) return schema.error();
    if (schema->id == 0) return std::optional<Message>();  // invalid: ignored, as the spec says
    const auto [it, added] = schemas.emplace(schema->id, *schema);
    if (!added && !(it->second == *schema)) {
      return InvalidArgument("Schema " + Str(schema->id) +
                             " differs from an earlier one with that id");
    }
  } else if (Is(opcode, Opcode::kChannel)) {
    Result<Channel> channel = internal::ParseChannel(content);
    if (!channel.ok()) return channel.error();
    const auto [it, added] = channels.emplace(channel->id, *channel);
    if (!added && !(it->second == *channel)) {
      return InvalidArgument("Channel " + Str(channel->id) +
                             " differs from an earlier one with that id");
    }
  } else if (Is(opcode, Opcode::kMessage)) {
    Result<Message> message = internal::ParseMessage(content);
    if (!message.ok()) return message.error();
    if (channels.count(message->channel_id) == 0) {
      return InvalidArgument("Message: channel " + Str(message->channel_id) +
                             " has no Channel record before it");
    }
    return std::optional<Message>(std::move(*message));
  }
  return std::optional<Message>();
}

// ---- Open(): the header and the summary ---------------------------------------------------------

Status Reader::Impl::LoadHeader(bool& cut) {
  const uint64_t size = source->size();
  Result<std::string_view> magic =
      source->Read(0, std::min<uint64_t>(size, kMagic.size()), scratch);
  if (!magic.ok()) return magic.error();
  if (*magic != kMagic.substr(0, magic->size())) {
    return Bad(0, "not an MCAP file (it does not start with the MCAP magic)");
  }
  cut = size < kMagic.size() + kRecordPrefixBytes;
  if (cut) return {};
  Result<std::string_view> prefix = source->Read(kMagic.size(), kRecordPrefixBytes, scratch);
  if (!prefix.ok()) return prefix.error();
  Decoder d(*prefix);
  const uint8_t opcode = d.U8("opcode");
  const uint64_t length = d.U64("length");
  if (!Is(opcode, Opcode::kHeader)) {
    return Bad(kMagic.size(),
               "expected the Header record (opcode 0x01), found " + internal::OpcodeName(opcode));
  }
  const uint64_t start = kMagic.size() + kRecordPrefixBytes;
  cut = length > size - start;
  if (cut) return {};
  if (length > kMaxRecordFieldsBytes) {
    return Bad(kMagic.size(), "Header: " + Str(length) + " bytes is over the limit of 1 MiB");
  }
  Result<std::string_view> content = source->Read(start, length, scratch);
  if (!content.ok()) return content.error();
  Result<Header> parsed = internal::ParseHeader(*content);
  if (!parsed.ok()) return Bad(kMagic.size(), parsed.error().message);
  header = std::move(*parsed);
  data_start = start + length;
  return {};
}

Status Reader::Impl::SummaryRecord(uint64_t at, const RecordView& record, uint64_t summary_start,
                                   uint64_t group_limit) {
  const uint8_t op = record.opcode;
  if (Is(op, Opcode::kSchema) || Is(op, Opcode::kChannel)) {
    if (auto defined = Interpret(op, record.content); !defined.ok()) return defined.error();
  } else if (Is(op, Opcode::kStatistics)) {
    Result<Statistics> s = internal::ParseStatistics(record.content);
    if (!s.ok()) return s.error();
    if (!statistics) statistics = std::move(*s);  // the spec allows one; keep the first
  } else if (Is(op, Opcode::kChunkIndex)) {
    Result<ChunkIndex> index = internal::ParseChunkIndex(record.content);
    if (!index.ok()) return index.error();
    chunk_indexes.push_back(std::move(*index));
    chunk_index_at.push_back(at);
  } else if (Is(op, Opcode::kAttachmentIndex)) {
    Result<internal::AttachmentIndex> index = internal::ParseAttachmentIndex(record.content);
    if (!index.ok()) return index.error();
    attachment_indexes.push_back(std::move(*index));
  } else if (Is(op, Opcode::kMetadataIndex)) {
    Result<internal::MetadataIndex> index = internal::ParseMetadataIndex(record.content);
    if (!index.ok()) return index.error();
    metadata_indexes.push_back(std::move(*index));
  } else if (Is(op, Opcode::kSummaryOffset)) {
    Result<internal::SummaryOffset> offset = internal::ParseSummaryOffset(record.content);
    if (!offset.ok()) return offset.error();
    if (offset->group_start < summary_start || offset->group_start > group_limit ||
        offset->group_length > group_limit - offset->group_start) {
      return InvalidArgument("Summary Offset: the group of " +
                             internal::OpcodeName(offset->group_opcode) + " (bytes " +
                             Str(offset->group_start) + " +" + Str(offset->group_length) +
                             ") is not inside the summary");
    }
  }
  return {};  // other records are skipped, as the spec asks
}

Result<bool> Reader::Impl::LoadSummary(std::string& why) {
  const uint64_t size = source->size();
  why = "the file was cut short at byte " + Str(size);
  if (size < data_start + kFooterRecordBytes + kMagic.size()) return false;
  const uint64_t footer_at = size - kMagic.size() - kFooterRecordBytes;
  Result<std::string_view> tail =
      source->Read(footer_at, kFooterRecordBytes + kMagic.size(), scratch);
  if (!tail.ok()) return tail.error();
  if (tail->substr(kFooterRecordBytes) != kMagic) return false;
  Decoder d(tail->substr(0, kRecordPrefixBytes));
  if (!Is(d.U8("opcode"), Opcode::kFooter) || d.U64("length") != internal::kFooterContentBytes) {
    why = "the closing magic has no Footer record before it, at byte " + Str(footer_at);
    return false;
  }
  const internal::Footer footer = *internal::ParseFooter(tail->substr(kRecordPrefixBytes));
  const uint64_t start = footer.summary_start;
  const uint64_t offsets = footer.summary_offset_start;
  if (start == 0) {
    why = "the writer wrote none";
    return false;
  }
  why = "the Footer at byte " + Str(footer_at) + " is not valid: its summary_start " + Str(start) +
        " does not follow a Data End record";
  if (start < data_start + kDataEndRecordBytes || start > footer_at ||
      (offsets != 0 && (offsets < start || offsets > footer_at))) {
    return false;
  }
  Result<std::string_view> data_end_record =
      source->Read(start - kDataEndRecordBytes, kDataEndRecordBytes, scratch);
  if (!data_end_record.ok()) return data_end_record.error();
  Decoder e(*data_end_record);
  if (!Is(e.U8("opcode"), Opcode::kDataEnd) || e.U64("length") != internal::kDataEndContentBytes) {
    return false;
  }
  data_end = start - kDataEndRecordBytes;
  data_end_crc = e.U32("data_section_crc");
  Result<std::string_view> summary =
      source->Read(start, footer_at + kFooterCrcBytes - start, scratch);
  if (!summary.ok()) return summary.error();
  if (footer.summary_crc != 0 && internal::Crc32(*summary) != footer.summary_crc) {
    return Bad(footer_at, "summary CRC mismatch: the Footer says " + Hex32(footer.summary_crc) +
                              ", bytes " + Str(start) + " to " + Str(footer_at + kFooterCrcBytes) +
                              " give " + Hex32(internal::Crc32(*summary)));
  }
  const std::string_view records = summary->substr(0, footer_at - start);
  const uint64_t group_limit = offsets != 0 ? offsets : footer_at;
  for (uint64_t at = 0; at < records.size();) {
    Result<RecordView> record = internal::RecordIn(records, at);
    if (!record.ok()) return Bad(start + at, "summary: " + record.error().message);
    if (Status s = SummaryRecord(start + at, *record, start, group_limit); !s) {
      return Bad(start + at, "summary: " + s.error().message);
    }
    at += record->size();
  }
  return true;
}

// ---- Open(): the data section -------------------------------------------------------------------

Status Reader::Impl::ScanChunk(uint64_t at, std::string_view content, bool decode) {
  Result<internal::ChunkRecord> chunk = internal::ParseChunk(content);
  if (!chunk.ok()) return chunk.error();
  if (decode) {
    Result<std::string_view> inner =
        internal::DecodeChunk(*chunk, options.max_chunk_bytes, decoded);
    if (!inner.ok()) return InvalidArgument("Chunk: " + inner.error().message);
    uint64_t messages = 0;
    for (uint64_t p = 0; p < inner->size();) {
      Result<RecordView> record = internal::RecordIn(*inner, p);
      if (!record.ok()) {
        return InvalidArgument("Chunk: its record at byte " + Str(p) + ": " +
                               record.error().message);
      }
      Result<std::optional<Message>> message = Interpret(record->opcode, record->content);
      if (!message.ok()) {
        return InvalidArgument("Chunk: its record at byte " + Str(p) + ": " +
                               message.error().message);
      }
      if (message->has_value()) ++messages;
      p += record->size();
    }
    recovered_messages += messages;
    ++recovered_chunks;
  } else if (chunk->uncompressed_size > options.max_chunk_bytes ||
             !CompressionFromName(chunk->compression)) {
    // Checked now so that an indexed file fails at Open(), not halfway through its messages.
    return InvalidArgument("Chunk: uncompressed_size " + Str(chunk->uncompressed_size) +
                           " over the limit, or unknown compression \"" +
                           chunk->compression.substr(0, 32) + "\"");
  }
  seen_chunks[at] = ChunkIndex{chunk->message_start_time_ns,
                               chunk->message_end_time_ns,
                               at,
                               kRecordPrefixBytes + content.size(),
                               {},
                               0,
                               chunk->compression,
                               chunk->records.size(),
                               chunk->uncompressed_size};
  return {};
}

Status Reader::Impl::ScanRecord(uint64_t at, uint8_t opcode, uint64_t length, bool strict) {
  const uint64_t start = at + kRecordPrefixBytes;
  if (!ReadWhole(opcode)) return Skip(start, length);
  Result<std::string_view> content = Take(start, length);
  if (!content.ok()) return content.error();
  if (Is(opcode, Opcode::kChunk)) return ScanChunk(at, *content, /*decode=*/!strict);
  if (Is(opcode, Opcode::kAttachment)) {
    Result<Attachment> attachment = internal::ParseAttachment(*content);
    if (!attachment.ok()) return attachment.error();
    attachments.push_back(std::move(*attachment));
    seen_attachments[at] = kRecordPrefixBytes + length;
    return {};
  }
  if (Is(opcode, Opcode::kMetadata)) {
    Result<Metadata> parsed = internal::ParseMetadata(*content);
    if (!parsed.ok()) return parsed.error();
    metadata.push_back(std::move(*parsed));
    seen_metadata[at] = kRecordPrefixBytes + length;
    return {};
  }
  Result<std::optional<Message>> message = Interpret(opcode, *content);
  if (!message.ok()) return message.error();
  if (message->has_value()) ++recovered_messages;
  return {};
}

Status Reader::Impl::Scan(uint64_t limit, bool strict, ScanEnd& end) {
  crc_pos = 0;
  crc = 0;
  if (Status s = Skip(0, data_start); !s) return s;
  for (uint64_t at = data_start;;) {
    end.at = at;
    if (at == limit) return {};       // kLimit
    const uint32_t crc_before = crc;  // of bytes [0, at)
    const uint64_t left = limit - at;
    if (left < kRecordPrefixBytes) {
      end.kind = ScanEnd::Kind::kCutHeader;
      return strict ? Status(Bad(at, "a record header runs past the Data End")) : Status();
    }
    Result<std::string_view> prefix = Take(at, kRecordPrefixBytes);
    if (!prefix.ok()) return prefix.error();
    Decoder d(*prefix);
    end.opcode = d.U8("opcode");
    const uint64_t length = d.U64("length");
    end.record_bytes = length;
    std::string problem;
    if (end.opcode == 0) {
      problem = "invalid opcode 0x00 (not a record)";
    } else if (length > left - kRecordPrefixBytes) {
      end.kind = ScanEnd::Kind::kCutRecord;
      if (!strict) return {};
      problem = internal::OpcodeName(end.opcode) + " record of " + Str(length) +
                " bytes runs past the Data End at byte " + Str(limit);
    } else if (ReadWhole(end.opcode) &&
               length > MaxContentBytes(end.opcode, options.max_chunk_bytes)) {
      problem = internal::OpcodeName(end.opcode) + " record of " + Str(length) +
                " bytes is over the reader's limit";
    } else if (Is(end.opcode, Opcode::kFooter) && !strict) {
      end.kind = ScanEnd::Kind::kFooter;  // a file without Data End (not ours)
      return {};
    } else if (Is(end.opcode, Opcode::kDataEnd)) {
      if (strict) return Bad(at, "a Data End record before the summary's, at byte " + Str(limit));
      Result<std::string_view> content =
          Take(at + kRecordPrefixBytes, std::min<uint64_t>(length, 4));
      if (!content.ok()) return content.error();
      Result<uint32_t> stored = internal::ParseDataEnd(*content);
      if (!stored.ok()) return Bad(at, stored.error().message);
      if (*stored != 0 && *stored != crc_before) {
        return Bad(at, "data-section CRC mismatch: the Data End says " + Hex32(*stored) +
                           ", bytes 0 to " + Str(at) + " give " + Hex32(crc_before));
      }
      end.kind = ScanEnd::Kind::kDataEnd;
      return {};
    } else if (Status s = ScanRecord(at, end.opcode, length, strict); !s) {
      if (s.error().code != ErrorCode::kInvalidArgument) return s;  // an I/O error
      problem = s.error().message;
    }
    if (!problem.empty()) {
      if (strict) return Bad(at, problem);
      end.kind = ScanEnd::Kind::kDamaged;
      end.problem = std::move(problem);
      return {};
    }
    at += kRecordPrefixBytes + length;
  }
}

Status Reader::Impl::CheckIndexes() const {
  if (chunk_indexes.size() != seen_chunks.size()) {
    return Bad(data_end, "the summary indexes " + Str(chunk_indexes.size()) +
                             " chunks, the data section has " + Str(seen_chunks.size()));
  }
  for (size_t i = 0; i < chunk_indexes.size(); ++i) {
    ChunkIndex expected = chunk_indexes[i];
    expected.message_index_offsets.clear();
    expected.message_index_length = 0;
    const auto seen = seen_chunks.find(expected.chunk_start_offset);
    if (seen == seen_chunks.end() || !(seen->second == expected)) {
      return Bad(chunk_index_at[i], "summary: Chunk Index " + Str(i) +
                                        " does not match a Chunk record at byte " +
                                        Str(expected.chunk_start_offset));
    }
  }
  const auto check = [&](const std::map<uint64_t, uint64_t>& seen, uint64_t offset, uint64_t length,
                         const char* what) -> Status {
    const auto it = seen.find(offset);
    if (it != seen.end() && it->second == length) return {};
    return Bad(offset, std::string("summary: no ") + what + " record of " + Str(length) +
                           " bytes starts here, as its index says");
  };
  if (attachment_indexes.size() != seen_attachments.size() ||
      metadata_indexes.size() != seen_metadata.size()) {
    return Bad(data_end, "the summary's Attachment or Metadata Indexes miss some records");
  }
  for (const auto& index : attachment_indexes) {
    if (Status s = check(seen_attachments, index.offset, index.length, "Attachment"); !s) return s;
  }
  for (const auto& index : metadata_indexes) {
    if (Status s = check(seen_metadata, index.offset, index.length, "Metadata"); !s) return s;
  }
  return {};
}

void Reader::Impl::ComposeNote(const std::string& why, const ScanEnd& end) {
  std::string lost;
  switch (end.kind) {
    case ScanEnd::Kind::kLimit:
      lost = "the file ends between two records: what came after was never written";
      break;
    case ScanEnd::Kind::kFooter:
      lost = "the data section ends at the Footer, at byte " + Str(end.at) + ", without Data End";
      break;
    case ScanEnd::Kind::kDataEnd:
      lost = "the data section is whole (its Data End is at byte " + Str(end.at) + ")";
      break;
    case ScanEnd::Kind::kCutHeader:
      lost = "the last " + Str(source->size() - end.at) + " bytes (a record header) are lost";
      break;
    case ScanEnd::Kind::kCutRecord:
      lost = (Is(end.opcode, Opcode::kChunk) ? std::string("the rest of the last chunk is lost")
                                             : "the rest of the last record (" +
                                                   internal::OpcodeName(end.opcode) + ") is lost") +
             " (from byte " + Str(end.at) + " it says " + Str(end.record_bytes) +
             " bytes follow its header; " + Str(source->size() - end.at - kRecordPrefixBytes) +
             " are there)";
      break;
    case ScanEnd::Kind::kDamaged:
      lost = "the record at byte " + Str(end.at) + " is damaged (" + end.problem +
             "): it and the " + Str(source->size() - end.at) + " bytes from there on are skipped";
      break;
  }
  note = name + ": no summary (" + why + "): read " + Count(recovered_messages, "message") +
         " in " + Count(recovered_chunks, "whole chunk") + ", up to byte " + Str(end.at) + "; " +
         lost;
}

Status Reader::Impl::Load() {
  bool cut = false;
  if (Status s = LoadHeader(cut); !s) return s;
  if (cut) {
    data_start = data_end = source->size();
    note = name + ": no summary (the file was cut short at byte " + Str(source->size()) +
           ", before the end of its Header): no messages";
    return {};
  }
  std::string why;
  Result<bool> summary = LoadSummary(why);
  if (!summary.ok()) return summary.error();
  ScanEnd end;
  if (*summary) {
    indexed = true;
    if (Status s = Scan(data_end, /*strict=*/true, end); !s) return s;
    if (data_end_crc != 0 && crc != data_end_crc) {
      return Bad(data_end, "data-section CRC mismatch: the Data End says " + Hex32(data_end_crc) +
                               ", bytes 0 to " + Str(data_end) + " give " + Hex32(crc));
    }
    recovered_messages = recovered_chunks = 0;
    std::string().swap(scratch);
    return CheckIndexes();
  }
  if (Status s = Scan(source->size(), /*strict=*/false, end); !s) return s;
  data_end = end.at;
  ComposeNote(why, end);
  // Open()'s buffers can hold a chunk of hundreds of MiB; iteration has its own.
  std::string().swap(scratch);
  std::string().swap(decoded);
  return {};
}

}  // namespace stevi::mcap
