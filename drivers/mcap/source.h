// Internal to drivers/mcap: the bytes a reader reads (a file through pread, or memory), and the
// helpers shared by Open()'s checks and the message iteration: framing one record inside a byte
// range, and decoding a chunk's records.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>

#include "core/common/error.h"
#include "drivers/mcap/records.h"

namespace stevi::mcap::internal {

class Source {
 public:
  virtual ~Source() = default;
  uint64_t size() const { return size_; }
  // The `n` bytes at `offset` (the caller keeps offset + n <= size()). The view points into the
  // source (memory) or into `scratch` (a file), and lives until `scratch` is reused.
  virtual Result<std::string_view> Read(uint64_t offset, uint64_t n, std::string& scratch) = 0;

 protected:
  uint64_t size_ = 0;
};

// kNotFound when `path` does not exist, kInvalidArgument when it is not a readable regular file.
Result<std::unique_ptr<Source>> OpenFileSource(const std::string& path);
std::unique_ptr<Source> MemorySource(std::string bytes);

// One record framed inside a byte range.
struct RecordView {
  uint8_t opcode = 0;
  std::string_view content;
  uint64_t size() const { return kRecordPrefixBytes + content.size(); }
};

// The record starting at `pos` of `bytes`; a problem ("the Chunk record says 900 bytes, only 12
// are left") when its header or content does not fit, or its opcode is 0. The caller names the
// byte.
Result<RecordView> RecordIn(std::string_view bytes, uint64_t pos);

// A chunk's records, uncompressed and checked: uncompressed_size at most `max_bytes`, a known
// compression, the size it decompresses to, and the CRC when it is not 0. The view points into
// `chunk.records` (no compression) or into `buffer`. A problem names the check that failed.
Result<std::string_view> DecodeChunk(const ChunkRecord& chunk, uint64_t max_bytes,
                                     std::string& buffer);

// "0x1234ABCD".
std::string Hex32(uint32_t value);

}  // namespace stevi::mcap::internal
