// The MCAP writer (drivers/mcap/mcap_writer.h). Layout of a file it writes:
//   magic, Header,
//   for each chunk: Chunk (Schema and Channel records before a channel's first message, then the
//     Messages), one Message Index per channel with messages in it (entries in log-time order),
//   Metadata and Attachment records where they were added (between chunks),
//   Data End (CRC of every byte before it), then the summary, grouped by opcode: Schemas,
//   Channels, Statistics, Chunk Indexes, Attachment Indexes, Metadata Indexes; the Summary
//   Offsets (one per group), Footer (summary CRC), magic.
// This is the layout of the reference C++ writer's summary, which Foxglove opens indexed.
#include "drivers/mcap/mcap_writer.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <utility>

#include "drivers/mcap/codec.h"
#include "drivers/mcap/records.h"

namespace stevi::mcap {
namespace {

using internal::Crc32;

// The writer's own bound on chunk_bytes: half the reader's, leaving room for the message that
// fills a chunk.
constexpr uint64_t kMaxOptionChunkBytes = uint64_t{256} << 20;
constexpr size_t kMaxHeaderStringBytes = 4096;
// Chunks smaller than this are stored uncompressed, and so are chunks that compress by less than
// 2 % (the reference writer's rules: not worth a reader's time to decompress).
constexpr uint64_t kMinCompressBytes = 1024;

// A failed write's code: a full disk or a file-size limit is an exhausted resource, the rest (EIO,
// a vanished device) an unavailable one.
ErrorCode WriteErrorCode(int err) {
  return (err == ENOSPC || err == EDQUOT || err == EFBIG) ? ErrorCode::kResourceExhausted
                                                          : ErrorCode::kUnavailable;
}

// Frees a buffer that one large message grew far beyond what chunks need.
void ReleaseIfLarge(std::string& buffer, uint64_t chunk_bytes) {
  if (buffer.capacity() > 4 * chunk_bytes + (uint64_t{4} << 20)) std::string().swap(buffer);
}

uint64_t MapBytes(const std::map<std::string, std::string>& map) {
  uint64_t n = 0;
  for (const auto& [key, value] : map) n += 8 + key.size() + value.size();
  return n;
}

}  // namespace

std::vector<std::string> WriterOptions::Validate() const {
  std::vector<std::string> problems;
  if (compression != Compression::kNone && compression != Compression::kZstd &&
      compression != Compression::kLz4) {
    problems.push_back("compression: must be kNone, kZstd or kLz4" +
                       Got(static_cast<int>(compression)));
  }
  if (chunk_bytes < 1 || chunk_bytes > kMaxOptionChunkBytes) {
    problems.push_back("chunk_bytes: must be in [1, 256 MiB]" +
                       Got(static_cast<double>(chunk_bytes)));
  }
  if (chunk_span_ns <= 0) {
    problems.push_back("chunk_span_ns: must be > 0" + Got(static_cast<double>(chunk_span_ns)));
  }
  if (profile.size() > kMaxHeaderStringBytes) {
    problems.push_back("profile: at most 4096 bytes" + Got(static_cast<double>(profile.size())));
  }
  if (library.size() > kMaxHeaderStringBytes) {
    problems.push_back("library: at most 4096 bytes" + Got(static_cast<double>(library.size())));
  }
  return problems;
}

struct Writer::Impl {
  std::string name;  // the path, or the name given with the file descriptor
  WriterOptions options;
  int fd = -1;
  uint64_t offset = 0;           // bytes written so far
  uint32_t data_crc = 0;         // CRC of bytes [0, offset) while in the data section
  std::optional<Error> failure;  // the first write failure: sticky
  bool closed = false;
  Status close_result;

  std::vector<Schema> schemas;  // schemas[id - 1]
  std::vector<bool> schema_written;
  std::vector<Channel> channels;  // channels[id - 1]
  std::vector<bool> channel_written;
  std::vector<uint32_t> next_sequence;

  // The open chunk: its records uncompressed, and each channel's (log_time, offset) entries.
  std::string chunk;
  std::map<uint16_t, std::vector<std::pair<uint64_t, uint64_t>>> chunk_entries;
  uint64_t chunk_start_ns = 0;
  uint64_t chunk_end_ns = 0;

