// Replaying a recording (drivers/recording/recorder.h) as a stereo source, at its recorded pace.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "core/geo/vehicle_state.h"
#include "drivers/recording/recording_reader.h"
#include "core/common/fields.h"
#include "drivers/stereo_source.h"

namespace stevi::drivers {

struct ReplayOptions {
  // Speed relative to the recording: 1 plays at the recorded pace, 4 four times faster, 0 as fast
  // as the caller takes frames. >= 0 and finite.
  double rate = 1.0;
  // Start again at the first frame after the last. Each lap repeats the recorded frames exactly
  // (index and times jump back at the wrap; the tracker treats a backward step as no time).
  bool loop = false;

  // Every problem, as "field: problem (got X)".
  std::vector<std::string> Validate() const { return fields::Check(*this); }

  // The fields of stevi.v1.ReplayConfig but its directory.
  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Number(s.rate, Field("rate", "",
                           "speed against the recording; 0 = as fast as the pipeline "
                           "takes frames")
                         .Above(0)
                         .AtMost(1000)
                         .Or(0, "max")
                         .Flag("rate", "R|max"));
    v.Flag(s.loop, Field("loop", "", "start again at the end"));
  }
};

// A calibration change, where it happened in the recording.
struct ReplayCalibrationChange {
  uint64_t frames_before = 0;  // frames recorded before it; the later ones follow it
  CalibrationChange change;
  // The rig rebuilt from it; null when its YAML does not give a rig (see ReplaySource::notes()),
  // and then the frames after it keep the rig they had.
  std::shared_ptr<const geometry::StereoRig> rig;
};

// Plays DIR's frames in order, decoded losslessly, with their recorded index, times, skew and
// rectified flag. Thread-compatible like every StereoSource: one thread calls Next(); Rig(),
// calibration_id() and Counters() are safe from any thread, the other accessors are immutable
// after Open().
class ReplaySource : public StereoSource {
 public:
  // Reads the manifest and scans records.bin once (without decoding images) for the frame count,
  // the vehicle states and the calibration changes. Errors as RecordingReader::Open's, plus
  // kInvalidArgument for invalid options. A truncated tail is not an error: the replay ends
  // before it, and notes() says so.
  static Result<std::unique_ptr<ReplaySource>> Open(const std::string& dir, ReplayOptions options);

  // "replay DIR (N frames, rate 1x)" ("rate max" for rate 0, ", loop" when looping).
  std::string Describe() const override;
  // The rig the frames last returned follow: the recording's rig, or the latest calibration
  // change passed.
  std::shared_ptr<const geometry::StereoRig> Rig() const override;
  // The next frame. At rate > 0 it waits (steady clock) until start + (t_k - t_0) / rate, where
  // start is when the first frame came out; recorded gaps longer than 10 s are shortened to 10 s,
  // and a caller that falls more than 0.5 s behind is not given the missed frames in a burst.
  // kOutOfRange at the end (unless looping); errors of a damaged recording end it the same way.
  Result<StereoFrame> Next() override;
  // 0: the replay paces itself.
  double NominalFps() const override { return 0; }
  SourceCounters Counters() const override;
  // Wakes a Next() waiting for a frame's recorded time (a gap may be 10 s divided by the rate).
  void Interrupt() override;

  // Every vehicle state of the recording, in recorded order (for a geo::PoseBuffer).
  const std::vector<geo::VehicleState>& vehicle_states() const { return vehicle_states_; }
  std::vector<geo::VehicleState> RecordedVehicleStates() const override { return vehicle_states_; }
  // The calibration changes of the recording, in order.
  const std::vector<ReplayCalibrationChange>& calibration_changes() const { return changes_; }
  // The calibration id the frames last returned follow (at first the manifest's calibration_id).
  std::string calibration_id() const;
  // Frames in the recording (up to a truncated or corrupt tail).
  uint64_t frame_count() const { return frame_count_; }
  // Capture times of the first and last frame, ns (0 without frames).
  int64_t first_t_ns() const { return first_t_ns_; }
  int64_t last_t_ns() const { return last_t_ns_; }
  // What was wrong with the recording: a truncated or corrupt tail, a calibration change that does
  // not give a rig. Empty for a sound recording.
  const std::vector<std::string>& notes() const { return notes_; }
  std::vector<std::string> Notes() const override { return notes_; }
  const v1::RecordingManifest& manifest() const { return manifest_; }
  const std::string& dir() const { return dir_; }
  // Completed laps (looping).
  int64_t laps() const { return laps_; }

 private:
  ReplaySource() = default;
  // Back to the first record, with the recording's rig.
  Status Rewind();
  // Waits until the frame with capture time t_ns is due.
  void Pace(int64_t t_ns);
  bool Interrupted() const;

  std::string dir_;
  ReplayOptions options_;
  v1::RecordingManifest manifest_;
  std::shared_ptr<const geometry::StereoRig> initial_rig_;
  std::vector<geo::VehicleState> vehicle_states_;
  std::vector<ReplayCalibrationChange> changes_;
  std::vector<std::string> notes_;
  uint64_t frame_count_ = 0;
  int64_t first_t_ns_ = 0;
  int64_t last_t_ns_ = 0;

  // Playback (the Next() thread).
  std::unique_ptr<RecordingReader> reader_;
  size_t next_change_ = 0;  // calibration changes passed in this lap
  uint64_t frames_this_lap_ = 0;
  int64_t laps_ = 0;
  bool paced_ = false;                            // the pacing clock is running
  bool wrapped_ = false;                          // the next frame starts a new lap
  std::chrono::steady_clock::time_point anchor_;  // when the anchor frame came out
  int64_t recorded_since_anchor_ns_ = 0;          // recorded time since the anchor frame
  int64_t previous_t_ns_ = 0;

  // Shared with other threads.
  mutable std::mutex mu_;
  std::condition_variable interrupt_cv_;  // Interrupt(), to a pacing wait
  bool interrupted_ = false;              // (mu_)
  std::shared_ptr<const geometry::StereoRig> rig_;
  std::string calibration_id_;
  SourceCounters counters_;
  std::deque<int64_t> recent_abs_skew_ns_;
};

}  // namespace stevi::drivers
