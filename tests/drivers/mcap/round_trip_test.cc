// The writer and reader together: round trips for every compression, chunk closing rules, ids,
// counters, and the writer's errors (existing files, unwritable places, invalid options, and real
// write failures from /dev/full and a file-size limit).
#include <fcntl.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
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

using test::Sent;
using ::testing::HasSubstr;

std::string TempDir() { return stevi::testing::MakeTempDir("stevi-mcap"); }

std::unique_ptr<Reader> OpenOrDie(const std::string& path) {
  Result<std::unique_ptr<Reader>> opened = Reader::Open(path);
  EXPECT_TRUE(opened.ok()) << opened.error().message;
  return opened.ok() ? std::move(*opened) : nullptr;
}

std::vector<Message> ReadAllOrDie(Reader& reader) {
  Result<std::vector<Message>> all = reader.ReadAll();
  EXPECT_TRUE(all.ok()) << all.error().message;
  return all.ok() ? std::move(*all) : std::vector<Message>{};
}

// Read messages equal the sent ones, with per-channel sequence numbers from 0.
void ExpectSameMessages(const std::vector<Message>& read, const std::vector<Sent>& sent) {
  ASSERT_EQ(read.size(), sent.size());
  std::map<uint16_t, uint32_t> sequence;
  for (size_t i = 0; i < sent.size(); ++i) {
    EXPECT_EQ(read[i].channel_id, sent[i].channel) << i;
    EXPECT_EQ(read[i].sequence, sequence[sent[i].channel]++) << i;
    EXPECT_EQ(read[i].log_time_ns, sent[i].log_time_ns) << i;
    EXPECT_EQ(read[i].publish_time_ns, sent[i].publish_time_ns) << i;
    EXPECT_EQ(read[i].data, sent[i].data) << i;
  }
}

// ---- Round trips --------------------------------------------------------------------------------

class RoundTrip : public ::testing::TestWithParam<Compression> {};

std::string CompressionParamName(const ::testing::TestParamInfo<Compression>& param) {
  return param.param == Compression::kNone ? "none" : std::string(CompressionName(param.param));
}

TEST_P(RoundTrip, SeveralChannelsWithTimesOutOfOrder) {
  const std::string path = TempDir() + "/flight.mcap";
  WriterOptions o;
  o.compression = GetParam();
  o.chunk_bytes = 32 << 10;
  const std::vector<Sent> sent = test::Interleaved(300, 3000);
  test::WriteSample(path, o, sent);

  for (const bool from_bytes : {false, true}) {
    std::unique_ptr<Reader> reader;
    if (from_bytes) {
      Result<std::unique_ptr<Reader>> opened = Reader::FromBytes(test::ReadFile(path), "mem");
      ASSERT_TRUE(opened.ok()) << opened.error().message;
      reader = std::move(*opened);
    } else {
      reader = OpenOrDie(path);
    }
    ASSERT_NE(reader, nullptr);
    EXPECT_TRUE(reader->indexed());
    EXPECT_EQ(reader->note(), "");
    EXPECT_EQ(reader->header().library, "stevi");
    EXPECT_EQ(reader->header().profile, "");
    ASSERT_EQ(reader->schemas().size(), 1u);
    EXPECT_EQ(reader->schema(1)->name, "stevi.test.Frame");
    EXPECT_EQ(reader->schema(1)->encoding, "protobuf");
    EXPECT_EQ(reader->schema(1)->data, std::string("\x0a\x05"
                                                   "frame",
                                                   7));
    ASSERT_EQ(reader->channels().size(), 3u);
    EXPECT_EQ(reader->channel(1)->topic, "/a");
    EXPECT_EQ(reader->channel(1)->metadata, (std::map<std::string, std::string>{{"rig", "left"}}));
    EXPECT_EQ(reader->channel(3)->schema_id, 0);
    EXPECT_EQ(reader->channel(3)->message_encoding, "json");
    ASSERT_TRUE(reader->statistics().has_value());
    EXPECT_EQ(reader->statistics()->message_count, sent.size());
    EXPECT_EQ(reader->statistics()->chunk_count, reader->chunk_indexes().size());
    EXPECT_GT(reader->chunk_indexes().size(), 5u);
    ASSERT_EQ(reader->metadata().size(), 1u);
    EXPECT_EQ(reader->metadata()[0].values.at("baseline_m"), "0.12");
    ASSERT_EQ(reader->attachments().size(), 1u);
    EXPECT_EQ(reader->attachments()[0].data, "f_px: 700\nbaseline_m: 0.12\n");
    EXPECT_EQ(reader->attachments()[0].media_type, "application/yaml");
    ExpectSameMessages(ReadAllOrDie(*reader), sent);
    // Next() to the end, then again after Rewind().
    reader->Rewind();
    size_t n = 0;
    while (true) {
      Result<std::optional<Message>> next = reader->Next();
      ASSERT_TRUE(next.ok());
      if (!next->has_value()) break;
      ++n;
    }
    EXPECT_EQ(n, sent.size());
    EXPECT_FALSE(reader->Next()->has_value()) << "the end stays the end";
  }
}

