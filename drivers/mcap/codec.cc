#include "drivers/mcap/codec.h"

#include <lz4frame.h>
#include <zlib.h>
#include <zstd.h>

#include <algorithm>
#include <limits>

namespace stevi::mcap {

std::string_view CompressionName(Compression c) {
  switch (c) {
    case Compression::kNone: return "";
    case Compression::kZstd: return "zstd";
    case Compression::kLz4: return "lz4";
  }
  return "";
}

std::optional<Compression> CompressionFromName(std::string_view name) {
  if (name.empty()) return Compression::kNone;
  if (name == "zstd") return Compression::kZstd;
  if (name == "lz4") return Compression::kLz4;
  return std::nullopt;
}

namespace internal {

uint32_t Crc32(std::string_view bytes, uint32_t crc) {
  // zlib's length is an unsigned int: feed large buffers in pieces.
  constexpr size_t kPiece = size_t{1} << 30;
  uLong value = crc;
  for (size_t at = 0; at < bytes.size(); at += kPiece) {
    const size_t n = std::min(kPiece, bytes.size() - at);
    value = crc32(value, reinterpret_cast<const Bytef*>(bytes.data() + at), static_cast<uInt>(n));
  }
  return static_cast<uint32_t>(value);
}

// ---- Encoder ------------------------------------------------------------------------------------

void Encoder::Le(uint64_t v, int bytes) {
  for (int i = 0; i < bytes; ++i) out_.push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
}

void Encoder::String(std::string_view s) {
  U32(static_cast<uint32_t>(s.size()));
  out_.append(s);
}

void Encoder::PatchU32Length(size_t at) {
  const uint64_t n = out_.size() - at - 4;
  for (int i = 0; i < 4; ++i) out_[at + i] = static_cast<char>((n >> (8 * i)) & 0xFF);
}

template <class Entries, class Put>
void Encoder::PrefixedEntries(const Entries& entries, Put put) {
  const size_t at = out_.size();
  U32(0);
  for (const auto& [key, value] : entries) put(key, value);
  PatchU32Length(at);
}

void Encoder::StringMap(const std::map<std::string, std::string>& map) {
  PrefixedEntries(map, [this](std::string_view key, std::string_view value) {
    String(key);
    String(value);
  });
}

void Encoder::U16U64Map(const std::map<uint16_t, uint64_t>& map) {
  PrefixedEntries(map, [this](uint16_t key, uint64_t value) {
    U16(key);
    U64(value);
  });
}

void Encoder::U64PairArray(const std::vector<std::pair<uint64_t, uint64_t>>& array) {
  PrefixedEntries(array, [this](uint64_t first, uint64_t second) {
    U64(first);
    U64(second);
  });
}

size_t Encoder::BeginRecord(Opcode op) {
  const size_t start = out_.size();
  U8(static_cast<uint8_t>(op));
  U64(0);
  return start;
}

void Encoder::EndRecord(size_t start) {
  const uint64_t n = out_.size() - start - 9;
  for (int i = 0; i < 8; ++i) out_[start + 1 + i] = static_cast<char>((n >> (8 * i)) & 0xFF);
}

// ---- Decoder ------------------------------------------------------------------------------------

void Decoder::Fail(std::string problem) {
  if (problem_.empty()) problem_ = std::move(problem);
  pos_ = bytes_.size();
}

bool Decoder::Need(uint64_t n, const char* field) {
  if (!ok()) return false;
  if (n <= left()) return true;
  Fail(std::string(field) + ": needs " + std::to_string(n) + " bytes, " + std::to_string(left()) +
       " left in the record");
  return false;
}

uint64_t Decoder::Le(int bytes, const char* field) {
  if (!Need(static_cast<uint64_t>(bytes), field)) return 0;
  uint64_t v = 0;
  for (int i = 0; i < bytes; ++i) {
    v |= uint64_t{static_cast<uint8_t>(bytes_[pos_ + i])} << (8 * i);
  }
  pos_ += static_cast<uint64_t>(bytes);
  return v;
}

uint8_t Decoder::U8(const char* field) { return static_cast<uint8_t>(Le(1, field)); }
uint16_t Decoder::U16(const char* field) { return static_cast<uint16_t>(Le(2, field)); }
uint32_t Decoder::U32(const char* field) { return static_cast<uint32_t>(Le(4, field)); }
uint64_t Decoder::U64(const char* field) { return Le(8, field); }

std::string_view Decoder::View(uint64_t n, const char* field) {
  if (!Need(n, field)) return {};
  const std::string_view v = bytes_.substr(pos_, n);
  pos_ += n;
  return v;
}

std::string_view Decoder::Rest() { return View(left(), "data"); }

std::string Decoder::String(const char* field) {
  const uint32_t n = U32(field);
  return std::string(View(n, field));
}

std::map<std::string, std::string> Decoder::StringMap(const char* field) {
  std::map<std::string, std::string> map;
  const uint32_t n = U32(field);
  Decoder entries(View(n, field));
  while (ok() && entries.ok() && entries.left() > 0) {
    std::string key = entries.String(field);
    std::string value = entries.String(field);
    if (entries.ok()) map.emplace(std::move(key), std::move(value));  // the first of a key wins
  }
  if (!entries.ok()) Fail(entries.problem());
  return map;
}

std::map<uint16_t, uint64_t> Decoder::U16U64Map(const char* field) {
  std::map<uint16_t, uint64_t> map;
  const uint32_t n = U32(field);
  if (ok() && n % 10 != 0) {
    Fail(std::string(field) + ": " + std::to_string(n) + " bytes is not a whole number of entries");
  }
  Decoder entries(View(n, field));
  while (ok() && entries.left() > 0) {
    const uint16_t key = entries.U16(field);
    map.emplace(key, entries.U64(field));
  }
  return map;
}

std::vector<std::pair<uint64_t, uint64_t>> Decoder::U64PairArray(const char* field) {
  std::vector<std::pair<uint64_t, uint64_t>> array;
  const uint32_t n = U32(field);
  if (ok() && n % 16 != 0) {
    Fail(std::string(field) + ": " + std::to_string(n) + " bytes is not a whole number of entries");
  }
  Decoder entries(View(n, field));
  if (!ok()) return array;
  array.reserve(n / 16);  // bounded by the bytes there
  while (entries.left() > 0) {
    const uint64_t first = entries.U64(field);
    array.emplace_back(first, entries.U64(field));
  }
  return array;
}

// ---- Compression --------------------------------------------------------------------------------

struct Compressor::Contexts {
  ZSTD_CCtx* zstd = nullptr;
};

Compressor::Compressor() : contexts_(std::make_unique<Contexts>()) {}

Compressor::~Compressor() { ZSTD_freeCCtx(contexts_->zstd); }

bool Compressor::Compress(Compression c, std::string_view in, std::string& out) {
  if (c == Compression::kZstd) {
    if (contexts_->zstd == nullptr) contexts_->zstd = ZSTD_createCCtx();
    if (contexts_->zstd == nullptr) return false;
    out.resize(ZSTD_compressBound(in.size()));
    const size_t n = ZSTD_compressCCtx(contexts_->zstd, out.data(), out.size(), in.data(),
                                       in.size(), /*compressionLevel=*/1);
    if (ZSTD_isError(n) != 0) return false;
    out.resize(n);
    return true;
  }
  if (c == Compression::kLz4) {
    LZ4F_preferences_t prefs{};
    prefs.frameInfo.contentSize = in.size();
    out.resize(LZ4F_compressFrameBound(in.size(), &prefs));
    const size_t n = LZ4F_compressFrame(out.data(), out.size(), in.data(), in.size(), &prefs);
    if (LZ4F_isError(n) != 0) return false;
    out.resize(n);
    return true;
  }
  return false;
}

namespace {

Status Problem(std::string text) { return InvalidArgument(std::move(text)); }

Status DecompressZstd(std::string_view in, uint64_t size, std::string& out) {
  const size_t n = ZSTD_decompress(out.data(), size, in.data(), in.size());
  if (ZSTD_isError(n) != 0) {
    return Problem(std::string("zstd: ") + ZSTD_getErrorName(n) + " (the chunk says " +
                   std::to_string(size) + " bytes uncompressed)");
  }
  if (n != size) {
    return Problem("zstd: decompressed to " + std::to_string(n) + " bytes, the chunk says " +
                   std::to_string(size));
  }
  return {};
}

Status DecompressLz4(std::string_view in, uint64_t size, std::string& out) {
  LZ4F_dctx* dctx = nullptr;
  if (LZ4F_isError(LZ4F_createDecompressionContext(&dctx, LZ4F_VERSION)) != 0) {
    return Internal("lz4: cannot create a decompression context");
  }
  size_t produced = 0;
  size_t consumed = 0;
  size_t hint = 1;  // LZ4F_decompress returns 0 once a frame ends
  std::string problem;
  while (consumed < in.size()) {
    size_t dst_size = size - produced;
    size_t src_size = in.size() - consumed;
    hint = LZ4F_decompress(dctx, out.data() + produced, &dst_size, in.data() + consumed, &src_size,
                           nullptr);
    if (LZ4F_isError(hint) != 0) {
      problem = std::string("lz4: ") + LZ4F_getErrorName(hint);
      break;
    }
    produced += dst_size;
    consumed += src_size;
    if (dst_size == 0 && src_size == 0) {  // the output is full and the frame has more
      problem =
          "lz4: the frame holds more than the " + std::to_string(size) + " bytes the chunk says";
      break;
    }
  }
  LZ4F_freeDecompressionContext(dctx);
  if (!problem.empty()) return Problem(problem);
  if (hint != 0) return Problem("lz4: the frame is cut short");
  if (produced != size) {
    return Problem("lz4: decompressed to " + std::to_string(produced) + " bytes, the chunk says " +
                   std::to_string(size));
  }
  return {};
}

}  // namespace

Status Decompress(std::string_view compression, std::string_view in, uint64_t size,
                  std::string& out) {
  if (size > std::numeric_limits<size_t>::max()) return Problem("chunk too large");
  out.resize(size);
  if (compression == "zstd") return DecompressZstd(in, size, out);
  if (compression == "lz4") {
    if (in.empty() && size == 0) return {};
    return DecompressLz4(in, size, out);
  }
  return Problem("unknown compression \"" + std::string(compression.substr(0, 32)) + "\"");
}

}  // namespace internal
}  // namespace stevi::mcap
