// Helpers for the drivers/mcap tests, written from the specification and independent of the
// library's own parsing: a CRC-32 built from the spec's parameters, a little-endian field reader,
// a record walker, and a sample file with known contents.
#pragma once

#include <array>
#include <cstdint>
#include <fstream>
#include <iterator>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include <gtest/gtest.h>

#include "drivers/mcap/mcap.h"

namespace stevi::mcap::test {

// CRC-32 from its definition in the spec (the ISO-HDLC / zlib variant): reflected polynomial
// 0xEDB88320, initial value and final xor 0xFFFFFFFF. Own table, no zlib.
inline uint32_t SpecCrc32(std::string_view bytes) {
  static const std::array<uint32_t, 256> table = [] {
    std::array<uint32_t, 256> t{};
    for (uint32_t n = 0; n < 256; ++n) {
      uint32_t c = n;
      for (int k = 0; k < 8; ++k) c = (c & 1) != 0 ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[n] = c;
    }
    return t;
  }();
  uint32_t crc = 0xFFFFFFFFu;
  for (const char ch : bytes) crc = table[(crc ^ static_cast<uint8_t>(ch)) & 0xFF] ^ (crc >> 8);
  return crc ^ 0xFFFFFFFFu;
}

// Little-endian fields at a byte offset (the test stops with a failure if out of range).
inline uint64_t Le(std::string_view bytes, uint64_t at, int width) {
  EXPECT_LE(at + width, bytes.size()) << "field at byte " << at << " past the end";
  if (at + width > bytes.size()) return 0;
  uint64_t v = 0;
  for (int i = 0; i < width; ++i) v |= uint64_t{static_cast<uint8_t>(bytes[at + i])} << (8 * i);
  return v;
}
inline uint64_t U64(std::string_view b, uint64_t at) { return Le(b, at, 8); }
inline uint32_t U32(std::string_view b, uint64_t at) { return static_cast<uint32_t>(Le(b, at, 4)); }
inline uint16_t U16(std::string_view b, uint64_t at) { return static_cast<uint16_t>(Le(b, at, 2)); }

// One record as the walker saw it.
struct Rec {
  uint8_t opcode = 0;
  uint64_t offset = 0;  // of the opcode
  std::string_view content;
  uint64_t size() const { return 9 + content.size(); }
};

// Every record in bytes [from, to): opcode u8 + length u64 LE + content. Fails the test when a
// record does not fit exactly.
inline std::vector<Rec> Walk(std::string_view bytes, uint64_t from, uint64_t to) {
  std::vector<Rec> records;
  uint64_t at = from;
  while (at < to) {
    if (to - at < 9) {
      ADD_FAILURE() << "a record header at byte " << at << " runs past " << to;
      break;
    }
    const uint64_t length = U64(bytes, at + 1);
    if (length > to - at - 9) {
      ADD_FAILURE() << "the record at byte " << at << " runs past " << to;
      break;
    }
    records.push_back(Rec{static_cast<uint8_t>(bytes[at]), at, bytes.substr(at + 9, length)});
    at += 9 + length;
  }
  return records;
}

// A string field (u32 length + bytes) at `at` of `content`; moves `at` past it.
inline std::string_view Str(std::string_view content, uint64_t& at) {
  const uint32_t n = U32(content, at);
  const std::string_view s = content.substr(at + 4, n);
  at += 4 + n;
  return s;
}

inline std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

inline void WriteFile(const std::string& path, std::string_view bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

// A message as the tests write it.
struct Sent {
  uint16_t channel = 0;
  uint64_t log_time_ns = 0;
  uint64_t publish_time_ns = 0;
  std::string data;
};

// Deterministic message data: compressible text with a counter, `size` bytes.
inline std::string Payload(uint64_t n, size_t size) {
  std::string s;
  while (s.size() < size) s += "frame " + std::to_string(n) + " of the stereo rig; ";
  s.resize(size);
  return s;
}

// Deterministic incompressible bytes (an xorshift stream).
inline std::string Noise(uint64_t seed, size_t size) {
  std::string s(size, '\0');
  uint64_t x = seed * 0x9E3779B97F4A7C15ull + 1;
  for (char& c : s) {
    x ^= x << 13;
    x ^= x >> 7;
    x ^= x << 17;
    c = static_cast<char>(x & 0xFF);
  }
  return s;
}

// Writes `messages` on channels "/a", "/b", "/c" (ids 1, 2, 3; /c without a schema) to a new file
// and closes it; fails the test on any error.
inline void WriteSample(const std::string& path, const WriterOptions& options,
                        const std::vector<Sent>& messages, bool extras = true) {
  Result<std::unique_ptr<Writer>> created = Writer::Create(path, options);
  ASSERT_TRUE(created.ok()) << created.error().message;
  Writer& w = **created;
  const uint16_t schema = w.AddSchema("stevi.test.Frame", "protobuf",
                                      std::string("\x0a\x05"
                                                  "frame",
                                                  7));
  ASSERT_EQ(schema, 1);
  ASSERT_EQ(w.AddChannel(schema, "/a", "protobuf", {{"rig", "left"}}), 1);
  ASSERT_EQ(w.AddChannel(schema, "/b", "protobuf"), 2);
  ASSERT_EQ(w.AddChannel(0, "/c", "json"), 3);
  if (extras) {
    ASSERT_TRUE(w.AddMetadata("calibration", {{"f_px", "700"}, {"baseline_m", "0.12"}}).ok());
  }
  for (size_t i = 0; i < messages.size(); ++i) {
    const Sent& m = messages[i];
    ASSERT_TRUE(w.Write(m.channel, m.log_time_ns, m.publish_time_ns, m.data).ok()) << i;
    if (extras && i == messages.size() / 2) {
      ASSERT_TRUE(w.AddAttachment("calibration.yaml", "application/yaml", m.log_time_ns,
                                  "f_px: 700\nbaseline_m: 0.12\n")
                      .ok());
    }
  }
  const Status closed = w.Close();
  ASSERT_TRUE(closed.ok()) << closed.error().message;
}

// `n` messages over the three channels, 10 ms apart in order of writing but with channel /b's
// log times 25 ms late and /c's 15 ms early, so that log times go back and forth.
inline std::vector<Sent> Interleaved(int n, size_t size,
                                     uint64_t t0_ns = 1'700'000'000'000'000'000ull) {
  std::vector<Sent> out;
  for (int i = 0; i < n; ++i) {
    Sent m;
    m.channel = static_cast<uint16_t>(1 + i % 3);
    const int64_t skew_ms = m.channel == 2 ? 25 : (m.channel == 3 ? -15 : 0);
    m.log_time_ns = t0_ns + static_cast<uint64_t>((i * 10 + skew_ms + 100) * 1'000'000ll);
    m.publish_time_ns = m.log_time_ns - 1000;
    m.data = m.channel == 3 ? "{\"n\":" + std::to_string(i) + "}" : Payload(i, size);
    out.push_back(std::move(m));
  }
  return out;
}

}  // namespace stevi::mcap::test