INSTANTIATE_TEST_SUITE_P(AllCompressions, RoundTrip,
                         ::testing::Values(Compression::kNone, Compression::kZstd,
                                           Compression::kLz4),
                         CompressionParamName);

TEST(RoundTrip, ChunksCloseBySize) {
  const std::string path = TempDir() + "/size.mcap";
  WriterOptions o;
  o.chunk_bytes = 4096;
  std::vector<Sent> sent;
  for (int i = 0; i < 100; ++i)
    sent.push_back({1, 1000u + i * 1'000'000u, 1000u, test::Payload(i, 1000)});
  test::WriteSample(path, o, sent, /*extras=*/false);
  std::unique_ptr<Reader> reader = OpenOrDie(path);
  ASSERT_NE(reader, nullptr);
  const std::vector<ChunkIndex>& chunks = reader->chunk_indexes();
  ASSERT_GT(chunks.size(), 20u);
  const uint64_t message_record = 9 + 22 + 1000;
  for (size_t i = 0; i + 1 < chunks.size(); ++i) {
    // Closed by the message that took it to 4096 bytes: at least that, less than one more.
    EXPECT_GE(chunks[i].uncompressed_size, o.chunk_bytes) << i;
    EXPECT_LT(chunks[i].uncompressed_size - (i == 0 ? 200 : 0), o.chunk_bytes + message_record);
  }
  ExpectSameMessages(ReadAllOrDie(*reader), sent);
}

