// Reading an MCAP file (drivers/mcap/README.md), ours or another writer's, checking every CRC and
// every length, and reading a file cut short (a crash, a full disk) up to its last whole chunk.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/common/error.h"
#include "drivers/mcap/mcap_format.h"

namespace stevi::mcap {

struct ReaderOptions {
  // The largest chunk accepted, uncompressed bytes, in [1 KiB, kMaxChunkBytes]. Lower it to bound
  // the memory an untrusted file can make the reader take (the fuzz target uses 8 MiB).
  uint64_t max_chunk_bytes = kMaxChunkBytes;

  // Every problem, as "field: problem (got X)".
  std::vector<std::string> Validate() const;
};

// Reads one MCAP file (ours or another writer's). Open() checks the whole file once: the
// footer, the summary and its CRC, every record of the data section and its CRC, every
// attachment's CRC. A file without a valid footer or summary (cut short by a crash or a full
// disk) is read linearly up to its last whole chunk whose CRC holds, and note() says what was
// recovered and what was lost. Messages are then read one chunk at a time, in file order; each
// chunk's CRC is checked as it is decompressed. Thread-compatible: use from one thread.
class Reader {
 public:
  // kNotFound when the file does not exist; kInvalidArgument naming the file, the byte offset and
  // the problem for anything that is not a readable MCAP file: a CRC mismatch, a length that runs
  // past its record, a summary that contradicts the data.
  static Result<std::unique_ptr<Reader>> Open(const std::string& path, ReaderOptions options = {});
  // The same over bytes in memory; `name` names them in messages.
  static Result<std::unique_ptr<Reader>> FromBytes(std::string bytes, std::string name,
                                                   ReaderOptions options = {});
  ~Reader();
  Reader(const Reader&) = delete;
  Reader& operator=(const Reader&) = delete;

  const std::string& name() const;
  uint64_t file_size() const;
  const Header& header() const;
  // Schemas and channels by id: the summary's, else those the linear read found. Messages read
  // later may add those defined only inside chunks.
  const std::map<uint16_t, Schema>& schemas() const;
  const std::map<uint16_t, Channel>& channels() const;
  const Schema* schema(uint16_t id) const;    // nullptr when unknown
  const Channel* channel(uint16_t id) const;  // nullptr when unknown
  // The summary's Statistics record, if it has one.
  const std::optional<Statistics>& statistics() const;
  // The summary's Chunk Indexes (empty without a summary).
  const std::vector<ChunkIndex>& chunk_indexes() const;
  // The Metadata and Attachment records of the data section, in file order.
  const std::vector<Metadata>& metadata() const;
  const std::vector<Attachment>& attachments() const;

  // True when the file has a valid footer and summary.
  bool indexed() const;
  // Empty for a whole, indexed file. Otherwise what was read and what was lost, e.g.
  // "flight.mcap: no summary (the file was cut short at byte 123456): read 812 messages in 14
  // whole chunks, up to byte 120034; the rest of the last chunk is lost".
  const std::string& note() const;
  // For a file without a summary, what the linear read at Open() found (0 otherwise).
  uint64_t recovered_messages() const;
  uint64_t recovered_chunks() const;

  // The next message in file order, nullopt at the end. kInvalidArgument naming the file and the
  // byte for a chunk that does not decompress, fails its CRC or holds a malformed record (only an
  // indexed file can have one: a file read linearly had its chunks checked by Open()); errors are
  // sticky until Rewind().
  Result<std::optional<Message>> Next();
  // Back to the first message.
  void Rewind();
  // Every message from the first, in file order (Rewind() and Next() to the end).
  Result<std::vector<Message>> ReadAll();

 private:
  struct Impl;
  explicit Reader(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace stevi::mcap
