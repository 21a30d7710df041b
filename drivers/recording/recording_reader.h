// Reading a recording (drivers/recording): the manifest, the rig, and the records in order. Also
// the format's constants and conversions, shared with the recorder. The format itself is
// described in proto/stevi/v1/recording.proto.
#pragma once

#include <cstdint>
#include <fstream>
#include <memory>
#include <optional>
#include <string>

#include "core/common/error.h"
#include "core/common/stereo_frame.h"
#include "core/geo/vehicle_state.h"
#include "core/geometry/stereo_rig.h"
#include "stevi/v1/recording.pb.h"

namespace stevi::drivers {

// ---- The format ---------------------------------------------------------------------------------

inline constexpr uint32_t kRecordingFormatVersion = 1;
inline constexpr const char* kManifestFileName = "manifest.json";
inline constexpr const char* kRecordsFileName = "records.bin";

// Limits that keep a damaged or hostile recording from making the reader allocate absurd amounts.
// The recorder refuses frames beyond them, so every recording it writes stays readable.
inline constexpr uint64_t kMaxManifestBytes = 16ull << 20;    // the manifest holds one YAML: KiB
inline constexpr uint64_t kMaxRecordBytes = 512ull << 20;     // one serialized RecordEntry
inline constexpr int kMaxImageSide = 16384;                   // width or height, pixels
inline constexpr int64_t kMaxImagePixels = int64_t{1} << 26;  // 64 Mpx: two BGR images < 512 MiB

// "4.0 GiB", "12.5 MiB", "900 B": sizes for messages.
std::string FormatBytes(uint64_t bytes);

// The vehicle state as stored (stevi.v1.VehicleState; t_ns is its unix_time_ns) and back.
v1::VehicleState VehicleStateToProto(const geo::VehicleState& state);
geo::VehicleState VehicleStateFromProto(const v1::VehicleState& state);

// The manifest's description of `rig`, chosen so that RigFromRecorded() rebuilds it bit for bit
// (ideal rigs as their numbers, others as their calibration YAML with the rectification terms).
// kInternal if the rebuilt rig would differ (a bug: the check runs before anything is recorded).
Result<v1::RecordedRig> RecordedRigOf(const geometry::StereoRig& rig);
// Rebuilds the rig. kInvalidArgument naming the bad field (the manifest is untrusted).
Result<geometry::StereoRig> RigFromRecorded(const v1::RecordedRig& recorded);

// True when the two rigs are the same bit for bit: image size, f, B, cx, cy, Q, every calibration
// matrix, whether they remap, and the calibration id.
bool RigsIdentical(const geometry::StereoRig& a, const geometry::StereoRig& b);

// ---- Reading ------------------------------------------------------------------------------------

// A calibration change recorded while recording: the frames after it follow this calibration.
struct CalibrationChange {
  std::string calibration_id;
  std::string yaml;          // OpenCV FileStorage YAML
  int64_t unix_time_ns = 0;  // when the change was made
};

// One record of records.bin.
struct RecordingRecord {
  enum class Kind { kFrame, kVehicleState, kCalibration };
  Kind kind = Kind::kFrame;
  StereoFrame frame;                  // kFrame (images empty when read with decode_images false)
  geo::VehicleState vehicle_state{};  // kVehicleState
  CalibrationChange calibration;      // kCalibration
  uint64_t offset = 0;                // byte offset of the record's length prefix in records.bin
};

// Reads one recording directory. Thread-compatible: use from one thread.
class RecordingReader {
 public:
  // Reads and checks DIR/manifest.json and rebuilds the rig, then opens DIR/records.bin.
  // kNotFound when DIR or a file is missing; kInvalidArgument naming the file and the problem for
  // a garbled manifest, an unknown format version or a rig that cannot be rebuilt.
  static Result<std::unique_ptr<RecordingReader>> Open(const std::string& dir);

  // The next record, in the order they were written; nullopt at the end. A truncated or corrupt
  // tail (a crash, a damaged disk) also ends the iteration, with end_note() saying where. With
  // decode_images false frame records keep their images empty (a fast scan).
  std::optional<RecordingRecord> Next(bool decode_images = true);

  // Back to the first record, as if just opened (records.bin's size is read again, so a live
  // recording shows what was written since). kInvalidArgument naming the file if it is gone.
  Status Rewind();

  // Empty after a clean end; else why the records ended early ("DIR/records.bin: truncated
  // record after 57 frames at byte 1234567 (2048 bytes announced, 100 left)").
  const std::string& end_note() const { return end_note_; }
  // Frames returned so far; byte offset of the next record.
  uint64_t frames_read() const { return frames_read_; }
  uint64_t offset() const { return offset_; }
  // Size of records.bin when it was opened (a live recording may grow; the rest is not read).
  uint64_t file_size() const { return file_size_; }
  // Records of kinds this version does not know (from a newer writer), skipped.
  uint64_t unknown_skipped() const { return unknown_skipped_; }

  const std::string& dir() const { return dir_; }
  const std::string& records_path() const { return records_path_; }
  const v1::RecordingManifest& manifest() const { return manifest_; }
  // The rig rebuilt from the manifest (identical to the recorded source's).
  std::shared_ptr<const geometry::StereoRig> rig() const { return rig_; }

 private:
  RecordingReader() = default;
  // Ends the iteration with a note; returns nullopt for Next() to pass on.
  std::nullopt_t EndWith(const std::string& problem);
  // Decodes one image and checks it against its stored size and channels.
  Result<cv::Mat> DecodeImage(const v1::RecordedImage& image, const char* side) const;
  // Next's steps, each returning the problem that ends the iteration (nullopt when all is well;
  // `where` places the record in messages). ReadRecordBytes: the record at `start` (its varint32
  // length prefix, then its bytes into buffer_), offset_ moved past it. ReadFrame: a frame
  // record's checks, and `frame` filled (with its images decoded when `decode_images`).
  std::optional<std::string> ReadRecordBytes(uint64_t start, const std::string& where);
  std::optional<std::string> ReadFrame(const v1::RecordedFrame& f, bool decode_images,
                                       const std::string& where, StereoFrame& frame) const;

  std::string dir_;
  std::string records_path_;
  v1::RecordingManifest manifest_;
  std::shared_ptr<const geometry::StereoRig> rig_;
  std::ifstream records_;
  uint64_t file_size_ = 0;
  uint64_t offset_ = 0;
  uint64_t frames_read_ = 0;
  uint64_t unknown_skipped_ = 0;
  bool ended_ = false;
  std::string end_note_;
  std::string buffer_;  // one record's bytes, reused
};

}  // namespace stevi::drivers
