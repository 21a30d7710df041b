#include "drivers/mcap/source.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <utility>

#include "drivers/mcap/codec.h"

namespace stevi::mcap::internal {
namespace {

class MemoryBytes : public Source {
 public:
  explicit MemoryBytes(std::string bytes) : bytes_(std::move(bytes)) { size_ = bytes_.size(); }
  Result<std::string_view> Read(uint64_t offset, uint64_t n, std::string& /*scratch*/) override {
    return std::string_view(bytes_).substr(offset, n);
  }

 private:
  std::string bytes_;
};

class FileBytes : public Source {
 public:
  FileBytes(std::string path, int fd, uint64_t size) : path_(std::move(path)), fd_(fd) {
    size_ = size;
  }
  ~FileBytes() override { ::close(fd_); }
  FileBytes(const FileBytes&) = delete;
  FileBytes& operator=(const FileBytes&) = delete;

  Result<std::string_view> Read(uint64_t offset, uint64_t n, std::string& scratch) override {
    scratch.resize(n);
    uint64_t done = 0;
    while (done < n) {
      const ssize_t got =
          ::pread(fd_, scratch.data() + done, n - done, static_cast<off_t>(offset + done));
      if (got > 0) {
        done += static_cast<uint64_t>(got);
        continue;
      }
      if (got < 0 && errno == EINTR) continue;
      const std::string why = got < 0 ? std::strerror(errno) : "the file shrank while being read";
      return Unavailable(path_ + ": cannot read at byte " + std::to_string(offset + done) + " (" +
                         why + ")");
    }
    return std::string_view(scratch);
  }

 private:
  std::string path_;
  int fd_;
};

}  // namespace

Result<std::unique_ptr<Source>> OpenFileSource(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    const int err = errno;
    return Error{
        (err == ENOENT || err == ENOTDIR) ? ErrorCode::kNotFound : ErrorCode::kInvalidArgument,
        path + ": cannot open it (" + std::strerror(err) + ")"};
  }
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);
    return InvalidArgument(path + ": not a regular file");
  }
  return std::unique_ptr<Source>(
      std::make_unique<FileBytes>(path, fd, static_cast<uint64_t>(st.st_size)));
}

std::unique_ptr<Source> MemorySource(std::string bytes) {
  return std::make_unique<MemoryBytes>(std::move(bytes));
}

Result<RecordView> RecordIn(std::string_view bytes, uint64_t pos) {
  const uint64_t left = bytes.size() - pos;
  if (left < kRecordPrefixBytes) {
    return InvalidArgument("a record header needs 9 bytes, " + std::to_string(left) + " are left");
  }
  Decoder d(bytes.substr(pos, kRecordPrefixBytes));
  RecordView record;
  record.opcode = d.U8("opcode");
  const uint64_t length = d.U64("length");
  if (record.opcode == 0) {
    return InvalidArgument("invalid opcode 0x00 (not a record)");
  }
  if (length > left - kRecordPrefixBytes) {
    return InvalidArgument("the " + OpcodeName(record.opcode) + " record says " +
                           std::to_string(length) + " bytes, only " +
                           std::to_string(left - kRecordPrefixBytes) + " are left");
  }
  record.content = bytes.substr(pos + kRecordPrefixBytes, length);
  return record;
}

std::string Hex32(uint32_t value) {
  char text[16];
  std::snprintf(text, sizeof(text), "0x%08X", value);
  return text;
}

Result<std::string_view> DecodeChunk(const ChunkRecord& chunk, uint64_t max_bytes,
                                     std::string& buffer) {
  const auto problem = [](std::string text) { return InvalidArgument(std::move(text)); };
  if (chunk.uncompressed_size > max_bytes) {
    return problem("uncompressed_size " + std::to_string(chunk.uncompressed_size) +
                   " is over the limit of " + std::to_string(max_bytes) + " bytes");
  }
  if (!CompressionFromName(chunk.compression)) {
    return problem("unknown compression \"" + chunk.compression.substr(0, 32) + "\"");
  }
  std::string_view records;
  if (chunk.compression.empty()) {
    if (chunk.records.size() != chunk.uncompressed_size) {
      return problem("uncompressed records of " + std::to_string(chunk.records.size()) +
                     " bytes, uncompressed_size says " + std::to_string(chunk.uncompressed_size));
    }
    records = chunk.records;
  } else {
    if (Status s = Decompress(chunk.compression, chunk.records, chunk.uncompressed_size, buffer);
        !s) {
      return s.error();
    }
    records = buffer;
  }
  if (chunk.uncompressed_crc != 0) {
    const uint32_t actual = Crc32(records);
    if (actual != chunk.uncompressed_crc) {
      return problem("uncompressed CRC mismatch: the chunk says " + Hex32(chunk.uncompressed_crc) +
                     ", its records give " + Hex32(actual));
    }
  }
  return records;
}

}  // namespace stevi::mcap::internal
