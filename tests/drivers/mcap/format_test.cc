// The writer's bytes against the MCAP specification (https://mcap.dev/spec), read back with a
// parser written here from the spec, CRCs computed here (own table and zlib), and chunks
// decompressed here with libzstd and LZ4F: none of it goes through the library's reader.
#include <lz4frame.h>
#include <zlib.h>
#include <zstd.h>

#include <algorithm>
#include <regex>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "drivers/mcap/mcap.h"
#include "tests/drivers/mcap/mcap_test_util.h"
#include "tests/testing/data.h"

namespace stevi::mcap {
namespace {

using test::Rec;
using test::Sent;
using test::SpecCrc32;
using test::U16;
using test::U32;
using test::U64;

const std::string kMagicBytes("\x89\x4D\x43\x41\x50\x30\x0D\x0A", 8);

uint32_t ZlibCrc(std::string_view bytes) {
  return static_cast<uint32_t>(
      crc32(0, reinterpret_cast<const Bytef*>(bytes.data()), static_cast<uInt>(bytes.size())));
}

// A file's parts as the spec lays them out, found from its end.
struct Layout {
  std::string bytes;
  uint64_t header_end = 0;  // the first data-section record
  uint64_t footer_at = 0;
  uint64_t summary_start = 0;
  uint64_t summary_offset_start = 0;
  uint32_t summary_crc = 0;
  uint64_t data_end_at = 0;  // the Data End record
  std::vector<Rec> data;     // records between the Header and the Data End
  std::vector<Rec> summary;  // records between the Data End and the Footer
};

Layout ReadLayout(const std::string& path) {
  Layout l;
  l.bytes = test::ReadFile(path);
  const std::string_view b = l.bytes;
  EXPECT_GT(b.size(), 8u + 9 + 13 + 29 + 8);
  l.header_end = 8 + 9 + U64(b, 9);
  l.footer_at = b.size() - 8 - 29;
  l.summary_start = U64(b, l.footer_at + 9);
  l.summary_offset_start = U64(b, l.footer_at + 17);
  l.summary_crc = U32(b, l.footer_at + 25);
  l.data_end_at = l.summary_start - 13;
  l.data = test::Walk(b, l.header_end, l.data_end_at);
  l.summary = test::Walk(b, l.summary_start, l.footer_at);
  return l;
}

std::string TempPath(const std::string& name) {
  return stevi::testing::MakeTempDir("stevi-mcap-format") + "/" + name;
}

WriterOptions SmallChunks(Compression c) {
  WriterOptions o;
  o.compression = c;
  o.chunk_bytes = 16 << 10;
  return o;
}

// The sample of most tests: 60 messages of 2 KiB (/c's are short JSON) in 16 KiB chunks.
Layout Sample(Compression c, std::vector<Sent>* sent = nullptr) {
  const std::vector<Sent> messages = test::Interleaved(60, 2048);
  if (sent != nullptr) *sent = messages;
  const std::string path = TempPath("sample.mcap");
  test::WriteSample(path, SmallChunks(c), messages);
  return ReadLayout(path);
}

// A chunk's records decompressed by the libraries directly.
std::string Decompress(std::string_view compression, std::string_view in, uint64_t size) {
  std::string out(size, '\0');
  if (compression.empty()) return std::string(in);
  if (compression == "zstd") {
    const size_t n = ZSTD_decompress(out.data(), out.size(), in.data(), in.size());
    EXPECT_FALSE(ZSTD_isError(n)) << ZSTD_getErrorName(n);
    EXPECT_EQ(n, size);
    return out;
  }
  EXPECT_EQ(compression, "lz4");
  LZ4F_dctx* ctx = nullptr;
  EXPECT_FALSE(LZ4F_isError(LZ4F_createDecompressionContext(&ctx, LZ4F_VERSION)));
  size_t dst = out.size();
  size_t src = in.size();
  const size_t left = LZ4F_decompress(ctx, out.data(), &dst, in.data(), &src, nullptr);
  LZ4F_freeDecompressionContext(ctx);
  EXPECT_EQ(left, 0u) << "the LZ4 frame did not end";
  EXPECT_EQ(dst, size);
  EXPECT_EQ(src, in.size());
  return out;
}

// ---- Magic, Header, Footer, Data End ------------------------------------------------------------

TEST(Crc, ReferenceCheckValue) {
  // The spec's CRC is CRC-32/ISO-HDLC: check("123456789") = 0xCBF43926, as zlib computes it.
  EXPECT_EQ(SpecCrc32("123456789"), 0xCBF43926u);
  EXPECT_EQ(ZlibCrc("123456789"), 0xCBF43926u);
}

TEST(FileLayout, MagicAtBothEnds) {
  const Layout l = Sample(Compression::kZstd);
  EXPECT_EQ(l.bytes.substr(0, 8), kMagicBytes);
  EXPECT_EQ(l.bytes.substr(l.bytes.size() - 8), kMagicBytes);
}

TEST(FileLayout, HeaderRecordBytes) {
  WriterOptions o;
  o.profile = "x-test";
  o.library = "stevi-test";
  const std::string path = TempPath("header.mcap");
  test::WriteSample(path, o, {}, /*extras=*/false);
  const std::string b = test::ReadFile(path);
  const std::string expected = std::string("\x01", 1) + std::string("\x18\0\0\0\0\0\0\0", 8) +
                               std::string("\x06\0\0\0", 4) + "x-test" +
                               std::string("\x0A\0\0\0", 4) + "stevi-test";
  EXPECT_EQ(b.substr(8, expected.size()), expected);
}

TEST(FileLayout, FooterPointsAtTheSummaryAfterDataEnd) {
  const Layout l = Sample(Compression::kZstd);
  const std::string_view b = l.bytes;
  // The Footer: opcode 0x02, content 20 bytes, right before the closing magic.
  EXPECT_EQ(static_cast<uint8_t>(b[l.footer_at]), 0x02);
  EXPECT_EQ(U64(b, l.footer_at + 1), 20u);
  // A 13-byte Data End right before summary_start; the first summary record starts there.
  EXPECT_EQ(static_cast<uint8_t>(b[l.data_end_at]), 0x0F);
  EXPECT_EQ(U64(b, l.data_end_at + 1), 4u);
  ASSERT_FALSE(l.summary.empty());
  EXPECT_EQ(l.summary.front().offset, l.summary_start);
  // summary_offset_start: the first Summary Offset record; they run to the Footer.
  const auto first_offset = std::find_if(l.summary.begin(), l.summary.end(),
                                         [](const Rec& r) { return r.opcode == 0x0E; });
  ASSERT_NE(first_offset, l.summary.end());
  EXPECT_EQ(first_offset->offset, l.summary_offset_start);
  EXPECT_TRUE(
      std::all_of(first_offset, l.summary.end(), [](const Rec& r) { return r.opcode == 0x0E; }));
}

TEST(FileLayout, EachSummaryOffsetSpansExactlyItsGroup) {
  const Layout l = Sample(Compression::kLz4);
  const std::string_view b = l.bytes;
  std::map<uint8_t, std::pair<uint64_t, uint64_t>> groups;  // opcode -> [first, end)
  for (const Rec& r : l.summary) {
    if (r.opcode == 0x0E) continue;
    auto [it, added] = groups.emplace(r.opcode, std::make_pair(r.offset, r.offset + r.size()));
    if (!added) {
      EXPECT_EQ(it->second.second, r.offset) << "opcode " << int{r.opcode} << " not grouped";
      it->second.second = r.offset + r.size();
    }
  }
  std::set<uint8_t> described;
  for (const Rec& r : l.summary) {
    if (r.opcode != 0x0E) continue;
    ASSERT_EQ(r.content.size(), 17u);
    const uint8_t op = static_cast<uint8_t>(r.content[0]);
    const uint64_t start = U64(r.content, 1);
    const uint64_t length = U64(r.content, 9);
    ASSERT_TRUE(groups.count(op)) << "a Summary Offset for absent opcode " << int{op};
    EXPECT_EQ(start, groups[op].first) << int{op};
    EXPECT_EQ(length, groups[op].second - groups[op].first) << int{op};
    EXPECT_EQ(static_cast<uint8_t>(b[start]), op);
    described.insert(op);
  }
  EXPECT_EQ(described.size(), groups.size()) << "every group has its Summary Offset";
}

TEST(FileLayout, CrcsCoverTheRangesTheSpecNames) {
  for (Compression c : {Compression::kNone, Compression::kZstd, Compression::kLz4}) {
    const Layout l = Sample(c);
    const std::string_view b = l.bytes;
    // Data End: every byte from the start of the file up to the Data End record.
    const uint32_t data_crc = U32(b, l.data_end_at + 9);
    EXPECT_EQ(data_crc, SpecCrc32(b.substr(0, l.data_end_at)));
    EXPECT_EQ(data_crc, ZlibCrc(b.substr(0, l.data_end_at)));
    // Footer: from summary_start through the footer's summary_offset_start field.
    const uint64_t crc_end = l.footer_at + 1 + 8 + 8 + 8;
    EXPECT_EQ(l.summary_crc, SpecCrc32(b.substr(l.summary_start, crc_end - l.summary_start)));
    EXPECT_EQ(l.summary_crc, ZlibCrc(b.substr(l.summary_start, crc_end - l.summary_start)));
    EXPECT_NE(data_crc, 0u);
    EXPECT_NE(l.summary_crc, 0u);
  }
}

// Opcodes as letters, so that the order of a whole file reads as one regular expression.
char Letter(uint8_t opcode) {
  static const char kLetters[] = "?HFSNMCIXAaTmiOD";  // 0x00 .. 0x0F
  return opcode < 16 ? kLetters[opcode] : '#';
}

TEST(FileLayout, RecordSequence) {
  const Layout l = Sample(Compression::kZstd);
  std::string sequence = "H";
  for (const Rec& r : l.data) sequence += Letter(r.opcode);
  sequence += 'D';
  for (const Rec& r : l.summary) sequence += Letter(r.opcode);
  sequence += 'F';
  // Header; chunks each followed by Message Indexes, with the Metadata and Attachment between
  // them; Data End; Schemas, Channels, Statistics, Chunk Indexes, Attachment Index, Metadata
  // Index; Summary Offsets; Footer.
  EXPECT_TRUE(std::regex_match(sequence, std::regex("H(CI+|m|A)+DS+N+TX+aiO+F"))) << sequence;
  EXPECT_EQ(std::count(sequence.begin(), sequence.end(), 'A'), 1) << sequence;
  EXPECT_EQ(std::count(sequence.begin(), sequence.end(), 'm'), 1) << sequence;
  EXPECT_EQ(std::count(sequence.begin(), sequence.end(), 'N'), 3) << sequence;
  EXPECT_EQ(std::count(sequence.begin(), sequence.end(), 'O'), 6) << sequence;
  EXPECT_EQ(sequence.find('M'), std::string::npos) << "no message outside chunks";
}

// ---- Chunks and their indexes -------------------------------------------------------------------

struct ChunkSeen {
  uint64_t offset = 0;
  uint64_t length = 0;
  std::string compression;
  uint64_t compressed_size = 0;
  uint64_t uncompressed_size = 0;
  uint64_t start_ns = 0;
  uint64_t end_ns = 0;
  std::map<uint16_t, uint64_t> index_offsets;
  uint64_t index_length = 0;
};

// Checks one chunk against the spec and returns what its Chunk Index must say; appends its
// messages (channel, log time, data) in record order to `messages`.
ChunkSeen CheckChunk(const Layout& l, size_t i, std::vector<Sent>& messages,
                     std::set<uint16_t>& defined_channels) {
  const Rec& chunk = l.data[i];
  const std::string_view c = chunk.content;
  ChunkSeen seen;
  seen.offset = chunk.offset;
  seen.length = chunk.size();
  seen.start_ns = U64(c, 0);
  seen.end_ns = U64(c, 8);
  seen.uncompressed_size = U64(c, 16);
  const uint32_t crc = U32(c, 24);
  uint64_t at = 28;
  seen.compression = std::string(test::Str(c, at));
  seen.compressed_size = U64(c, at);
  EXPECT_EQ(at + 8 + seen.compressed_size, c.size()) << "records fill the chunk";
  const std::string records =
      Decompress(seen.compression, c.substr(at + 8, seen.compressed_size), seen.uncompressed_size);
  EXPECT_EQ(records.size(), seen.uncompressed_size);
  EXPECT_EQ(crc, SpecCrc32(records));
  // Inner records: Schemas and Channels before their first message, then Messages.
  std::map<uint64_t, std::pair<uint16_t, uint64_t>> by_offset;  // offset -> (channel, log time)
  uint64_t lo = UINT64_MAX, hi = 0;
  for (const Rec& r : test::Walk(records, 0, records.size())) {
    if (r.opcode == 0x04) defined_channels.insert(U16(r.content, 0));
    if (r.opcode != 0x05) continue;
    const uint16_t channel = U16(r.content, 0);
    EXPECT_TRUE(defined_channels.count(channel)) << "channel " << channel << " used before defined";
    const uint64_t log_time = U64(r.content, 6);
    by_offset[r.offset] = {channel, log_time};
    lo = std::min(lo, log_time);
    hi = std::max(hi, log_time);
    messages.push_back(
        Sent{channel, log_time, U64(r.content, 14), std::string(r.content.substr(22))});
  }
  EXPECT_EQ(seen.start_ns, lo);
  EXPECT_EQ(seen.end_ns, hi);
  // The Message Indexes right after it: one per channel, each entry at a Message opcode with that
  // log time, sorted by log time, covering every message once.
  size_t covered = 0;
  for (size_t j = i + 1; j < l.data.size() && l.data[j].opcode == 0x07; ++j) {
    const Rec& index = l.data[j];
    const uint16_t channel = U16(index.content, 0);
    const uint32_t bytes = U32(index.content, 2);
    EXPECT_EQ(6 + bytes, index.content.size());
    EXPECT_GT(bytes, 0u) << "no empty Message Index";
    EXPECT_FALSE(seen.index_offsets.count(channel)) << "one index per channel";
    seen.index_offsets[channel] = index.offset;
    seen.index_length += index.size();
    uint64_t previous = 0;
    for (uint64_t e = 0; e < bytes / 16; ++e) {
      const uint64_t log_time = U64(index.content, 6 + 16 * e);
      const uint64_t offset = U64(index.content, 14 + 16 * e);
      EXPECT_EQ(static_cast<uint8_t>(records[offset]), 0x05) << "offset " << offset;
      EXPECT_EQ(U64(records, offset + 9 + 6), log_time);
      EXPECT_TRUE(by_offset.count(offset) == 1 && by_offset[offset].first == channel)
          << "offset " << offset << " is not a message of channel " << channel;
      EXPECT_GE(log_time, previous);
      previous = log_time;
      ++covered;
    }
  }
  EXPECT_EQ(covered, by_offset.size());
  return seen;
}

class ChunkBytes : public ::testing::TestWithParam<Compression> {};

std::string CompressionParamName(const ::testing::TestParamInfo<Compression>& param) {
  return param.param == Compression::kNone ? "none" : std::string(CompressionName(param.param));
}

TEST_P(ChunkBytes, DecompressedByTheLibrariesAndIndexedAsTheSpecSays) {
  std::vector<Sent> sent;
  const Layout l = Sample(GetParam(), &sent);
  std::vector<Sent> read;
  std::set<uint16_t> defined;
  std::vector<ChunkSeen> chunks;
  for (size_t i = 0; i < l.data.size(); ++i) {
    if (l.data[i].opcode == 0x06) chunks.push_back(CheckChunk(l, i, read, defined));
  }
  ASSERT_GE(chunks.size(), 5u);
  for (const ChunkSeen& c : chunks) {
    // zstd and lz4 shrink this text; none stays none; a chunk under 1 KiB is never compressed.
    EXPECT_EQ(c.compression,
              c.uncompressed_size < 1024 ? "" : std::string(CompressionName(GetParam())))
        << "chunk at byte " << c.offset << " of " << c.uncompressed_size << " bytes";
  }
  ASSERT_EQ(read.size(), sent.size());
  for (size_t i = 0; i < sent.size(); ++i) {
    EXPECT_EQ(read[i].channel, sent[i].channel) << i;
    EXPECT_EQ(read[i].log_time_ns, sent[i].log_time_ns) << i;
    EXPECT_EQ(read[i].publish_time_ns, sent[i].publish_time_ns) << i;
    EXPECT_EQ(read[i].data, sent[i].data) << i;
  }
  // The Chunk Indexes in the summary say the same, in file order.
  std::vector<Rec> indexes;
  for (const Rec& r : l.summary) {
    if (r.opcode == 0x08) indexes.push_back(r);
  }
  ASSERT_EQ(indexes.size(), chunks.size());
  for (size_t k = 0; k < chunks.size(); ++k) {
    const std::string_view x = indexes[k].content;
    const ChunkSeen& c = chunks[k];
    EXPECT_EQ(U64(x, 0), c.start_ns);
    EXPECT_EQ(U64(x, 8), c.end_ns);
    EXPECT_EQ(U64(x, 16), c.offset);
    EXPECT_EQ(U64(x, 24), c.length);
    const uint32_t map_bytes = U32(x, 32);
    std::map<uint16_t, uint64_t> offsets;
    for (uint64_t e = 0; e < map_bytes / 10; ++e) {
      offsets[U16(x, 36 + 10 * e)] = U64(x, 38 + 10 * e);
    }
    EXPECT_EQ(offsets, c.index_offsets);
    uint64_t at = 36 + map_bytes;
    EXPECT_EQ(U64(x, at), c.index_length);
    at += 8;
    EXPECT_EQ(test::Str(x, at), c.compression);
    EXPECT_EQ(U64(x, at), c.compressed_size);
    EXPECT_EQ(U64(x, at + 8), c.uncompressed_size);
  }
}

INSTANTIATE_TEST_SUITE_P(AllCompressions, ChunkBytes,
                         ::testing::Values(Compression::kNone, Compression::kZstd,
                                           Compression::kLz4),
                         CompressionParamName);

TEST(ChunkBytes, TinyAndIncompressibleChunksAreStoredUncompressed) {
  for (const bool tiny : {true, false}) {
    WriterOptions o;
    o.compression = Compression::kZstd;
    const std::string path = TempPath("raw.mcap");
    Sent m{1, 1000, 1000, tiny ? std::string("small") : test::Noise(7, 4096)};
    test::WriteSample(path, o, {m}, /*extras=*/false);
    const Layout l = ReadLayout(path);
    ASSERT_EQ(l.data.front().opcode, 0x06);
    uint64_t at = 28;
    EXPECT_EQ(test::Str(l.data.front().content, at), "") << (tiny ? "tiny" : "noise");
  }
}

// ---- Summary contents ---------------------------------------------------------------------------

TEST(Summary, StatisticsMatchWhatWasWritten) {
  std::vector<Sent> sent;
  const Layout l = Sample(Compression::kZstd, &sent);
  const auto stats = std::find_if(l.summary.begin(), l.summary.end(),
                                  [](const Rec& r) { return r.opcode == 0x0B; });
  ASSERT_NE(stats, l.summary.end());
  const std::string_view s = stats->content;
  std::map<uint16_t, uint64_t> counts;
  uint64_t lo = UINT64_MAX, hi = 0;
  for (const Sent& m : sent) {
    ++counts[m.channel];
    lo = std::min(lo, m.log_time_ns);
    hi = std::max(hi, m.log_time_ns);
  }
  const auto chunks =
      std::count_if(l.data.begin(), l.data.end(), [](const Rec& r) { return r.opcode == 0x06; });
  EXPECT_EQ(U64(s, 0), sent.size());  // message_count
  EXPECT_EQ(U16(s, 8), 1u);           // schema_count
  EXPECT_EQ(U32(s, 10), 3u);          // channel_count
  EXPECT_EQ(U32(s, 14), 1u);          // attachment_count
  EXPECT_EQ(U32(s, 18), 1u);          // metadata_count
  EXPECT_EQ(U32(s, 22), static_cast<uint32_t>(chunks));
  EXPECT_EQ(U64(s, 26), lo);
  EXPECT_EQ(U64(s, 34), hi);
  const uint32_t map_bytes = U32(s, 42);
  std::map<uint16_t, uint64_t> stored;
  for (uint64_t e = 0; e < map_bytes / 10; ++e) stored[U16(s, 46 + 10 * e)] = U64(s, 48 + 10 * e);
  EXPECT_EQ(stored, counts);
}

TEST(Summary, AttachmentAndMetadataIndexesPointAtTheirRecords) {
  const Layout l = Sample(Compression::kNone);
  const std::string_view b = l.bytes;
  for (const Rec& r : l.summary) {
    if (r.opcode != 0x0A && r.opcode != 0x0D) continue;
    const uint64_t offset = U64(r.content, 0);
    const uint64_t length = U64(r.content, 8);
    const auto target = std::find_if(l.data.begin(), l.data.end(),
                                     [&](const Rec& d) { return d.offset == offset; });
    ASSERT_NE(target, l.data.end());
    EXPECT_EQ(target->size(), length);
    EXPECT_EQ(target->opcode, r.opcode == 0x0A ? 0x09 : 0x0C);
    if (r.opcode == 0x0A) {
      // The attachment's own CRC covers its fields before the CRC.
      const std::string_view a = b.substr(offset + 9, length - 9);
      EXPECT_EQ(U32(a, a.size() - 4), SpecCrc32(a.substr(0, a.size() - 4)));
      uint64_t at = 16;
      EXPECT_EQ(test::Str(a, at), "calibration.yaml");
      EXPECT_EQ(test::Str(a, at), "application/yaml");
      EXPECT_EQ(U64(a, at), U64(r.content, 32));  // data_size
    }
  }
}

}  // namespace
}  // namespace stevi::mcap
