// Files cut short, damaged or hostile: the reader never crashes, keeps exactly the messages of
// the whole chunks before the damage, says so in note(), and never accepts damage silently. What
// "whole chunks before the cut" means is computed here from the full file with the test's own
// record walker.
#include <algorithm>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "drivers/mcap/mcap.h"
#include "tests/drivers/mcap/mcap_test_util.h"
#include "tests/testing/data.h"
#include "tests/testing/status_matchers.h"

using stevi::testing::IsError;

namespace stevi::mcap {
namespace {

using test::Rec;
using test::Sent;
using test::U32;
using test::U64;
using ::testing::HasSubstr;

// A written sample and, from its bytes, where each chunk ends and how many messages it holds.
struct Sample {
  std::string bytes;
  std::vector<Sent> sent;
  std::vector<std::pair<uint64_t, uint64_t>> chunk_ends;  // (end offset, messages in it)
  std::vector<uint64_t> chunk_starts;
  uint64_t data_end_at = 0;  // the Data End record
};

Sample MakeSample(Compression c, int messages, size_t size, uint64_t chunk_bytes) {
  Sample s;
  const std::string path = stevi::testing::MakeTempDir("stevi-mcap-recovery") + "/f.mcap";
  WriterOptions o;
  o.compression = c;
  o.chunk_bytes = chunk_bytes;
  s.sent = test::Interleaved(messages, size);
  test::WriteSample(path, o, s.sent);
  s.bytes = test::ReadFile(path);
  const uint64_t footer_at = s.bytes.size() - 8 - 29;
  s.data_end_at = U64(s.bytes, footer_at + 9) - 13;
  const std::vector<Rec> data = test::Walk(s.bytes, 8 + 9 + U64(s.bytes, 9), s.data_end_at);
  for (size_t i = 0; i < data.size(); ++i) {
    if (data[i].opcode != 0x06) continue;
    uint64_t count = 0;  // entries of the Message Indexes that follow
    for (size_t j = i + 1; j < data.size() && data[j].opcode == 0x07; ++j) {
      count += U32(data[j].content, 2) / 16;
    }
    s.chunk_ends.emplace_back(data[i].offset + data[i].size(), count);
    s.chunk_starts.push_back(data[i].offset);
  }
  return s;
}

// The messages a reader must return for the first `cut` bytes: those of the chunks that end
// before the cut.
std::pair<uint64_t, uint64_t> WholeChunksBefore(const Sample& s, uint64_t cut) {
  uint64_t chunks = 0, messages = 0;
  for (const auto& [end, count] : s.chunk_ends) {
    if (end > cut) break;
    ++chunks;
    messages += count;
  }
  return {chunks, messages};
}

// Reads all messages and checks they are the first sent ones.
void ExpectPrefix(Reader& reader, const std::vector<Sent>& sent, uint64_t count,
                  const std::string& where) {
  Result<std::vector<Message>> read = reader.ReadAll();
  ASSERT_TRUE(read.ok()) << where << ": " << read.error().message;
  ASSERT_EQ(read->size(), count) << where << ": " << reader.note();
  for (size_t i = 0; i < count; ++i) {
    ASSERT_EQ((*read)[i].log_time_ns, sent[i].log_time_ns) << where << " message " << i;
    ASSERT_EQ((*read)[i].data, sent[i].data) << where << " message " << i;
  }
}

void CheckCut(const Sample& s, uint64_t cut, const std::unique_ptr<Reader>& reader) {
  const std::string where = "cut at " + std::to_string(cut);
  const auto [chunks, messages] = WholeChunksBefore(s, cut);
  if (cut == s.bytes.size()) {
    EXPECT_TRUE(reader->indexed());
    EXPECT_EQ(reader->note(), "");
    ExpectPrefix(*reader, s.sent, s.sent.size(), where);
    return;
  }
  EXPECT_FALSE(reader->indexed()) << where;
  EXPECT_THAT(reader->note(), HasSubstr("cut short at byte " + std::to_string(cut))) << where;
  EXPECT_EQ(reader->recovered_chunks(), chunks) << where << ": " << reader->note();
  EXPECT_EQ(reader->recovered_messages(), messages) << where << ": " << reader->note();
  if (cut > s.data_end_at + 13) {
    EXPECT_THAT(reader->note(), HasSubstr("the data section is whole")) << where;
  } else if (cut > 8 + 9 + 13 && messages > 0) {
    EXPECT_THAT(reader->note(), HasSubstr("read " + std::to_string(messages) + " message" +
                                          (messages == 1 ? "" : "s") + " in " +
                                          std::to_string(chunks) + " whole chunk"))
        << where;
  }
  ExpectPrefix(*reader, s.sent, messages, where);
  // Metadata and attachments before the cut are kept too.
  EXPECT_LE(reader->attachments().size(), 1u);
}

class Truncation : public ::testing::TestWithParam<Compression> {};

std::string CompressionParamName(const ::testing::TestParamInfo<Compression>& param) {
  return param.param == Compression::kNone ? "none" : std::string(CompressionName(param.param));
}

TEST_P(Truncation, EveryByteOfASmallFile) {
  const Sample s = MakeSample(GetParam(), 24, 300, 1500);
  ASSERT_GE(s.chunk_ends.size(), 4u);
  for (uint64_t cut = 0; cut <= s.bytes.size(); ++cut) {
    Result<std::unique_ptr<Reader>> reader =
        Reader::FromBytes(s.bytes.substr(0, cut), "flight.mcap");
    ASSERT_TRUE(reader.ok()) << "cut at " << cut << ": " << reader.error().message;
    CheckCut(s, cut, *reader);
    if (HasFailure()) return;  // one cut's report is enough
  }
}

TEST_P(Truncation, StrideThroughALargerFileOnDisk) {
  const Sample s = MakeSample(GetParam(), 1500, 700, 32 << 10);
  ASSERT_GE(s.chunk_ends.size(), 10u);
  std::vector<uint64_t> cuts;
  for (uint64_t cut = 0; cut < s.bytes.size(); cut += 4099) cuts.push_back(cut);
  for (const auto& [end, count] : s.chunk_ends) {
    for (const uint64_t cut : {end - 1, end, end + 1}) cuts.push_back(cut);
  }
  for (uint64_t back = 0; back < 64; ++back) cuts.push_back(s.bytes.size() - back);
  const std::string dir = stevi::testing::MakeTempDir("stevi-mcap-cuts");
  for (size_t i = 0; i < cuts.size(); ++i) {
    const uint64_t cut = cuts[i];
    // Every fourth through a file, to read with pread as a real flight is.
    Result<std::unique_ptr<Reader>> reader = Reader::FromBytes(s.bytes.substr(0, cut), "f");
    if (i % 4 == 0) {
      const std::string path = dir + "/cut" + std::to_string(cut) + ".mcap";
      test::WriteFile(path, s.bytes.substr(0, cut));
      reader = Reader::Open(path);
    }
    ASSERT_TRUE(reader.ok()) << "cut at " << cut << ": " << reader.error().message;
    CheckCut(s, cut, *reader);
    if (HasFailure()) return;
  }
}

INSTANTIATE_TEST_SUITE_P(AllCompressions, Truncation,
                         ::testing::Values(Compression::kNone, Compression::kZstd,
                                           Compression::kLz4),
                         CompressionParamName);

// ---- Corruption ---------------------------------------------------------------------------------

TEST(Corruption, EveryFlippedByteIsRejectedOrNoted) {
  for (Compression c : {Compression::kNone, Compression::kZstd}) {
    const Sample s = MakeSample(c, 12, 200, 1000);
    int rejected = 0, noted = 0;
    for (uint64_t at = 0; at < s.bytes.size(); ++at) {
      std::string bytes = s.bytes;
      bytes[at] = static_cast<char>(bytes[at] ^ 0xFF);
      Result<std::unique_ptr<Reader>> reader = Reader::FromBytes(bytes, "bad.mcap");
      if (!reader.ok()) {
        ++rejected;
        EXPECT_THAT(reader, IsError(ErrorCode::kInvalidArgument));
        EXPECT_THAT(reader.error().message, HasSubstr("bad.mcap: byte ")) << at;
        continue;
      }
      ASSERT_FALSE((*reader)->note().empty()) << "byte " << at << " flipped, silently accepted";
      ++noted;
      // Recovered: a prefix of what was written, and nothing else.
      Result<std::vector<Message>> read = (*reader)->ReadAll();
      ASSERT_TRUE(read.ok()) << at << ": " << read.error().message;
      ASSERT_LE(read->size(), s.sent.size());
      for (size_t i = 0; i < read->size(); ++i) ASSERT_EQ((*read)[i].data, s.sent[i].data) << at;
    }
    EXPECT_GT(rejected, 0);
    EXPECT_GT(noted, 0);  // the closing magic, the footer's own fields
    std::printf("%s: of %zu flipped bytes, %d rejected, %d read as cut short with a note\n",
                c == Compression::kNone ? "none" : "zstd", s.bytes.size(), rejected, noted);
  }
}

TEST(Corruption, DamagedChunkInACutFileEndsTheRecoveryThere) {
  const Sample s = MakeSample(Compression::kNone, 24, 300, 1500);
  ASSERT_GE(s.chunk_ends.size(), 4u);
  std::string bytes = s.bytes.substr(0, s.chunk_ends[3].first);  // four whole chunks
  // A byte inside the third chunk's (uncompressed) records.
  const uint64_t at = s.chunk_ends[2].first - 100;
  bytes[at] = static_cast<char>(bytes[at] ^ 0x01);
  Result<std::unique_ptr<Reader>> reader = Reader::FromBytes(bytes, "crash.mcap");
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  const std::string& note = (*reader)->note();
  EXPECT_THAT(note, HasSubstr("is damaged (Chunk: uncompressed CRC mismatch"));
  EXPECT_THAT(note, HasSubstr("it and the"));
  const uint64_t kept = s.chunk_ends[0].second + s.chunk_ends[1].second;
  EXPECT_EQ((*reader)->recovered_chunks(), 2u);
  ExpectPrefix(**reader, s.sent, kept, "damaged third chunk");
}

TEST(Corruption, ChunkCrcIsCheckedWhenReadingAnIndexedFile) {
  // Another writer may leave the data-section CRC at 0 (not computed): then a damaged chunk is
  // found by its own CRC, when its messages are read.
  const Sample s = MakeSample(Compression::kNone, 24, 300, 1500);
  std::string bytes = s.bytes;
  for (int i = 0; i < 4; ++i) bytes[s.data_end_at + 9 + i] = 0;
  const uint64_t at = s.chunk_ends[1].first - 100;
  bytes[at] = static_cast<char>(bytes[at] ^ 0x01);
  Result<std::unique_ptr<Reader>> reader = Reader::FromBytes(bytes, "old.mcap");
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  EXPECT_TRUE((*reader)->indexed());
  uint64_t read = 0;
  Result<std::optional<Message>> next = (*reader)->Next();
  for (; next.ok() && next->has_value(); next = (*reader)->Next()) ++read;
  ASSERT_FALSE(next.ok());
  EXPECT_EQ(read, s.chunk_ends[0].second) << "the first chunk's messages come out";
  EXPECT_THAT(next.error().message,
              HasSubstr("old.mcap: byte " + std::to_string(s.chunk_starts[1]) + ": Chunk: "));
  EXPECT_THAT(next.error().message, HasSubstr("uncompressed CRC mismatch"));
  EXPECT_FALSE((*reader)->Next().ok()) << "errors are sticky";
}

TEST(Corruption, SummaryCrcMismatchIsRejected) {
  const Sample s = MakeSample(Compression::kZstd, 12, 200, 1000);
  std::string bytes = s.bytes;
  const uint64_t in_summary = s.data_end_at + 13 + 20;
  bytes[in_summary] = static_cast<char>(bytes[in_summary] ^ 0x10);
  Result<std::unique_ptr<Reader>> reader = Reader::FromBytes(bytes, "s.mcap");
  ASSERT_FALSE(reader.ok());
  EXPECT_THAT(reader.error().message, HasSubstr("summary CRC mismatch"));
}

// ---- Hand-built files ---------------------------------------------------------------------------

// The spec's primitives, for files no writer of ours would produce.
struct Bytes {
  std::string b;
  Bytes& Le(uint64_t v, int n) {
    for (int i = 0; i < n; ++i) b.push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
    return *this;
  }
  Bytes& Str(std::string_view s) {
    Le(s.size(), 4);
    b += s;
    return *this;
  }
  Bytes& Record(uint8_t op, const std::string& content) {
    Le(op, 1).Le(content.size(), 8);
    b += content;
    return *this;
  }
};

std::string Message(uint16_t channel, uint64_t t, std::string_view data) {
  return Bytes().Le(channel, 2).Le(0, 4).Le(t, 8).Le(t, 8).b + std::string(data);
}

std::string ChunkOf(const std::string& records, uint64_t claimed_size, std::string_view comp = "") {
  return Bytes().Le(1, 8).Le(2, 8).Le(claimed_size, 8).Le(0, 4).Str(comp).Le(records.size(), 8).b +
         records;
}

Bytes Start() {
  Bytes f;
  f.b = std::string(kMagic);
  f.Record(0x01, Bytes().Str("").Str("hand").b);
  return f;
}

TEST(HandBuilt, UnknownRecordsAreSkippedAndLooseMessagesRead) {
  Bytes f = Start();
  f.Record(0x80, "private");
  f.Record(0x03, Bytes().Le(1, 2).Str("S").Str("jsonschema").Str("{}").b);
  f.Record(0x03, Bytes().Le(0, 2).Str("zero").Str("").Str("").b);  // id 0: ignored
  f.Record(0x04, Bytes().Le(5, 2).Le(1, 2).Str("/loose").Str("json").Le(0, 4).b);
  f.Record(0x05, Message(5, 10, "outside"));
  const std::string inner =
      Bytes().Record(0x81, "ext").Record(0x05, Message(5, 20, "inside")).Record(0xFE, "").b;
  f.Record(0x06, ChunkOf(inner, inner.size()));
  f.Record(0x0F, Bytes().Le(0, 4).b);
  f.Record(0x02, Bytes().Le(0, 8).Le(0, 8).Le(0, 4).b);
  f.b += kMagic;
  Result<std::unique_ptr<Reader>> reader = Reader::FromBytes(f.b, "hand.mcap");
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  EXPECT_FALSE((*reader)->indexed());
  EXPECT_THAT((*reader)->note(), HasSubstr("no summary (the writer wrote none)"));
  EXPECT_THAT((*reader)->note(), HasSubstr("the data section is whole"));
  Result<std::vector<mcap::Message>> read = (*reader)->ReadAll();
  ASSERT_TRUE(read.ok()) << read.error().message;
  ASSERT_EQ(read->size(), 2u);
  EXPECT_EQ((*read)[0].data, "outside");
  EXPECT_EQ((*read)[1].data, "inside");
  EXPECT_EQ((*reader)->channel(5)->topic, "/loose");
  EXPECT_EQ((*reader)->schemas().size(), 1u) << "the schema with id 0 is ignored";
}

TEST(HandBuilt, FooterWithoutDataEnd) {
  Bytes f = Start();
  f.Record(0x04, Bytes().Le(1, 2).Le(0, 2).Str("/t").Str("json").Le(0, 4).b);
  f.Record(0x05, Message(1, 10, "{}"));
  f.Record(0x02, Bytes().Le(0, 8).Le(0, 8).Le(0, 4).b);
  f.b += kMagic;
  Result<std::unique_ptr<Reader>> reader = Reader::FromBytes(f.b, "nodataend.mcap");
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  EXPECT_THAT((*reader)->note(), HasSubstr("without Data End"));
  EXPECT_EQ((*reader)->recovered_messages(), 1u);
}

// Each a file whose last record is hostile; the reader must stop there, with a note.
TEST(HandBuilt, HostileLengthsStopTheReadWithANote) {
  struct Case {
    const char* name;
    Bytes file;
    const char* says;
  };
  std::vector<Case> cases;
  cases.push_back({"huge length", Start().Le(0x06, 1).Le(~0ull, 8).Le(7, 1),
                   "the rest of the last chunk is lost"});
  cases.push_back({"terabyte chunk", Start().Record(0x06, ChunkOf("", uint64_t{1} << 40, "zstd")),
                   "over the limit"});
  cases.push_back({"unknown compression", Start().Record(0x06, ChunkOf("xx", 2, "brotli")),
                   "unknown compression"});
  cases.push_back(
      {"zstd garbage", Start().Record(0x06, ChunkOf("not zstd", 100, "zstd")), "zstd: "});
  cases.push_back({"lz4 garbage", Start().Record(0x06, ChunkOf("not lz4!", 100, "lz4")), "lz4: "});
  cases.push_back({"undefined channel",
                   Start().Record(0x06, ChunkOf(Bytes().Record(0x05, Message(9, 1, "x")).b, 32)),
                   "channel 9 has no Channel record before it"});
  cases.push_back({"inner record too long",
                   Start().Record(0x06, ChunkOf(Bytes().Le(0x05, 1).Le(1000, 8).b, 9)),
                   "says 1000 bytes, only 0 are left"});
  cases.push_back(
      {"odd map",
       Start().Record(0x04, Bytes().Le(1, 2).Le(0, 2).Str("t").Str("e").Le(3, 4).b + "abc"),
       "Channel: metadata"});
  cases.push_back({"zero opcode", Start().Le(0, 1).Le(4, 8).Le(0, 4), "invalid opcode 0x00"});
  cases.push_back({"attachment crc",
                   Start().Record(0x09, Bytes().Le(1, 8).Le(1, 8).Str("a").Str("t").Le(1, 8).b +
                                            "x" + Bytes().Le(12345, 4).b),
                   "Attachment: crc"});
  for (const Case& c : cases) {
    Result<std::unique_ptr<Reader>> reader = Reader::FromBytes(c.file.b, c.name);
    ASSERT_TRUE(reader.ok()) << c.name << ": " << reader.error().message;
    EXPECT_THAT((*reader)->note(), HasSubstr(c.says)) << c.name;
    EXPECT_EQ((*reader)->recovered_messages(), 0u) << c.name;
    Result<std::vector<mcap::Message>> read = (*reader)->ReadAll();
    ASSERT_TRUE(read.ok()) << c.name;
    EXPECT_TRUE(read->empty()) << c.name;
  }
}

TEST(HandBuilt, TinyPrefixesAreCutShortNotErrors) {
  for (size_t n = 0; n <= kMagic.size(); ++n) {
    Result<std::unique_ptr<Reader>> reader =
        Reader::FromBytes(std::string(kMagic.substr(0, n)), "t");
    ASSERT_TRUE(reader.ok()) << n;
    EXPECT_THAT((*reader)->note(), HasSubstr("cut short at byte " + std::to_string(n)));
  }
  // A Header of the wrong opcode is no MCAP file.
  Bytes wrong;
  wrong.b = std::string(kMagic);
  wrong.Record(0x02, std::string(20, '\0'));
  Result<std::unique_ptr<Reader>> reader = Reader::FromBytes(wrong.b, "w");
  ASSERT_FALSE(reader.ok());
  EXPECT_THAT(reader.error().message, HasSubstr("w: byte 8: expected the Header record"));
}

}  // namespace
}  // namespace stevi::mcap
