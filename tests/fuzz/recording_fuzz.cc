// Fuzz target: a recording directory as the replay source reads it (drivers/recording): the
// manifest (protobuf JSON, with the rig's calibration YAML) and records.bin (varint-framed
// RecordEntry messages holding PNG images, vehicle states and calibration changes), through
// RecordingReader::Open, Next() to the end, Rewind() and a second pass.
//
// Input: byte 0, bit 0: decode the images (Next(true)), else the fast scan; bytes 1-2, little
// endian: the manifest's length N (cut to what is there); then N bytes of manifest.json, and the
// rest is records.bin. Both are written to a temporary folder of this process, then read.
// Checked besides the sanitizers:
//   - records come at increasing offsets inside the file, frames are counted, and decoded frames
//     have two 8-bit images (grey or BGR) of one size within the format's limits;
//   - the iteration ends (within one record per byte), and after Rewind() a second pass returns
//     the same records and the same end note;
//   - nothing throws out.
// The same folder then goes through `stevi export --format mcap`'s own reader of the format
// (client/advisory/flight_export.h, protobuf alone), which must end with a result or a clear
// error; when it succeeds, the MCAP file it wrote reads back whole.
#include <unistd.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

#include "client/advisory/flight_export.h"
#include "drivers/mcap/mcap_reader.h"
#include "drivers/recording/recording_reader.h"
#include "tests/fuzz/require.h"

namespace drivers = stevi::drivers;

namespace {

using stevi::fuzz::Require;

// This process's folder, removed at exit (never destroyed, so the exit handler can name it).
const std::string& Folder() {
  static const std::string* const folder = [] {
    std::string pattern =
        (std::filesystem::temp_directory_path() / "stevi-fuzz-recording-XXXXXX").string();
    Require(mkdtemp(pattern.data()) != nullptr);
    std::atexit([] {
      std::error_code ignored;
      std::filesystem::remove_all(Folder(), ignored);
    });
    return new std::string(std::move(pattern));
  }();
  return *folder;
}

void WriteFile(const std::string& path, const uint8_t* data, size_t size) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  Require(out.good());
}

// What one pass saw: each record's kind and offset, and how it ended.
struct Pass {
  std::vector<std::pair<int, uint64_t>> records;
  uint64_t frames = 0;
  std::string end_note;
  bool operator==(const Pass&) const = default;
};

void CheckFrame(const stevi::StereoFrame& frame, bool decoded) {
  if (!decoded) {
    Require(frame.left.empty() && frame.right.empty());
    return;
  }
  Require(!frame.left.empty() && frame.left.size() == frame.right.size());
  Require(frame.left.type() == frame.right.type());
  Require(frame.left.type() == CV_8UC1 || frame.left.type() == CV_8UC3);
  Require(frame.left.cols <= drivers::kMaxImageSide && frame.left.rows <= drivers::kMaxImageSide);
}

Pass ReadAll(drivers::RecordingReader& reader, bool decode) {
  Pass pass;
  uint64_t last_end = 0;
  const uint64_t size = reader.file_size();
  for (uint64_t n = 0;; ++n) {
    Require(n <= size);  // every record takes at least one byte
    std::optional<drivers::RecordingRecord> record = reader.Next(decode);
    if (!record) break;
    Require(record->offset >= last_end && record->offset < size);
    Require(reader.offset() > record->offset && reader.offset() <= size);
    last_end = reader.offset();
    if (record->kind == drivers::RecordingRecord::Kind::kFrame) {
      CheckFrame(record->frame, decode);
      ++pass.frames;
    }
    pass.records.emplace_back(static_cast<int>(record->kind), record->offset);
  }
  Require(!reader.Next(decode).has_value());  // the end stays the end
  Require(reader.frames_read() == pass.frames);
  pass.end_note = reader.end_note();
  return pass;
}

}  // namespace

// The client's export of the folder into a flight log, read back.
void Export(const std::string& dir) {
  const std::string out = dir + "/export.mcap";
  std::error_code ignored;
  std::filesystem::remove(out, ignored);
  stevi::Result<std::unique_ptr<drivers::FlightLog>> log =
      drivers::FlightLog::Create(out, drivers::FlightLogOptions{}, {});
  Require(log.ok());
  const stevi::Result<stevi::client::RecordingExport> done =
      stevi::client::ExportRecording(dir, **log);
  Require(done.ok() || !done.error().message.empty());
  Require((*log)->Close().ok());
  stevi::Result<std::unique_ptr<stevi::mcap::Reader>> read = stevi::mcap::Reader::Open(out);
  Require(read.ok() && (*read)->indexed());
  Require((*read)->ReadAll().ok());
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 3) return 0;
  const bool decode = (data[0] & 1) != 0;
  const size_t manifest_size = std::min<size_t>(data[1] | (size_t{data[2]} << 8), size - 3);
  const uint8_t* manifest = data + 3;
  const uint8_t* records = manifest + manifest_size;
  const size_t records_size = size - 3 - manifest_size;

  const std::string& dir = Folder();
  WriteFile(dir + "/" + drivers::kManifestFileName, manifest, manifest_size);
  WriteFile(dir + "/" + drivers::kRecordsFileName, records, records_size);

  Export(dir);
  stevi::Result<std::unique_ptr<drivers::RecordingReader>> opened =
      drivers::RecordingReader::Open(dir);
  if (!opened.ok()) return 0;
  drivers::RecordingReader& reader = **opened;
  Require(reader.rig() != nullptr && reader.file_size() == records_size);
  const Pass first = ReadAll(reader, decode);
  Require(reader.Rewind().ok());
  Require(reader.offset() == 0 && reader.frames_read() == 0 && reader.end_note().empty());
  const Pass second = ReadAll(reader, decode);
  Require(first == second);
  return 0;
}
