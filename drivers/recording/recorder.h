// Recording stereo frames, vehicle states and calibration changes to a directory, for replay
// (drivers/recording/replay_source.h). The format: proto/stevi/v1/recording.proto.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <variant>
#include <vector>

#include "core/common/error.h"
#include "core/common/fields.h"
#include "core/common/stereo_frame.h"
#include "core/geo/vehicle_state.h"
#include "core/geometry/stereo_rig.h"
#include "drivers/recording/recording_reader.h"

namespace stevi::drivers {

struct RecorderOptions {
  // The smallest max_bytes: a few 640x480 pairs. Below it a recording would stop at once.
  static constexpr uint64_t kMinMaxBytes = uint64_t{1} << 20;

  // Bound on the size of records.bin, bytes. A record that would go past it is not written and
  // the recording stops, saying so. The manifest (a few KiB) comes on top.
  uint64_t max_bytes = uint64_t{4} << 30;
  // Frames waiting to be encoded and written. When the writer falls behind, AddFrame() drops the
  // frame (and counts it) rather than blocking the capture thread.
  int queue_frames = 32;
  // PNG (zlib) compression level: 1 is fast and still lossless; higher saves little on noisy
  // camera images and costs much CPU.
  int png_compression = 1;

  // The one declaration of each field and its bounds (core/common/fields.h). The server's
  // record { ... } settings and its StartRecording call are checked by it too.
  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Number(s.max_bytes, Field("max_bytes", "bytes", "bound on the recording's records.bin")
                              .AtLeast(static_cast<double>(kMinMaxBytes)));
    v.Number(s.queue_frames,
             Field("queue_frames", "frames", "frames waiting to be written").In(1, 1024));
    v.Number(s.png_compression,
             Field("png_compression", "", "zlib level of the PNGs").In(0, 9).NoProto());
  }

  // Every problem, as "field: problem (got X)".
  std::vector<std::string> Validate() const { return fields::Check(*this); }
};

// What is being recorded, for the manifest.
struct RecordingInfo {
  // The source's description (StereoSource::Describe()).
  std::string source;
  // The rig the frames follow (StereoSource::Rig()); required. Replay rebuilds it bit for bit.
  std::shared_ptr<const geometry::StereoRig> rig;
  // The calibration in use at the start; empty means the rig's calibration_id().
  std::string calibration_id;
};

// A snapshot of a recorder's state.
struct RecorderStatus {
  bool recording = false;  // false once stopped (by Stop(), the disk limit or a write error)
  std::string dir;
  uint64_t frames_written = 0;
  uint64_t bytes_written = 0;   // size of records.bin
  uint64_t frames_dropped = 0;  // the queue was full
  uint64_t frames_queued = 0;   // waiting to be written
  uint64_t vehicle_states_written = 0;
  uint64_t calibration_changes_written = 0;
  uint64_t other_dropped = 0;  // vehicle states and calibration changes the queue had no room for
  // Why it stopped ("disk limit of 4.0 GiB reached after 1234 frames"); empty while recording.
  std::string stop_reason;
  // The write error that stopped it, empty otherwise (then stop_reason says the same).
  std::string error;
};

// Records to one directory: DIR/manifest.json and DIR/records.bin. A writer thread encodes and
// appends; callers never wait for the disk. Thread-safe: every method may be called from any
// thread.
class Recorder {
 public:
  // Creates DIR if missing and starts recording: records.bin created, the manifest written
  // (state RECORDING). A DIR that already holds a recording is refused (kAlreadyExists), as are
  // invalid options or a missing rig (kInvalidArgument). Errors name the path.
  static Result<std::unique_ptr<Recorder>> Start(const std::string& dir, RecorderOptions options,
                                                 RecordingInfo info);
  // Stops as Stop("recorder destroyed") does.
  ~Recorder();
  Recorder(const Recorder&) = delete;
  Recorder& operator=(const Recorder&) = delete;

  // Queues a copy of the frame and returns at once. kResourceExhausted when the queue is full
  // (the frame is dropped and counted), kFailedPrecondition once stopped, kInvalidArgument for
  // images that are not 8-bit grey or BGR of one size within the format's limits.
  stevi::Status AddFrame(const StereoFrame& frame);
  // Queues a vehicle state, in order with the frames (same errors as AddFrame).
  stevi::Status AddVehicleState(const geo::VehicleState& state);
  // Records that the rig's calibration changed: the frames added after this call follow it.
  // kInvalidArgument when `yaml` is not a valid calibration (then nothing is recorded).
  stevi::Status SetCalibration(const std::string& calibration_id, const std::string& yaml);

  // Writes what is queued, syncs records.bin, writes the final manifest (state STOPPED with the
  // reason) and ends the writer thread. Blocks until done. Idempotent: a recording that already
  // stopped (disk limit, write error, an earlier Stop) keeps its first reason. Returns the write
  // error that stopped the recording, or a failure to write the final manifest.
  stevi::Status Stop(const std::string& reason = "stopped");

  RecorderStatus Status() const;

 private:
  struct Item {
    std::variant<StereoFrame, geo::VehicleState, CalibrationChange> entry;
  };
  // Why the writer ended, as it decided (disk limit, write error) or as asked.
  struct Outcome {
    std::string reason;
    std::string error;                      // empty unless a write failed
    ErrorCode code = ErrorCode::kInternal;  // of the error
  };

  Recorder(std::string dir, RecorderOptions options, v1::RecordingManifest manifest, int fd);
  // Queues an item unless the queue has no room (counted) or the recorder stopped.
  stevi::Status Enqueue(Item item);
  // Why an item of that kind cannot be queued now (stopped; no room, counted as dropped), or
  // nullopt when it can. mu_ must be held.
  std::optional<Error> RefuseLocked(bool frame);
  void WriterLoop();
  // Encodes and appends one record; an Outcome when the recording must stop (disk limit, error).
  std::optional<Outcome> Write(const Item& item);
  // Appends one framed record; truncates back to the last whole record on failure.
  std::optional<Outcome> Append(const std::string& record);
  // Syncs and closes records.bin and writes the final manifest; the error if any step failed.
  std::string Finish(const Outcome& outcome);

  const std::string dir_;
  const RecorderOptions options_;
  const std::string records_path_;
  const std::string manifest_path_;
  // Owned by the writer thread once it runs: records.bin and the manifest it rewrites at the end.
  int fd_ = -1;
  v1::RecordingManifest manifest_;

  mutable std::mutex mu_;
  std::condition_variable wake_;
  std::deque<Item> queue_;
  size_t queued_frames_ = 0;
  size_t queued_other_ = 0;
  bool stop_requested_ = false;
  std::string requested_reason_;
  bool stopped_ = false;         // new items are refused (the writer stopped, or Stop() was called)
  std::string stopping_reason_;  // the writer's reason, as soon as it decided to stop
  RecorderStatus status_;        // counters, guarded by mu_
  ErrorCode error_code_ = ErrorCode::kInternal;  // of status_.error

  std::mutex stop_mu_;  // serialises Stop() calls
  std::thread writer_;
};

}  // namespace stevi::drivers
