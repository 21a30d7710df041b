// Writing an MCAP file (drivers/mcap/README.md): schemas and messages are bytes; the writer puts
// every message in a chunk (zstd, lz4 frame or none), indexes each chunk, and writes the summary
// Foxglove needs to open a file fast and seek in it.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/error.h"
#include "drivers/mcap/mcap_format.h"

namespace stevi::mcap {

struct WriterOptions {
  Compression compression = Compression::kZstd;
  // A chunk closes when its uncompressed records reach this many bytes, in [1, 256 MiB].
  uint64_t chunk_bytes = 1 << 20;
  // ... or when its messages span this much log time, ns (> 0), so that a crash loses at most
  // about this much.
  int64_t chunk_span_ns = 1'000'000'000;
  std::string profile;            // Header.profile ("" for ours), at most 4 KiB
  std::string library = "stevi";  // Header.library, at most 4 KiB

  // Every problem, as "field: problem (got X)".
  std::vector<std::string> Validate() const;
};

// Writes one MCAP file: magic and Header at once, then chunks as they fill (each Chunk followed by
// one Message Index per channel in it, handed to the OS at once), and at Close() the summary. A
// crash loses only the open chunk. Thread-compatible: call from one thread at a time.
class Writer {
 public:
  // Creates `path` and writes magic + Header. kAlreadyExists if it exists (a flight is never
  // overwritten), kInvalidArgument for bad options, kNotFound (no such directory) or kInternal
  // naming the path when it cannot be created.
  static Result<std::unique_ptr<Writer>> Create(const std::string& path,
                                                WriterOptions options = {});
  // The same over a file descriptor opened for writing (a file the caller created, a pipe, a
  // device), which the writer owns from now on, even on error. `name` names it in messages. The
  // writer never seeks: it counts offsets from the first byte it writes.
  static Result<std::unique_ptr<Writer>> FromFd(int fd, std::string name,
                                                WriterOptions options = {});
  // Close()s if not closed; an error then is only printed to stderr.
  ~Writer();
  Writer(const Writer&) = delete;
  Writer& operator=(const Writer&) = delete;

  // A schema's id (>= 1). The same name, encoding and data again return the same id. 0 when
  // refused: data over kMaxSchemaBytes, names over kMaxRecordFieldsBytes, or 65535 schemas.
  uint16_t AddSchema(std::string_view name, std::string_view encoding, std::string_view data);
  // A channel's id (>= 1); schema_id 0 means no schema. The same arguments again return the same
  // id. 0 when refused: an unknown schema id, fields over kMaxRecordFieldsBytes, 65535 channels.
  uint16_t AddChannel(uint16_t schema_id, std::string_view topic, std::string_view message_encoding,
                      const std::map<std::string, std::string>& metadata = {});

  // Appends a message to the open chunk (its channel's and schema's records go first when it is
  // the channel's first message); the chunk is written when full (chunk_bytes, chunk_span_ns).
  // Sequence numbers count per channel from 0. kInvalidArgument for an unknown channel or data
  // over kMaxMessageBytes, kFailedPrecondition after Close(). A write failure (a full disk:
  // kResourceExhausted; others kUnavailable) is sticky: every later call returns it and nothing
  // more is written; the file keeps its whole chunks (a partly written one is cut off when the
  // file can be truncated) and reads as a file cut short.
  Status Write(uint16_t channel_id, uint64_t log_time_ns, uint64_t publish_time_ns,
               std::string_view data);
  // A Metadata record (e.g. the calibration's numbers), written at once.
  Status AddMetadata(std::string_view name, const std::map<std::string, std::string>& values);
  // An Attachment record with its CRC (e.g. the calibration YAML file), written at once;
  // create_time is set to log_time_ns.
  Status AddAttachment(std::string_view name, std::string_view media_type, uint64_t log_time_ns,
                       std::string_view data);
  // Writes the open chunk now, however small (e.g. before a long pause).
  Status Flush();
  // Writes the open chunk, DataEnd (with the data-section CRC), the summary (Schemas, Channels,
  // Statistics, Chunk Indexes, Attachment Indexes, Metadata Indexes, grouped), the Summary
  // Offsets, the Footer (with the summary CRC) and the closing magic, then syncs and closes the
  // file. Idempotent: later calls return the first call's result. After a write failure it only
  // closes the file and returns that failure.
  Status Close();

  // For status: messages accepted (the open chunk's included), chunks written, bytes written.
  uint64_t messages() const;
  uint64_t chunks() const;
  uint64_t bytes() const;

 private:
  struct Impl;
  explicit Writer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace stevi::mcap