  internal::Compressor compressor;
  std::string compressed;  // reused between chunks
  std::string out;         // the bytes of one write, reused

  uint64_t messages = 0;
  Statistics stats;
  std::vector<ChunkIndex> chunk_indexes;
  std::vector<internal::AttachmentIndex> attachment_indexes;
  std::vector<internal::MetadataIndex> metadata_indexes;

  // Why nothing can be written now (closed, failed), or OK.
  Status Usable() const;
  // Writes all of `bytes` at the end of the file. On failure the error becomes sticky and the file
  // is cut back to `offset` (the end of the last whole write) where it can be.
  Status WriteOut(std::string_view bytes, bool data_section);
  // The Schema and Channel records the channel's first message needs, not yet written.
  std::string PendingDefinitions(uint16_t channel_id) const;
  void MarkDefined(uint16_t channel_id);
  // Writes the open chunk (if any) and its Message Indexes.
  Status FlushChunk();
  // The chunk's records as stored: compressed when that pays.
  internal::ChunkRecord StoredChunk();
  // Data End, the summary, Summary Offsets, Footer and magic; then syncs.
  Status Finish();
  void AppendSummaryGroups(uint64_t base, std::vector<internal::SummaryOffset>& groups);
};

Status Writer::Impl::Usable() const {
  if (failure) return *failure;
  if (closed) return FailedPrecondition(name + ": the writer is closed");
  return {};
}

Status Writer::Impl::WriteOut(std::string_view bytes, bool data_section) {
  if (failure) return *failure;
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n > 0) {
      done += static_cast<size_t>(n);
      continue;
    }
    const int err = n < 0 ? errno : EIO;  // write() returning 0 for a non-empty buffer: no room
    if (err == EINTR) continue;
    // Cut off the partial write so that the file ends on a whole record (fails harmlessly on
    // pipes and devices).
    if (done > 0) (void)::ftruncate(fd, static_cast<off_t>(offset));
    failure = Error{WriteErrorCode(err), name + ": cannot write (" + std::strerror(err) +
                                             ") at byte " + std::to_string(offset) +
                                             "; the file keeps what was written before"};
    return *failure;
  }
  if (data_section) data_crc = Crc32(bytes, data_crc);
  offset += bytes.size();
  return {};
}

std::string Writer::Impl::PendingDefinitions(uint16_t channel_id) const {
  std::string records;
  if (channel_written[channel_id - 1]) return records;
  const Channel& channel = channels[channel_id - 1];
  if (channel.schema_id != 0 && !schema_written[channel.schema_id - 1]) {
    internal::AppendSchema(records, schemas[channel.schema_id - 1]);
  }
  internal::AppendChannel(records, channel);
  return records;
}

void Writer::Impl::MarkDefined(uint16_t channel_id) {
  channel_written[channel_id - 1] = true;
  const uint16_t schema_id = channels[channel_id - 1].schema_id;
  if (schema_id != 0) schema_written[schema_id - 1] = true;
}

internal::ChunkRecord Writer::Impl::StoredChunk() {
  internal::ChunkRecord record;
  record.message_start_time_ns = chunk_start_ns;
  record.message_end_time_ns = chunk_end_ns;
  record.uncompressed_size = chunk.size();
  record.uncompressed_crc = Crc32(chunk);
  record.records = chunk;
  if (options.compression != Compression::kNone && chunk.size() >= kMinCompressBytes &&
      compressor.Compress(options.compression, chunk, compressed) &&
      chunk.size() * 100 >= compressed.size() * 102) {
    record.compression = std::string(CompressionName(options.compression));
    record.records = compressed;
  }
  return record;
}

