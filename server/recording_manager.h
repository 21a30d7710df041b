// The server's recorder: at most one recording at a time, of every frame the source delivers
// (before the pipeline may drop one), with the vehicle pose at each frame and the calibration in
// use, for replay (--source replay, stevi-process --replay). RPC logic as plain functions.
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "core/common/error.h"
#include "drivers/recording/recorder.h"
#include "server/runtime/engine.h"
#include "server/runtime/pose_source.h"
#include "stevi/v1/obstacle_service.pb.h"

namespace stevi::server {

// A recording name a client may give: 1..64 of [A-Za-z0-9._-], not starting with '.'. Empty
// when it is fine, else the problem.
std::string CheckRecordingName(const std::string& name);

// Thread-safe. Installs itself as the engine's capture tap; the destructor stops a running
// recording and removes the tap.
class RecordingManager {
 public:
  // Recordings asked for by name go to DATA_DIR/recordings/NAME.
  RecordingManager(std::string data_dir, Engine& engine, const PoseSource& poses);
  ~RecordingManager();
  RecordingManager(const RecordingManager&) = delete;
  RecordingManager& operator=(const RecordingManager&) = delete;

  // Starts recording into `dir` (the operator's --record DIR: any path). kFailedPrecondition
  // while a recording runs; kAlreadyExists when `dir` holds a recording; kInvalidArgument for
  // options the recorder's field list refuses (drivers::RecorderOptions: max_bytes below 1 MiB).
  Result<v1::RecordingStatus> StartIn(const std::string& dir, uint64_t max_bytes,
                                      int queue_frames = drivers::RecorderOptions().queue_frames);
  // The StartRecording RPC: a checked name under DATA_DIR/recordings (default from the time).
  Result<v1::RecordingStatus> Start(const v1::StartRecordingRequest& request);
  // Stops the running recording, waiting for the queued frames to be written; without one,
  // the last recording's status.
  v1::RecordingStatus Stop(const std::string& reason = "stopped by request");
  // The running recording, else the last one (empty dir when there was none).
  v1::RecordingStatus Status() const;

 private:
  void OnFrame(const StereoFrame& frame);

  const std::string recordings_root_;
  Engine& engine_;
  const PoseSource& poses_;

  mutable std::mutex mu_;  // guards the members below (never held while the disk is written)
  std::shared_ptr<drivers::Recorder> active_;
  std::string active_dir_;
  uint64_t active_max_bytes_ = 0;
  std::string recorded_calibration_id_;
  std::optional<v1::RecordingStatus> last_;
};

}  // namespace stevi::server
