// Fuzz target: an MCAP file as drivers/mcap's Reader reads it (Reader::FromBytes): the footer and
// summary, the linear read of the data section with its recovery of files cut short, chunk
// decompression (zstd, lz4 frames) and CRCs, and the message iteration.
//
// Input: the file's bytes. The reader's chunk limit is 8 MiB, so that a chunk claiming a huge
// uncompressed size costs little.
// Checked besides the sanitizers:
//   - Open either fails with kInvalidArgument naming the input, or succeeds; a file read without
//     a summary has a note, an indexed one has none;
//   - an indexed file's messages, or the recovered ones (exactly recovered_messages() of them),
//     come out of ReadAll(), each on a channel the reader knows; a second ReadAll() returns the
//     same messages (or the same error);
//   - nothing throws out.
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "drivers/mcap/mcap.h"
#include "tests/fuzz/require.h"

namespace mcap = stevi::mcap;

namespace {

using stevi::fuzz::Require;

// What one ReadAll() gave: the messages, or the error's text.
struct Pass {
  std::vector<mcap::Message> messages;
  std::string error;
  bool operator==(const Pass&) const = default;
};

Pass ReadAll(mcap::Reader& reader) {
  Pass pass;
  stevi::Result<std::vector<mcap::Message>> all = reader.ReadAll();
  if (!all.ok()) {
    Require(all.error().code == stevi::ErrorCode::kInvalidArgument);
    pass.error = all.error().message;
    return pass;
  }
  pass.messages = std::move(*all);
  for (const mcap::Message& m : pass.messages) Require(reader.channel(m.channel_id) != nullptr);
  return pass;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  mcap::ReaderOptions options;
  options.max_chunk_bytes = 8 << 20;
  stevi::Result<std::unique_ptr<mcap::Reader>> opened =
      mcap::Reader::FromBytes(bytes, "fuzz.mcap", options);
  if (!opened.ok()) {
    Require(opened.error().code == stevi::ErrorCode::kInvalidArgument);
    Require(opened.error().message.rfind("fuzz.mcap: ", 0) == 0);
    return 0;
  }
  mcap::Reader& reader = **opened;
  Require(reader.file_size() == size);
  Require(reader.indexed() == reader.note().empty());
  const Pass first = ReadAll(reader);
  if (!reader.indexed()) {
    // A file read linearly had its chunks checked at Open(): reading them cannot fail.
    Require(first.error.empty());
    Require(first.messages.size() == reader.recovered_messages());
  }
  const Pass second = ReadAll(reader);
  Require(first == second);
  return 0;
}