Status Writer::Impl::FlushChunk() {
  if (chunk.empty()) return {};
  const internal::ChunkRecord record = StoredChunk();
  out.clear();
  internal::AppendChunk(out, record);
  ChunkIndex index;
  index.message_start_time_ns = record.message_start_time_ns;
  index.message_end_time_ns = record.message_end_time_ns;
  index.chunk_start_offset = offset;
  index.chunk_length = out.size();
  index.compression = record.compression;
  index.compressed_size = record.records.size();
  index.uncompressed_size = record.uncompressed_size;
  for (auto& [channel_id, entries] : chunk_entries) {
    // Readers binary-search an index by log time: keep each sorted (stable: equal times keep
    // their file order).
    std::stable_sort(entries.begin(), entries.end(),
                     [](const auto& a, const auto& b) { return a.first < b.first; });
    index.message_index_offsets[channel_id] = offset + out.size();
    internal::AppendMessageIndex(out, internal::MessageIndex{channel_id, entries});
  }
  index.message_index_length = out.size() - index.chunk_length;
  if (Status written = WriteOut(out, /*data_section=*/true); !written) return written;
  chunk_indexes.push_back(std::move(index));
  ++stats.chunk_count;
  chunk.clear();
  chunk_entries.clear();
  ReleaseIfLarge(chunk, options.chunk_bytes);
  ReleaseIfLarge(compressed, options.chunk_bytes);
  ReleaseIfLarge(out, options.chunk_bytes);
  return {};
}

void Writer::Impl::AppendSummaryGroups(uint64_t base,
                                       std::vector<internal::SummaryOffset>& groups) {
  // Runs `append`, then notes the group of records it added (if any).
  const auto group = [&](Opcode op, const auto& append) {
    const size_t begin = out.size();
    append();
    if (out.size() > begin) {
      groups.push_back({static_cast<uint8_t>(op), base + begin, out.size() - begin});
    }
  };
  group(Opcode::kSchema, [&] {
    for (const Schema& schema : schemas) internal::AppendSchema(out, schema);
  });
  group(Opcode::kChannel, [&] {
    for (const Channel& channel : channels) internal::AppendChannel(out, channel);
  });
  group(Opcode::kStatistics, [&] {
    Statistics s = stats;
    s.schema_count = static_cast<uint16_t>(schemas.size());
    s.channel_count = static_cast<uint32_t>(channels.size());
    internal::AppendStatistics(out, s);
  });
  group(Opcode::kChunkIndex, [&] {
    for (const ChunkIndex& index : chunk_indexes) internal::AppendChunkIndex(out, index);
  });
  group(Opcode::kAttachmentIndex, [&] {
    for (const auto& index : attachment_indexes) internal::AppendAttachmentIndex(out, index);
  });
  group(Opcode::kMetadataIndex, [&] {
    for (const auto& index : metadata_indexes) internal::AppendMetadataIndex(out, index);
  });
}

Status Writer::Impl::Finish() {
  if (Status flushed = FlushChunk(); !flushed) return flushed;
  out.clear();
  // The data-section CRC covers every byte before the Data End record.
  internal::AppendDataEnd(out, data_crc);
  const uint64_t summary_start = offset + out.size();
  std::vector<internal::SummaryOffset> groups;
  AppendSummaryGroups(offset, groups);
  const uint64_t summary_offset_start = offset + out.size();
  for (const internal::SummaryOffset& group : groups) internal::AppendSummaryOffset(out, group);
  internal::AppendFooter(out, {summary_start, summary_offset_start, 0});
  // The summary CRC covers the summary start through the footer's summary_offset_start field:
  // all but the footer's last 4 bytes, which receive it.
  const size_t from = summary_start - offset;
  const uint32_t crc = Crc32(std::string_view(out).substr(from, out.size() - 4 - from));
  for (int i = 0; i < 4; ++i) out[out.size() - 4 + i] = static_cast<char>((crc >> (8 * i)) & 0xFF);
  out.append(kMagic);
  if (Status written = WriteOut(out, /*data_section=*/false); !written) return written;
  // A flight's file must survive a power cut after Close(). Pipes and some devices cannot sync.
  if (::fsync(fd) != 0 && errno != EINVAL && errno != EROFS) {
    const int err = errno;
    failure = Error{WriteErrorCode(err), name + ": cannot sync (" + std::strerror(err) + ")"};
    return *failure;
  }
  return {};
}

// ---- Writer -------------------------------------------------------------------------------------

Writer::Writer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

Writer::~Writer() {
  if (impl_->closed) return;
  if (Status closed = Close(); !closed) {
    std::fprintf(stderr, "stevi mcap: %s\n", closed.error().message.c_str());
  }
}

