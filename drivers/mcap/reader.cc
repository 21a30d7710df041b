// The MCAP reader (drivers/mcap/mcap_reader.h).
//
// Open() reads the file once, front to back:
//   1. the leading magic and the Header;
//   2. the footer (the 29 bytes before the closing magic). When it is there and valid and points
//      at a Data End record, the summary is read and its CRC checked: the file is "indexed";
//   3. the data section, record by record, every length bounded by the bytes left and by
//      per-record limits, while its CRC is computed. An indexed file must be whole: its data
//      section must end exactly at the Data End, match that record's CRC, and agree with the
//      summary's indexes (every chunk, attachment and metadata record where they say); any
//      failure rejects the file. A file without a usable summary is read linearly instead: each
//      chunk is decompressed and its CRC checked, and the read stops at the first record that is
//      cut short or damaged; what came before is kept and note() says what was lost.
// Next() then walks the same data section again, one chunk at a time. Open() is in
// reader_open.cc.
#include "drivers/mcap/mcap_reader.h"

#include <utility>

#include "drivers/mcap/codec.h"
#include "drivers/mcap/reader_impl.h"

namespace stevi::mcap {

using internal::Decoder;
using internal::Is;
using internal::kRecordPrefixBytes;
using internal::RecordView;
using internal::Str;

std::vector<std::string> ReaderOptions::Validate() const {
  std::vector<std::string> problems;
  if (max_chunk_bytes < 1024 || max_chunk_bytes > kMaxChunkBytes) {
    problems.push_back("max_chunk_bytes: must be in [1 KiB, 512 MiB]" +
                       Got(static_cast<double>(max_chunk_bytes)));
  }
  return problems;
}

// ---- Iteration ----------------------------------------------------------------------------------

Result<std::optional<Message>> Reader::Impl::NextInChunk() {
  const uint64_t p = record_pos;
  Result<RecordView> record = internal::RecordIn(records, p);
  if (!record.ok()) {
    return Bad(chunk_at, "Chunk: its record at byte " + Str(p) + ": " + record.error().message);
  }
  record_pos += record->size();
  Result<std::optional<Message>> message = Interpret(record->opcode, record->content);
  if (!message.ok()) {
    return Bad(chunk_at, "Chunk: its record at byte " + Str(p) + ": " + message.error().message);
  }
  return message;
}

Result<std::optional<Message>> Reader::Impl::NextMessage() {
  while (true) {
    if (record_pos < records.size()) {
      Result<std::optional<Message>> message = NextInChunk();
      if (!message.ok() || message->has_value()) return message;
      continue;
    }
    if (pos >= data_end) return std::optional<Message>();
    const uint64_t at = pos;
    Result<std::string_view> prefix = source->Read(at, kRecordPrefixBytes, iter_head);
    if (!prefix.ok()) return prefix.error();
    Decoder d(*prefix);
    const uint8_t opcode = d.U8("opcode");
    const uint64_t length = d.U64("length");
    // Open() checked the framing up to data_end; a file can still change under us.
    if (data_end - at < kRecordPrefixBytes || length > data_end - at - kRecordPrefixBytes) {
      return Bad(at, "the record no longer fits: the file changed since it was opened");
    }
    pos = at + kRecordPrefixBytes + length;
    if (!Is(opcode, Opcode::kChunk) && !Is(opcode, Opcode::kMessage) &&
        !Is(opcode, Opcode::kSchema) && !Is(opcode, Opcode::kChannel)) {
      continue;
    }
    Result<std::string_view> content = source->Read(at + kRecordPrefixBytes, length, iter_raw);
    if (!content.ok()) return content.error();
    if (!Is(opcode, Opcode::kChunk)) {
      Result<std::optional<Message>> message = Interpret(opcode, *content);
      if (!message.ok()) return Bad(at, message.error().message);
      if (message->has_value()) return message;
      continue;
    }
    Result<internal::ChunkRecord> chunk = internal::ParseChunk(*content);
    if (!chunk.ok()) return Bad(at, chunk.error().message);
    Result<std::string_view> inner =
        internal::DecodeChunk(*chunk, options.max_chunk_bytes, iter_decoded);
    if (!inner.ok()) return Bad(at, "Chunk: " + inner.error().message);
    records = *inner;
    record_pos = 0;
    chunk_at = at;
  }
}

// ---- Reader -------------------------------------------------------------------------------------

Reader::Reader(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Reader::~Reader() = default;

namespace {

Result<std::unique_ptr<Reader>> Problems(const std::string& name, const ReaderOptions& options) {
  std::vector<std::string> problems;
  AppendPrefixed(problems, "options.", options.Validate());
  if (!problems.empty()) return InvalidArgument(problems).Prefixed(name + ": ");
  return std::unique_ptr<Reader>();
}

}  // namespace

Result<std::unique_ptr<Reader>> Reader::Open(const std::string& path, ReaderOptions options) {
  if (Result<std::unique_ptr<Reader>> bad = Problems(path, options); !bad.ok()) return bad;
  Result<std::unique_ptr<internal::Source>> source = internal::OpenFileSource(path);
  if (!source.ok()) return source.error();
  auto impl = std::make_unique<Impl>();
  impl->name = path;
  impl->options = options;
  impl->source = std::move(*source);
  if (Status loaded = impl->Load(); !loaded) return loaded.error();
  impl->pos = impl->data_start;
  return std::unique_ptr<Reader>(new Reader(std::move(impl)));
}

Result<std::unique_ptr<Reader>> Reader::FromBytes(std::string bytes, std::string name,
                                                  ReaderOptions options) {
  if (Result<std::unique_ptr<Reader>> bad = Problems(name, options); !bad.ok()) return bad;
  auto impl = std::make_unique<Impl>();
  impl->name = std::move(name);
  impl->options = options;
  impl->source = internal::MemorySource(std::move(bytes));
  if (Status loaded = impl->Load(); !loaded) return loaded.error();
  impl->pos = impl->data_start;
  return std::unique_ptr<Reader>(new Reader(std::move(impl)));
}

const std::string& Reader::name() const { return impl_->name; }
uint64_t Reader::file_size() const { return impl_->source->size(); }
const Header& Reader::header() const { return impl_->header; }
const std::map<uint16_t, Schema>& Reader::schemas() const { return impl_->schemas; }
const std::map<uint16_t, Channel>& Reader::channels() const { return impl_->channels; }

const Schema* Reader::schema(uint16_t id) const {
  const auto it = impl_->schemas.find(id);
  return it == impl_->schemas.end() ? nullptr : &it->second;
}

const Channel* Reader::channel(uint16_t id) const {
  const auto it = impl_->channels.find(id);
  return it == impl_->channels.end() ? nullptr : &it->second;
}

const std::optional<Statistics>& Reader::statistics() const { return impl_->statistics; }
const std::vector<ChunkIndex>& Reader::chunk_indexes() const { return impl_->chunk_indexes; }
const std::vector<Metadata>& Reader::metadata() const { return impl_->metadata; }
const std::vector<Attachment>& Reader::attachments() const { return impl_->attachments; }
bool Reader::indexed() const { return impl_->indexed; }
const std::string& Reader::note() const { return impl_->note; }
uint64_t Reader::recovered_messages() const { return impl_->recovered_messages; }
uint64_t Reader::recovered_chunks() const { return impl_->recovered_chunks; }

Result<std::optional<Message>> Reader::Next() {
  Impl& r = *impl_;
  if (r.iter_error) return *r.iter_error;
  Result<std::optional<Message>> next = r.NextMessage();
  if (!next.ok()) r.iter_error = next.error();
  return next;
}

void Reader::Rewind() {
  Impl& r = *impl_;
  r.pos = r.data_start;
  r.records = {};
  r.record_pos = 0;
  r.iter_error.reset();
}

Result<std::vector<Message>> Reader::ReadAll() {
  Rewind();
  std::vector<Message> messages;
  while (true) {
    Result<std::optional<Message>> next = Next();
    if (!next.ok()) return next.error();
    if (!next->has_value()) return messages;
    messages.push_back(std::move(**next));
  }
}

}  // namespace stevi::mcap
