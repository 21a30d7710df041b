#include "client/advisory/flight_export.h"

#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/io/zero_copy_stream_impl.h>
#include <google/protobuf/util/json_util.h>

#include <fcntl.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "stevi/v1/recording.pb.h"

namespace stevi::client {
namespace {

namespace fs = std::filesystem;

Result<v1::RecordingManifest> ReadManifest(const std::string& dir) {
  const fs::path path = fs::path(dir) / "manifest.json";
  std::error_code ec;
  const uintmax_t size = fs::file_size(path, ec);
  if (ec) {
    return NotFound(dir + " is not a stevi recording (no manifest.json: " + ec.message() + ")");
  }
  if (size > kMaxExportManifestBytes) {
    return InvalidArgument(path.string() + ": " + std::to_string(size) +
                           " bytes, more than a manifest");
  }
  std::ifstream in(path, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  v1::RecordingManifest manifest;
  google::protobuf::util::JsonParseOptions parse;
  parse.ignore_unknown_fields = true;
  if (const auto status = google::protobuf::util::JsonStringToMessage(text.str(), &manifest, parse);
      !status.ok()) {
    return InvalidArgument(path.string() + ": not a recording manifest (" + status.ToString() +
                           ")");
  }
  if (manifest.format_version() != 1) {
    return InvalidArgument(path.string() + ": format version " +
                           std::to_string(manifest.format_version()) + " is not known (1 is)");
  }
  if (manifest.encoding() != v1::IMAGE_ENCODING_PNG) {
    return InvalidArgument(path.string() + ": image encoding " +
                           v1::ImageEncoding_Name(manifest.encoding()) + " is not known (PNG is)");
  }
  return manifest;
}

// A calibration as an attachment named after its id.
Status AttachCalibration(drivers::FlightLog& log, const std::string& id, const std::string& yaml,
                         int64_t time_ns) {
  if (yaml.empty()) return Status::Ok();
  return log.AddAttachment("calibration-" + (id.empty() ? std::string("initial") : id) + ".yaml",
                           "application/x-yaml", time_ns, yaml);
}

// The fd closes with the reader.
struct Fd {
  int fd = -1;
  ~Fd() {
    if (fd >= 0) ::close(fd);
  }
};

}  // namespace

Result<RecordingExport> ExportRecording(const std::string& dir, drivers::FlightLog& log) {
  Result<v1::RecordingManifest> manifest = ReadManifest(dir);
  if (!manifest.ok()) return manifest.error();
  RecordingExport out;
  if (Status s = AttachCalibration(log, manifest->calibration_id(),
                                   manifest->rig().calibration_yaml(), manifest->created_unix_ns());
      !s.ok()) {
    return s.error();
  }
  if (!manifest->rig().calibration_yaml().empty()) ++out.calibrations;
  if (manifest->state() != v1::RECORDING_STATE_STOPPED) {
    out.note = "the recording was never stopped (a crash?): its records file is read to its end";
  }

  const std::string records_path = (fs::path(dir) / "records.bin").string();
  Fd file{::open(records_path.c_str(), O_RDONLY | O_CLOEXEC)};
  if (file.fd < 0) return NotFound(records_path + ": cannot be opened");
  google::protobuf::io::FileInputStream raw(file.fd);
  uint64_t number = 0;
  for (;; ++number) {
    // One CodedInputStream per record: its byte counter and total limit stay per record.
    google::protobuf::io::CodedInputStream in(&raw);
    in.SetTotalBytesLimit(static_cast<int>(kMaxExportRecordBytes + 16));
    uint32_t size = 0;
    if (!in.ReadVarint32(&size)) break;  // the end (or a torn length: nothing follows)
    const std::string where = records_path + " record " + std::to_string(number);
    if (size > kMaxExportRecordBytes) {
      return InvalidArgument(where + ": " + std::to_string(size) + " bytes, more than any record");
    }
    std::string bytes;
    if (!in.ReadString(&bytes, static_cast<int>(size))) {
      out.note = where + " is cut short (a crash while recording?): read up to it";
      break;
    }
    v1::RecordEntry entry;
    if (!entry.ParseFromString(bytes)) return InvalidArgument(where + ": not a RecordEntry");
    if (entry.has_frame()) {
      const v1::RecordedFrame& f = entry.frame();
      ++out.frames;
      v1::TrackFrame timing;  // the flight log paces images on a frame's times
      timing.set_capture_time_ns(f.t_ns());
      timing.set_capture_unix_time_ns(f.unix_time_ns());
      if (log.ImageDue(v1::PREVIEW_KIND_LEFT, timing)) {
        const int64_t t = f.unix_time_ns() > 0 ? f.unix_time_ns() : f.t_ns();
        if (Status s = log.AddEncodedImage(v1::PREVIEW_KIND_LEFT, "png", f.left().data(), t);
            !s.ok()) {
          return s.error();
        }
        ++out.images;
      }
    } else if (entry.has_vehicle_state()) {
      if (Status s = log.AddVehicleState(entry.vehicle_state()); !s.ok()) return s.error();
      ++out.vehicle_states;
    } else if (entry.has_calibration()) {
      const v1::CalibrationChange& c = entry.calibration();
      if (Status s =
              AttachCalibration(log, c.calibration_id(), c.calibration_yaml(), c.unix_time_ns());
          !s.ok()) {
        return s.error();
      }
      ++out.calibrations;
    }
  }
  return out;
}

Status ForEachFrameLine(const std::string& path,
                        const std::function<Status(const v1::TrackFrame&)>& each) {
  std::ifstream in(path);
  if (!in) return NotFound("cannot read " + path);
  std::string line;
  uint64_t line_number = 0;
  google::protobuf::util::JsonParseOptions parse;
  parse.ignore_unknown_fields = true;
  while (std::getline(in, line)) {
    ++line_number;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    v1::TrackFrame frame;
    if (!google::protobuf::util::JsonStringToMessage(line, &frame, parse).ok()) {
      return InvalidArgument(path + " line " + std::to_string(line_number) +
                             ": not a TrackFrame JSON line (as `stevi watch --json` writes)");
    }
    if (Status s = each(frame); !s.ok()) return s;
  }
  return Status::Ok();
}

}  // namespace stevi::client