Result<std::unique_ptr<Writer>> Writer::Create(const std::string& path, WriterOptions options) {
  std::vector<std::string> problems;
  if (path.empty()) problems.push_back("path: must not be empty");
  AppendPrefixed(problems, "options.", options.Validate());
  if (!problems.empty()) return InvalidArgument(problems).Prefixed(path + ": ");
  // O_EXCL: never overwrite a flight, even one created a moment ago by someone else.
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd < 0) {
    const int err = errno;
    if (err == EEXIST) {
      return AlreadyExists(path + ": exists already; a recording is never overwritten");
    }
    return Error{(err == ENOENT || err == ENOTDIR) ? ErrorCode::kNotFound : ErrorCode::kInternal,
                 path + ": cannot create it (" + std::strerror(err) + ")"};
  }
  Result<std::unique_ptr<Writer>> writer = FromFd(fd, path, std::move(options));
  // Leave no half-written file behind, so that a retry is not refused.
  if (!writer.ok()) ::unlink(path.c_str());
  return writer;
}

Result<std::unique_ptr<Writer>> Writer::FromFd(int fd, std::string name, WriterOptions options) {
  std::vector<std::string> problems;
  if (fd < 0) problems.push_back("fd: must be an open file descriptor" + Got(fd));
  AppendPrefixed(problems, "options.", options.Validate());
  if (!problems.empty()) {
    if (fd >= 0) ::close(fd);
    return InvalidArgument(problems).Prefixed(name + ": ");
  }
  auto impl = std::make_unique<Impl>();
  impl->name = std::move(name);
  impl->options = std::move(options);
  impl->fd = fd;
  std::string& start = impl->out;
  start.assign(kMagic);
  internal::AppendHeader(start, Header{impl->options.profile, impl->options.library});
  if (Status written = impl->WriteOut(start, /*data_section=*/true); !written) {
    ::close(fd);
    return written.error();
  }
  return std::unique_ptr<Writer>(new Writer(std::move(impl)));
}

uint16_t Writer::AddSchema(std::string_view name, std::string_view encoding,
                           std::string_view data) {
  Impl& w = *impl_;
  for (const Schema& s : w.schemas) {
    if (s.name == name && s.encoding == encoding && s.data == data) return s.id;
  }
  if (w.schemas.size() >= 0xFFFF || data.size() > kMaxSchemaBytes ||
      name.size() + encoding.size() > kMaxRecordFieldsBytes) {
    return 0;
  }
  const auto id = static_cast<uint16_t>(w.schemas.size() + 1);
  w.schemas.push_back(Schema{id, std::string(name), std::string(encoding), std::string(data)});
  w.schema_written.push_back(false);
  return id;
}

uint16_t Writer::AddChannel(uint16_t schema_id, std::string_view topic,
                            std::string_view message_encoding,
                            const std::map<std::string, std::string>& metadata) {
  Impl& w = *impl_;
  for (const Channel& c : w.channels) {
    if (c.schema_id == schema_id && c.topic == topic && c.message_encoding == message_encoding &&
        c.metadata == metadata) {
      return c.id;
    }
  }
  if (schema_id > w.schemas.size() || w.channels.size() >= 0xFFFF ||
      topic.size() + message_encoding.size() + MapBytes(metadata) > kMaxRecordFieldsBytes) {
    return 0;
  }
  const auto id = static_cast<uint16_t>(w.channels.size() + 1);
  w.channels.push_back(
      Channel{id, schema_id, std::string(topic), std::string(message_encoding), metadata});
  w.channel_written.push_back(false);
  w.next_sequence.push_back(0);
  return id;
}