TEST(RoundTrip, ChunksCloseBySpan) {
  const std::string path = TempDir() + "/span.mcap";
  WriterOptions o;
  o.chunk_span_ns = 100'000'000;  // 100 ms
  std::vector<Sent> sent;
  for (int i = 0; i < 50; ++i) {
    sent.push_back({2, 5'000'000'000u + i * 30'000'000ull, 0, "m" + std::to_string(i)});
  }
  test::WriteSample(path, o, sent, /*extras=*/false);
  std::unique_ptr<Reader> reader = OpenOrDie(path);
  ASSERT_NE(reader, nullptr);
  const std::vector<ChunkIndex>& chunks = reader->chunk_indexes();
  // A chunk closes with the message that takes its span to 100 ms or more: 0, 30, 60, 90, 120 ms.
  ASSERT_EQ(chunks.size(), 10u);
  for (size_t i = 0; i + 1 < chunks.size(); ++i) {
    EXPECT_EQ(chunks[i].message_end_time_ns - chunks[i].message_start_time_ns, 120'000'000u) << i;
    EXPECT_EQ(chunks[i + 1].message_start_time_ns - chunks[i].message_end_time_ns, 30'000'000u);
  }
  ExpectSameMessages(ReadAllOrDie(*reader), sent);
}

TEST(RoundTrip, EmptyFileIsValid) {
  const std::string path = TempDir() + "/empty.mcap";
  test::WriteSample(path, {}, {}, /*extras=*/false);
  std::unique_ptr<Reader> reader = OpenOrDie(path);
  ASSERT_NE(reader, nullptr);
  EXPECT_TRUE(reader->indexed());
  EXPECT_EQ(reader->statistics()->message_count, 0u);
  EXPECT_EQ(reader->statistics()->message_start_time_ns, 0u);
  EXPECT_TRUE(reader->chunk_indexes().empty());
  EXPECT_EQ(reader->channels().size(), 3u) << "channels are in the summary even without messages";
  EXPECT_TRUE(ReadAllOrDie(*reader).empty());
}

// ---- Writer API ---------------------------------------------------------------------------------

TEST(Writer, IdsAreStableAndRefusalsAreZero) {
  Result<std::unique_ptr<Writer>> w = Writer::Create(TempDir() + "/ids.mcap");
  ASSERT_TRUE(w.ok());
  EXPECT_EQ((*w)->AddSchema("a", "protobuf", "x"), 1);
  EXPECT_EQ((*w)->AddSchema("b", "protobuf", "x"), 2);
  EXPECT_EQ((*w)->AddSchema("a", "protobuf", "x"), 1);
  EXPECT_EQ((*w)->AddSchema("a", "protobuf", std::string(kMaxSchemaBytes + 1, 'x')), 0);
  EXPECT_EQ((*w)->AddChannel(1, "/t", "protobuf"), 1);
  EXPECT_EQ((*w)->AddChannel(1, "/t", "protobuf"), 1);
  EXPECT_EQ((*w)->AddChannel(1, "/t", "protobuf", {{"k", "v"}}), 2);
  EXPECT_EQ((*w)->AddChannel(9, "/t", "protobuf"), 0) << "unknown schema";
  // A caller's mistake is not a write failure: refused, not sticky.
  const Status bad = (*w)->Write(7, 1, 1, "x");
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad, IsError(ErrorCode::kInvalidArgument));
  EXPECT_TRUE((*w)->Write(1, 1, 1, "x").ok());
  EXPECT_TRUE((*w)->Close().ok());
}

TEST(Writer, CountersAndFlushMakeTheFileReadableWhileOpen) {
  const std::string path = TempDir() + "/live.mcap";
  Result<std::unique_ptr<Writer>> created = Writer::Create(path);
  ASSERT_TRUE(created.ok());
  Writer& w = **created;
  const uint16_t channel = w.AddChannel(0, "/live", "json");
  for (int i = 0; i < 10; ++i) ASSERT_TRUE(w.Write(channel, 1000 + i, 1000 + i, "{}").ok());
  EXPECT_EQ(w.messages(), 10u);
  EXPECT_EQ(w.chunks(), 0u) << "the chunk is still open";
  const uint64_t before = w.bytes();
  ASSERT_TRUE(w.Flush().ok());
  EXPECT_EQ(w.chunks(), 1u);
  EXPECT_GT(w.bytes(), before);
  EXPECT_EQ(w.bytes(), std::filesystem::file_size(path));
  // What a crash now would leave: a file without summary whose chunk is whole.
  std::unique_ptr<Reader> live = OpenOrDie(path);
  ASSERT_NE(live, nullptr);
  EXPECT_FALSE(live->indexed());
  EXPECT_THAT(live->note(), HasSubstr("read 10 messages in 1 whole chunk,"));
  EXPECT_EQ(ReadAllOrDie(*live).size(), 10u);
  ASSERT_TRUE(w.Close().ok());
  EXPECT_EQ(w.bytes(), std::filesystem::file_size(path));
  EXPECT_TRUE(w.Close().ok()) << "Close() is idempotent";
  const Status late = w.Write(channel, 1, 1, "{}");
  ASSERT_FALSE(late.ok());
  EXPECT_THAT(late, IsError(ErrorCode::kFailedPrecondition));
}

TEST(Writer, DestructorClosesTheFile) {
  const std::string path = TempDir() + "/dropped.mcap";
  {
    Result<std::unique_ptr<Writer>> w = Writer::Create(path);
    ASSERT_TRUE(w.ok());
    ASSERT_TRUE((*w)->Write((*w)->AddChannel(0, "/x", "json"), 5, 5, "{}").ok());
  }
  std::unique_ptr<Reader> reader = OpenOrDie(path);
  ASSERT_NE(reader, nullptr);
  EXPECT_TRUE(reader->indexed());
  EXPECT_EQ(ReadAllOrDie(*reader).size(), 1u);
}

// ---- Writer errors ------------------------------------------------------------------------------

TEST(WriterErrors, NeverOverwritesAnExistingFile) {
  const std::string path = TempDir() + "/old.mcap";
  test::WriteFile(path, "an earlier flight");
  Result<std::unique_ptr<Writer>> w = Writer::Create(path);
  ASSERT_FALSE(w.ok());
  EXPECT_THAT(w, IsError(ErrorCode::kAlreadyExists, HasSubstr(path)));
  EXPECT_EQ(test::ReadFile(path), "an earlier flight");
}

TEST(WriterErrors, MissingOrUnwritableDirectory) {
  const std::string missing = TempDir() + "/no/such/dir/f.mcap";
  Result<std::unique_ptr<Writer>> w = Writer::Create(missing);
  ASSERT_FALSE(w.ok());
  EXPECT_THAT(w, IsError(ErrorCode::kNotFound, HasSubstr(missing)));
  // A read-only directory; root ignores the mode bits, but not sysfs, which refuses new files.
  std::string unwritable = TempDir() + "/ro";
  std::filesystem::create_directory(unwritable);
  ASSERT_EQ(::chmod(unwritable.c_str(), 0555), 0);
  unwritable = (::geteuid() == 0 ? std::string("/sys") : unwritable) + "/f.mcap";
  w = Writer::Create(unwritable);
  ASSERT_FALSE(w.ok());
  EXPECT_THAT(w, IsError(ErrorCode::kInternal)) << w.error().message;
  EXPECT_THAT(w.error().message, HasSubstr(unwritable));
}

TEST(WriterErrors, InvalidOptionsAreListedAndNothingIsCreated) {
  const std::string path = TempDir() + "/bad.mcap";
  WriterOptions o;
  o.compression = static_cast<Compression>(7);
  o.chunk_bytes = 0;
  o.chunk_span_ns = 0;
  o.library = std::string(5000, 'x');
  Result<std::unique_ptr<Writer>> w = Writer::Create(path, o);
  ASSERT_FALSE(w.ok());
  EXPECT_THAT(w, IsError(ErrorCode::kInvalidArgument));
  for (const char* field : {"compression", "chunk_bytes", "chunk_span_ns", "library"}) {
    EXPECT_THAT(w.error().message, HasSubstr(std::string("options.") + field));
  }
  EXPECT_FALSE(std::filesystem::exists(path));
  EXPECT_EQ(o.Validate().size(), 4u);
  EXPECT_TRUE(WriterOptions{}.Validate().empty());
}

TEST(WriterErrors, DevFullFailsAtTheHeader) {
  const int fd = ::open("/dev/full", O_WRONLY | O_CLOEXEC);
  ASSERT_GE(fd, 0);
  Result<std::unique_ptr<Writer>> w = Writer::FromFd(fd, "/dev/full");
  ASSERT_FALSE(w.ok());
  EXPECT_THAT(w, IsError(ErrorCode::kResourceExhausted,
                         HasSubstr("/dev/full: cannot write (No space left on device)")));
}

// Writes 1 KiB messages until one fails; returns how many messages were in whole chunks then.
size_t WriteUntilFailure(Writer& w, uint16_t channel, std::vector<Sent>& sent, Status& failure) {
  size_t flushed = 0;
  for (int i = 0; i < 200; ++i) {
    Sent m{channel, 1000u + i, 1000u + i, test::Noise(i, 1024)};
    const uint64_t chunks = w.chunks();
    failure = w.Write(m.channel, m.log_time_ns, m.publish_time_ns, m.data);
    if (!failure.ok()) return flushed;
    sent.push_back(m);
    if (w.chunks() > chunks) flushed = sent.size();
  }
  ADD_FAILURE() << "no write failed";
  return flushed;
}

// A full disk mid-flight: the writer's file descriptor is pointed at /dev/full (dup2) after some
// chunks, so the next chunk's write fails with ENOSPC as on a full disk.
TEST(WriterErrors, WriteFailureIsStickyAndTheFileKeepsItsWholeChunks) {
  const std::string path = TempDir() + "/full.mcap";
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  ASSERT_GE(fd, 0);
  WriterOptions o;
  o.chunk_bytes = 4096;
  Result<std::unique_ptr<Writer>> created = Writer::FromFd(fd, path, o);
  ASSERT_TRUE(created.ok());
  Writer& w = **created;
  const uint16_t channel = w.AddChannel(0, "/cam", "raw");
  std::vector<Sent> sent;
  for (int i = 0; i < 12; ++i) {
    sent.push_back({channel, 1000u + i, 1000u + i, test::Noise(i, 1024)});
    ASSERT_TRUE(w.Write(channel, 1000u + i, 1000u + i, sent.back().data).ok());
  }
  ASSERT_TRUE(w.Flush().ok());
  const uint64_t bytes = w.bytes();
  const size_t kept = sent.size();
  const int full = ::open("/dev/full", O_WRONLY | O_CLOEXEC);
  ASSERT_GE(full, 0);
  ASSERT_EQ(::dup2(full, fd), fd);
  ::close(full);

  Status failure;
  EXPECT_EQ(WriteUntilFailure(w, channel, sent, failure), 0u);
  ASSERT_FALSE(failure.ok());
  EXPECT_THAT(failure,
              IsError(ErrorCode::kResourceExhausted, HasSubstr("No space left on device")));
  // Sticky: every later call returns it, nothing more is written.
  for (const Status& again : {w.Write(channel, 1, 1, "x"), w.AddMetadata("m", {}), w.Flush(),
                              w.AddAttachment("a", "text/plain", 1, "x"), w.Close(), w.Close()}) {
    ASSERT_FALSE(again.ok());
    EXPECT_EQ(again.error().message, failure.error().message);
  }
  EXPECT_EQ(w.bytes(), bytes);
  EXPECT_EQ(std::filesystem::file_size(path), bytes);
  std::unique_ptr<Reader> reader = OpenOrDie(path);
  ASSERT_NE(reader, nullptr);
  EXPECT_FALSE(reader->indexed());
  EXPECT_THAT(reader->note(), HasSubstr("cut short at byte " + std::to_string(bytes)));
  const std::vector<Message> read = ReadAllOrDie(*reader);
  ASSERT_EQ(read.size(), kept);
  for (size_t i = 0; i < kept; ++i) EXPECT_EQ(read[i].data, sent[i].data);
}

// Restores the file-size limit and SIGXFSZ's disposition when the test ends.
class FileSizeLimit {
 public:
  explicit FileSizeLimit(uint64_t bytes) {
    ::getrlimit(RLIMIT_FSIZE, &saved_);
    old_handler_ = ::signal(SIGXFSZ, SIG_IGN);  // write() then fails with EFBIG
    rlimit limit = saved_;
    limit.rlim_cur = bytes;
    ok_ = ::setrlimit(RLIMIT_FSIZE, &limit) == 0;
  }
  ~FileSizeLimit() {
    ::setrlimit(RLIMIT_FSIZE, &saved_);
    ::signal(SIGXFSZ, old_handler_);
  }
  FileSizeLimit(const FileSizeLimit&) = delete;
  FileSizeLimit& operator=(const FileSizeLimit&) = delete;
  bool ok() const { return ok_; }

 private:
  rlimit saved_{};
  sighandler_t old_handler_ = SIG_DFL;
  bool ok_ = false;
};

// A file-size limit (RLIMIT_FSIZE) hit in the middle of a chunk: the kernel writes part of it,
// then refuses (EFBIG); the writer cuts the partial chunk off, so the file ends on a whole one.
TEST(WriterErrors, PartialChunkWriteIsCutBackToTheLastWholeChunk) {
  const std::string path = TempDir() + "/limit.mcap";
  WriterOptions o;
  o.chunk_bytes = 4096;
  o.compression = Compression::kNone;
  Result<std::unique_ptr<Writer>> created = Writer::Create(path, o);
  ASSERT_TRUE(created.ok());
  Writer& w = **created;
  const uint16_t channel = w.AddChannel(0, "/cam", "raw");
  std::vector<Sent> sent;
  Status failure;
  size_t flushed = 0;
  {
    FileSizeLimit limit(10'000);  // two chunks of ~4.2 KB fit, the third does not
    ASSERT_TRUE(limit.ok());
    flushed = WriteUntilFailure(w, channel, sent, failure);
  }
  ASSERT_FALSE(failure.ok());
  EXPECT_THAT(failure, IsError(ErrorCode::kResourceExhausted, HasSubstr("File too large")));
  EXPECT_EQ(w.chunks(), 2u);
  EXPECT_EQ(std::filesystem::file_size(path), w.bytes()) << "the partial chunk was cut off";
  EXPECT_FALSE(w.Close().ok());
  std::unique_ptr<Reader> reader = OpenOrDie(path);
  ASSERT_NE(reader, nullptr);
  EXPECT_THAT(reader->note(), HasSubstr("the file ends between two records"));
  const std::vector<Message> read = ReadAllOrDie(*reader);
  ASSERT_EQ(read.size(), flushed);
  for (size_t i = 0; i < flushed; ++i) EXPECT_EQ(read[i].data, sent[i].data);
}

// ---- Reader API ---------------------------------------------------------------------------------

TEST(ReaderErrors, MissingFileNotMcapAndBadOptions) {
  Result<std::unique_ptr<Reader>> r = Reader::Open(TempDir() + "/none.mcap");
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r, IsError(ErrorCode::kNotFound));
  r = Reader::FromBytes("GIF89a, not a flight", "picture.gif");
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(
      r, IsError(ErrorCode::kInvalidArgument, HasSubstr("picture.gif: byte 0: not an MCAP file")));
  ReaderOptions o;
  o.max_chunk_bytes = 10;
  r = Reader::FromBytes(std::string(kMagic), "x", o);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.error().message, HasSubstr("options.max_chunk_bytes"));
  r = Reader::Open(TempDir());
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r, IsError(ErrorCode::kInvalidArgument)) << "a directory is not a file";
}

}  // namespace
}  // namespace stevi::mcap
