// `stevi export --format mcap`: flights into MCAP files that Foxglove opens. The sources are a
// file of TrackFrame JSON lines (`stevi watch --json`, stevi-process) and a stevi recording (a
// folder written by stevi-server --record or StartRecording), read through its format's protobuf
// messages (proto/stevi/v1/recording.proto) alone.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "core/common/error.h"
#include "drivers/mcap/flight_log.h"

namespace stevi::client {

// What a recording held, as exported.
struct RecordingExport {
  uint64_t frames = 0;  // frames read
  uint64_t images = 0;  // left images written (at the image rate)
  uint64_t vehicle_states = 0;
  uint64_t calibrations = 0;  // the manifest's rig and every change, as attachments
  std::string note;           // a truncated records file, a recording never stopped
};

// Limits that keep a damaged or hostile recording from making the reader allocate absurd
// amounts; the recorder never writes beyond them.
inline constexpr uint64_t kMaxExportManifestBytes = 16ull << 20;
inline constexpr uint64_t kMaxExportRecordBytes = 512ull << 20;

// Writes the recording in `dir` into `log`: the left images (PNG, lossless, as recorded) at the
// log's image rate, the vehicle states, and the calibrations as attachments. A torn last record
// (a crash) ends the reading with a note. kNotFound for a folder without a recording;
// kInvalidArgument naming the file, the record and the problem for a damaged one.
Result<RecordingExport> ExportRecording(const std::string& dir, drivers::FlightLog& log);

// Calls `each` with every TrackFrame JSON line of `path` (`stevi watch --json`, stevi-process),
// blank lines skipped, until it fails. kNotFound for a file that cannot be read; kInvalidArgument
// naming the line that is not a TrackFrame.
Status ForEachFrameLine(const std::string& path,
                        const std::function<Status(const v1::TrackFrame&)>& each);

}  // namespace stevi::client
