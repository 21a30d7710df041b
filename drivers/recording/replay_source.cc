#include "drivers/recording/replay_source.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <thread>
#include <utility>

#include "core/geometry/calibration_io.h"

namespace stevi::drivers {
namespace {

using Clock = std::chrono::steady_clock;

// A recorded gap longer than this (a paused capture, a clock jump, a damaged time) is played as
// this long, so that the replay never stalls for hours.
constexpr int64_t kMaxGapNs = 10'000'000'000;
// A caller this far behind the schedule gets the schedule moved rather than a burst of frames.
constexpr auto kMaxLate = std::chrono::milliseconds(500);
// The pause at a loop's wrap when the recording has one frame (no frame period to go by).
constexpr int64_t kDefaultPeriodNs = 100'000'000;
// Skews averaged for SourceCounters::mean_abs_skew_ns.
constexpr size_t kRecentSkews = 100;

}  // namespace

Result<std::unique_ptr<ReplaySource>> ReplaySource::Open(const std::string& dir,
                                                         ReplayOptions options) {
  if (std::vector<std::string> problems = options.Validate(); !problems.empty()) {
    return InvalidArgument(problems);
  }
  Result<std::unique_ptr<RecordingReader>> opened = RecordingReader::Open(dir);
  if (!opened.ok()) return opened.error();
  RecordingReader& reader = **opened;

  auto source = std::unique_ptr<ReplaySource>(new ReplaySource());
  source->dir_ = dir;
  source->options_ = options;
  source->manifest_ = reader.manifest();
  source->initial_rig_ = reader.rig();

  // One pass without decoding images: the frame count and everything that is not a frame.
  while (std::optional<RecordingRecord> record = reader.Next(/*decode_images=*/false)) {
    switch (record->kind) {
      case RecordingRecord::Kind::kFrame:
        if (source->frame_count_ == 0) source->first_t_ns_ = record->frame.t_ns;
        source->last_t_ns_ = record->frame.t_ns;
        ++source->frame_count_;
        break;
      case RecordingRecord::Kind::kVehicleState:
        source->vehicle_states_.push_back(record->vehicle_state);
        break;
      case RecordingRecord::Kind::kCalibration: {
        ReplayCalibrationChange change;
        change.frames_before = source->frame_count_;
        change.change = std::move(record->calibration);
        Result<geometry::StereoCalibration> calibration =
            geometry::ParseCalibrationYaml(change.change.yaml);
        Result<geometry::StereoRig> rig =
            calibration.ok()
                ? geometry::StereoRig::FromCalibration(*calibration, change.change.calibration_id)
                : Result<geometry::StereoRig>(calibration.error());
        if (rig.ok()) {
          change.rig = std::make_shared<const geometry::StereoRig>(std::move(rig.value()));
        } else {
          source->notes_.push_back(
              reader.records_path() + ": calibration change '" + change.change.calibration_id +
              "' after " + std::to_string(change.frames_before) + " frames gives no rig (" +
              rig.error().message + "); the frames after it keep the previous rig");
        }
        source->changes_.push_back(std::move(change));
        break;
      }
    }
  }
  if (!reader.end_note().empty()) source->notes_.insert(source->notes_.begin(), reader.end_note());
  // The same reader plays the frames (the manifest is not read, nor the rig built, again).
  source->reader_ = std::move(opened.value());
  if (Status s = source->Rewind(); !s) return s.error();
  return source;
}

Status ReplaySource::Rewind() {
  if (Status s = reader_->Rewind(); !s) return s;
  next_change_ = 0;
  frames_this_lap_ = 0;
  std::lock_guard lock(mu_);
  rig_ = initial_rig_;
  calibration_id_ = manifest_.calibration_id();
  return Status::Ok();
}

std::string ReplaySource::Describe() const {
  std::string rate;
  if (options_.rate == 0) {
    rate = "max";
  } else {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%gx", options_.rate);
    rate = buf;
  }
  std::string text = "replay " + dir_ + " (" + std::to_string(frame_count_) + " frames, rate ";
  text += rate;
  if (options_.loop) text += ", loop";
  text += ")";
  return text;
}

std::shared_ptr<const geometry::StereoRig> ReplaySource::Rig() const {
  std::lock_guard lock(mu_);
  return rig_;
}

std::string ReplaySource::calibration_id() const {
  std::lock_guard lock(mu_);
  return calibration_id_;
}

SourceCounters ReplaySource::Counters() const {
  std::lock_guard lock(mu_);
  return counters_;
}

Result<StereoFrame> ReplaySource::Next() {
  // Bounded: each pass reads one record, and a lap without a frame ends the replay.
  while (true) {
    if (Interrupted()) return Unavailable("replay " + dir_ + ": stopped");
    std::optional<RecordingRecord> record = reader_->Next(/*decode_images=*/true);
    if (!record) {
      if (options_.loop && frames_this_lap_ > 0) {
        if (Status s = Rewind(); !s) return s.error();
        ++laps_;
        wrapped_ = true;
        continue;
      }
      std::string message = frame_count_ == 0
                                ? "replay " + dir_ + ": the recording holds no frames"
                                : "end of the recording " + dir_ + " after " +
                                      std::to_string(reader_->frames_read()) + " frames";
      if (!reader_->end_note().empty()) message += " (" + reader_->end_note() + ")";
      return OutOfRange(message);
    }
    switch (record->kind) {
      case RecordingRecord::Kind::kVehicleState: continue;  // all of them were read at Open()
      case RecordingRecord::Kind::kCalibration: {
        // The i-th change of this lap is the i-th of the scan: the file is the same.
        if (next_change_ < changes_.size()) {
          const ReplayCalibrationChange& change = changes_[next_change_];
          if (change.rig) {
            std::lock_guard lock(mu_);
            rig_ = change.rig;
            calibration_id_ = change.change.calibration_id;
          }
        }
        ++next_change_;
        continue;
      }
      case RecordingRecord::Kind::kFrame: break;
    }
    StereoFrame& frame = record->frame;
    Pace(frame.t_ns);
    if (Interrupted()) return Unavailable("replay " + dir_ + ": stopped");
    ++frames_this_lap_;
    {
      std::lock_guard lock(mu_);
      ++counters_.pairs;
      const int64_t abs_skew = std::abs(frame.pair_skew_ns);
      counters_.last_skew_ns = frame.pair_skew_ns;
      counters_.max_abs_skew_ns = std::max(counters_.max_abs_skew_ns, abs_skew);
      recent_abs_skew_ns_.push_back(abs_skew);
      if (recent_abs_skew_ns_.size() > kRecentSkews) recent_abs_skew_ns_.pop_front();
      double sum = 0;
      for (int64_t s : recent_abs_skew_ns_) sum += static_cast<double>(s);
      counters_.mean_abs_skew_ns = sum / static_cast<double>(recent_abs_skew_ns_.size());
    }
    return std::move(frame);
  }
}

void ReplaySource::Pace(int64_t t_ns) {
  if (options_.rate <= 0) return;
  if (!paced_) {
    paced_ = true;
    anchor_ = Clock::now();
    recorded_since_anchor_ns_ = 0;
  } else {
    int64_t step_ns = t_ns - previous_t_ns_;
    if (wrapped_) {
      // A new lap: one frame period after the last frame, not the (negative) step back in time.
      step_ns = frame_count_ > 1
                    ? (last_t_ns_ - first_t_ns_) / static_cast<int64_t>(frame_count_ - 1)
                    : kDefaultPeriodNs;
    }
    recorded_since_anchor_ns_ += std::clamp<int64_t>(step_ns, 0, kMaxGapNs);
  }
  wrapped_ = false;
  previous_t_ns_ = t_ns;
  const auto due = anchor_ + std::chrono::nanoseconds(std::llround(
                                 static_cast<double>(recorded_since_anchor_ns_) / options_.rate));
  const Clock::time_point now = Clock::now();
  if (now > due + kMaxLate) {
    // The caller stalled: carry on from now instead of catching up in a burst.
    anchor_ = now;
    recorded_since_anchor_ns_ = 0;
    return;
  }
  std::unique_lock lock(mu_);
  interrupt_cv_.wait_until(lock, due, [&] { return interrupted_; });
}

void ReplaySource::Interrupt() {
  {
    std::lock_guard lock(mu_);
    interrupted_ = true;
  }
  interrupt_cv_.notify_all();
}

bool ReplaySource::Interrupted() const {
  std::lock_guard lock(mu_);
  return interrupted_;
}

}  // namespace stevi::drivers