Status Writer::Write(uint16_t channel_id, uint64_t log_time_ns, uint64_t publish_time_ns,
                     std::string_view data) {
  Impl& w = *impl_;
  if (Status usable = w.Usable(); !usable) return usable;
  if (channel_id == 0 || channel_id > w.channels.size()) {
    return InvalidArgument(w.name + ": Write: unknown channel id " + std::to_string(channel_id));
  }
  if (data.size() > kMaxMessageBytes) {
    return InvalidArgument(w.name + ": Write: a message of " + std::to_string(data.size()) +
                           " bytes is over the limit of 256 MiB");
  }
  const std::string definitions = w.PendingDefinitions(channel_id);
  const uint64_t needed = definitions.size() + internal::kRecordPrefixBytes +
                          internal::kMessageFieldsBytes + data.size();
  // Keep every chunk within what readers accept: close this one first if it would overflow.
  if (!w.chunk.empty() && w.chunk.size() + needed > kMaxChunkBytes) {
    if (Status flushed = w.FlushChunk(); !flushed) return flushed;
  }
  w.chunk += definitions;
  w.MarkDefined(channel_id);
  const bool first_in_chunk = w.chunk_entries.empty();
  w.chunk_entries[channel_id].emplace_back(log_time_ns, w.chunk.size());
  internal::AppendMessage(w.chunk, channel_id, w.next_sequence[channel_id - 1]++, log_time_ns,
                          publish_time_ns, data);
  w.chunk_start_ns = first_in_chunk ? log_time_ns : std::min(w.chunk_start_ns, log_time_ns);
  w.chunk_end_ns = first_in_chunk ? log_time_ns : std::max(w.chunk_end_ns, log_time_ns);
  Statistics& s = w.stats;
  s.message_start_time_ns =
      s.message_count == 0 ? log_time_ns : std::min(s.message_start_time_ns, log_time_ns);
  s.message_end_time_ns = std::max(s.message_end_time_ns, log_time_ns);
  ++s.message_count;
  ++s.channel_message_counts[channel_id];
  ++w.messages;
  if (w.chunk.size() >= w.options.chunk_bytes ||
      w.chunk_end_ns - w.chunk_start_ns >= static_cast<uint64_t>(w.options.chunk_span_ns)) {
    return w.FlushChunk();
  }
  return {};
}

Status Writer::AddMetadata(std::string_view name,
                           const std::map<std::string, std::string>& values) {
  Impl& w = *impl_;
  if (Status usable = w.Usable(); !usable) return usable;
  if (name.size() + MapBytes(values) > kMaxRecordFieldsBytes) {
    return InvalidArgument(w.name + ": AddMetadata: " + std::string(name.substr(0, 64)) +
                           ": the name and values are over the limit of 1 MiB");
  }
  w.out.clear();
  internal::AppendMetadata(w.out, Metadata{std::string(name), values});
  const internal::MetadataIndex index{w.offset, w.out.size(), std::string(name)};
  if (Status written = w.WriteOut(w.out, /*data_section=*/true); !written) return written;
  w.metadata_indexes.push_back(index);
  ++w.stats.metadata_count;
  return {};
}

Status Writer::AddAttachment(std::string_view name, std::string_view media_type,
                             uint64_t log_time_ns, std::string_view data) {
  Impl& w = *impl_;
  if (Status usable = w.Usable(); !usable) return usable;
  if (data.size() > kMaxAttachmentBytes ||
      name.size() + media_type.size() > kMaxRecordFieldsBytes) {
    return InvalidArgument(w.name + ": AddAttachment: " + std::string(name.substr(0, 64)) +
                           ": over the limits (data 256 MiB, name and media type 1 MiB)");
  }
  const Attachment attachment{log_time_ns, log_time_ns, std::string(name), std::string(media_type),
                              std::string(data)};
  w.out.clear();
  internal::AppendAttachment(w.out, attachment);
  const internal::AttachmentIndex index{
      w.offset,    w.out.size(),    log_time_ns,          log_time_ns,
      data.size(), attachment.name, attachment.media_type};
  if (Status written = w.WriteOut(w.out, /*data_section=*/true); !written) return written;
  w.attachment_indexes.push_back(index);
  ++w.stats.attachment_count;
  return {};
}

Status Writer::Flush() {
  if (Status usable = impl_->Usable(); !usable) return usable;
  return impl_->FlushChunk();
}

Status Writer::Close() {
  Impl& w = *impl_;
  if (w.closed) return w.close_result;
  w.closed = true;
  Status result = w.failure ? Status(*w.failure) : w.Finish();
  if (::close(w.fd) != 0 && result.ok()) {
    const int err = errno;
    result = Error{WriteErrorCode(err), w.name + ": cannot close (" + std::strerror(err) + ")"};
  }
  w.fd = -1;
  w.close_result = result;
  return result;
}

uint64_t Writer::messages() const { return impl_->messages; }
uint64_t Writer::chunks() const { return impl_->stats.chunk_count; }
uint64_t Writer::bytes() const { return impl_->offset; }

}  // namespace stevi::mcap
