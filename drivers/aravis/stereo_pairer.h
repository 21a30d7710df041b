// Pairs the frames of two separately clocked cameras into stereo pairs by capture time.
// Pure C++ (no Aravis), so that the pairing rules are testable without cameras.
#pragma once

#include <cstdint>
#include <deque>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/stereo_frame.h"
#include "drivers/stereo_source.h"

namespace stevi::drivers {

enum class Side { kLeft, kRight };

// "left" or "right".
const char* SideName(Side side);

// One frame of one camera.
struct MonoFrame {
  cv::Mat image;             // CV_8UC1
  int64_t t_ns = 0;          // capture time on the clock that both cameras share
  int64_t unix_time_ns = 0;  // wall-clock time of the capture (0 = unknown)
  uint64_t frame_id = 0;     // the camera's frame counter (diagnostics only)
};

struct PairerOptions {
  // Largest |right - left| capture-time difference of a pair, ns (> 0). Half a frame period is
  // the natural choice: a frame can then only ever lie within the tolerance of one partner.
  int64_t tolerance_ns = 16'666'667;
  // Frames kept per side while waiting for a partner (>= 1). When the other side stalls, the
  // oldest is dropped (and counted) beyond this.
  int max_pending = 4;

  std::vector<std::string> Validate() const;
};

// Thread-compatible: one caller at a time (the Aravis source serialises its two camera threads
// with a mutex).
//
// Rules, for frames that arrive in capture-time order on each side:
// - A new frame pairs with the closest pending frame of the other side within the tolerance.
//   The pair gets t_ns = left time, pair_skew_ns = right - left, index = pairs before it.
//   Pending frames older than the two partners can never pair any more and are dropped.
// - An unpaired frame waits. Frames older than the other side's newest time minus the
//   tolerance can never pair (the other side only gets newer) and are dropped.
// - A frame not newer than the last one of its side (a clock step back, a duplicate) is dropped.
// Every drop counts in unpaired_dropped.
class StereoPairer {
 public:
  explicit StereoPairer(PairerOptions options = {});

  // Adds a frame; returns the pair it completes, if any.
  std::optional<StereoFrame> Add(Side side, MonoFrame frame);

  // Forgets one side's pending frames and its last time, e.g. after the camera reconnected
  // (its clock may have restarted). The dropped frames are counted.
  void ResetSide(Side side);

  // pairs, unpaired_dropped and the skew statistics; the other fields are 0.
  SourceCounters Counters() const;

  // Frames waiting for a partner on one side.
  size_t pending(Side side) const { return queue(side).size(); }
  const PairerOptions& options() const { return options_; }

 private:
  std::deque<MonoFrame>& queue(Side side) { return side == Side::kLeft ? left_ : right_; }
  const std::deque<MonoFrame>& queue(Side side) const {
    return side == Side::kLeft ? left_ : right_;
  }
  // Drops the frames of `side` captured before `t_ns` (counted).
  void DropOlderThan(Side side, int64_t t_ns);
  StereoFrame MakePair(MonoFrame left, MonoFrame right);

  PairerOptions options_;
  std::deque<MonoFrame> left_, right_;
  // Newest capture time seen per side (also of frames already paired or dropped).
  std::optional<int64_t> newest_left_, newest_right_;

  uint64_t pairs_ = 0;
  uint64_t dropped_ = 0;
  int64_t last_skew_ns_ = 0;
  int64_t max_abs_skew_ns_ = 0;
  // |skew| of the last kSkewWindow pairs (a ring) and their sum, for the running mean.
  static constexpr size_t kSkewWindow = 100;
  std::vector<int64_t> recent_abs_skew_;
  size_t recent_next_ = 0;
  int64_t recent_sum_ = 0;
};

}  // namespace stevi::drivers
