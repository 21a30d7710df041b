// Internal to drivers/mcap: the spec's serialization primitives (little-endian integers,
// u32-prefixed strings, maps and arrays), CRC-32 and chunk compression.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "core/common/error.h"
#include "drivers/mcap/mcap_format.h"

namespace stevi::mcap::internal {

// CRC-32 as zlib computes it (reflected 0xEDB88320, init and final xor 0xFFFFFFFF), continuing
// from `crc` (0 to start): Crc32(b, Crc32(a)) == Crc32(a + b).
uint32_t Crc32(std::string_view bytes, uint32_t crc = 0);

// Appends the spec's fields to a string.
class Encoder {
 public:
  explicit Encoder(std::string& out) : out_(out) {}
  void U8(uint8_t v) { out_.push_back(static_cast<char>(v)); }
  void U16(uint16_t v) { Le(v, 2); }
  void U32(uint32_t v) { Le(v, 4); }
  void U64(uint64_t v) { Le(v, 8); }
  // u32 byte length + bytes (the caller keeps it under 4 GiB).
  void String(std::string_view s);
  // Bytes with no prefix.
  void Raw(std::string_view s) { out_.append(s); }
  void StringMap(const std::map<std::string, std::string>& map);
  void U16U64Map(const std::map<uint16_t, uint64_t>& map);
  // u32 byte length + (u64, u64) entries.
  void U64PairArray(const std::vector<std::pair<uint64_t, uint64_t>>& array);
  // Starts a record: the opcode and a length to be patched by EndRecord(start).
  size_t BeginRecord(Opcode op);
  void EndRecord(size_t start);

 private:
  void Le(uint64_t v, int bytes);
  // Patches a u32 byte length written at `at` to cover what follows it.
  void PatchU32Length(size_t at);
  // u32 byte length + each (key, value) entry as `put` writes it (used in codec.cc only).
  template <class Entries, class Put>
  void PrefixedEntries(const Entries& entries, Put put);
  std::string& out_;
};

// Reads the spec's fields from bounded bytes. Every read checks the bytes left; the first failure
// sticks (later reads return zeros and empty values) and problem() says what it was, naming the
// field.
class Decoder {
 public:
  explicit Decoder(std::string_view bytes) : bytes_(bytes) {}
  uint8_t U8(const char* field);
  uint16_t U16(const char* field);
  uint32_t U32(const char* field);
  uint64_t U64(const char* field);
  std::string String(const char* field);
  // `n` raw bytes.
  std::string_view View(uint64_t n, const char* field);
  // What is left (a record's last Bytes field).
  std::string_view Rest();
  std::map<std::string, std::string> StringMap(const char* field);
  std::map<uint16_t, uint64_t> U16U64Map(const char* field);
  std::vector<std::pair<uint64_t, uint64_t>> U64PairArray(const char* field);

  bool ok() const { return problem_.empty(); }
  const std::string& problem() const { return problem_; }
  uint64_t position() const { return pos_; }
  uint64_t left() const { return bytes_.size() - pos_; }
  // Records the first problem (also for checks made by the caller).
  void Fail(std::string problem);

 private:
  // True when `n` more bytes are there; otherwise fails naming `field`.
  bool Need(uint64_t n, const char* field);
  uint64_t Le(int bytes, const char* field);
  std::string_view bytes_;
  uint64_t pos_ = 0;
  std::string problem_;
};

// Compresses chunks, keeping its zstd context between them. zstd at level 1 (the fastest: a
// recorder must keep up with the cameras), lz4 as one LZ4 frame with its content size.
class Compressor {
 public:
  Compressor();
  ~Compressor();
  Compressor(const Compressor&) = delete;
  Compressor& operator=(const Compressor&) = delete;
  // `in` compressed with `c` (not kNone) into `out`; false when the library fails.
  bool Compress(Compression c, std::string_view in, std::string& out);

 private:
  struct Contexts;
  std::unique_ptr<Contexts> contexts_;
};

// Decompresses a chunk's records stored with `compression` ("zstd" or "lz4") into `out`, which
// must come out exactly `size` bytes. A problem ("zstd: ...") when it does not.
Status Decompress(std::string_view compression, std::string_view in, uint64_t size,
                  std::string& out);

}  // namespace stevi::mcap::internal
