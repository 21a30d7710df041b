// CLEAR-MOT scoring of reported tracks against ground truth with ids (Bernardin and Stiefelhagen,
// "Evaluating multiple object tracking performance: the CLEAR MOT metrics", 2008), on image boxes.
//
// Per frame:
//   1. A correspondence (truth id -> track id) of the previous frame is kept when both are still
//      there and their boxes still overlap with IoU >= min_iou.
//   2. The remaining expected truths and tracks are matched one-to-one by IoU >= min_iou, best
//      first (MatchByIoU).
//   3. A match whose track id differs from the one its truth was last matched to (in any earlier
//      frame) is an ID switch.
//   4. Unmatched expected truths are misses (FN). An unmatched track is "don't care" (neither a
//      match nor a false positive) when its box overlaps, IoU >= min_iou and one-to-one, the full
//      projected box of an obstacle that is not expected this frame (hidden behind another, cut by
//      the image border or outside it, too small or too far): a track that coasts on a real
//      obstacle it cannot see is right, not wrong. Any other unmatched track is a false positive.
//   5. A fragmentation is a truth trajectory that was tracked, then untracked while expected, then
//      tracked again (counted at the re-acquisition).
// MOTA = 1 - (FN + FP + IDSW) / GT, with GT the number of expected truths over all frames.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <set>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

namespace stevi::testing {

// One obstacle of the truth in one frame. Every obstacle of the scene is listed every frame,
// expected or not, so that the don't-care rule can see the hidden ones.
struct MotTruth {
  int id = 0;             // stable over the sequence
  bool expected = false;  // ground truth this frame: a tracker should report it
  cv::Rect box;           // the visible part (used when expected)
  cv::Rect full_box;      // the whole obstacle projected, not clipped to the image (may be empty)
  double range_m = 0;     // truth range, metres
  // The truth time to the closest approach (seconds from this frame), set only when the obstacle
  // is on a collision course (see tracking_eval.h).
  std::optional<double> time_to_collision_s;
};

// One reported track in one frame.
struct MotTrack {
  std::uint64_t id = 0;
  cv::Rect box;
  bool measured = false;        // a detection updated it this frame (else it coasts)
  int hits = 0;                 // frames with a detection so far
  double range_m = 0;           // raw: the last detection's range
  double smoothed_range_m = 0;  // the tracker's smoothed range
  std::optional<double> time_to_collision_s;
};

// What one frame scored.
struct MotFrame {
  std::vector<std::pair<int, std::uint64_t>> matches;    // (truth id, track id)
  std::vector<int> misses;                               // expected truth ids without a track
  std::vector<std::uint64_t> false_positives;            // track ids
  std::vector<std::pair<std::uint64_t, int>> dont_care;  // (track id, hidden truth id)
  std::vector<int> id_switches;                          // truth ids whose track id changed
  std::vector<int> fragmentations;                       // truth ids tracked again after a gap
};

struct MotSummary {
  int frames = 0;
  int ground_truth = 0;     // expected truths over all frames (GT)
  int matches = 0;          // TP
  int misses = 0;           // FN
  int false_positives = 0;  // FP
  int id_switches = 0;      // IDSW
  int fragmentations = 0;
  int dont_care = 0;                   // unmatched tracks on an obstacle that is not expected
  double iou_sum = 0;                  // over the matches
  std::set<std::uint64_t> track_ids;   // every reported track id
  std::map<int, int> expected_frames;  // truth id -> frames expected
  std::map<int, int> matched_frames;   // truth id -> frames matched
  // Over the matches whose track was measured this frame (a coasting track's raw range is stale):
  // track minus truth, metres.
  std::vector<double> range_errors_m;
  std::vector<double> smoothed_range_errors_m;
  // Over the matches where both the truth and the track have a time to collision and the track has
  // at least MotOptions::min_ttc_hits hits: track minus truth, seconds.
  std::vector<double> ttc_errors_s;

  // 1 - (FN + FP + IDSW) / GT (1 when there is no ground truth).
  double Mota() const;
  // Mean IoU of the matches (0 when there is none).
  double MeanIoU() const;
};

// Root mean square (0 for an empty vector).
double Rms(const std::vector<double>& values);

struct MotOptions {
  // A track and a truth (or a hidden obstacle, for don't-care) match at this IoU or more.
  double min_iou = 0.3;
  // The time to collision is scored once a track has this many hits: its velocity needs several
  // measurements to settle (a new track starts at rest).
  int min_ttc_hits = 10;
};

// Accumulates CLEAR-MOT over a sequence, frame by frame. Thread-compatible.
class MotAccumulator {
 public:
  explicit MotAccumulator(MotOptions options = {});

  // Scores one frame: `truths` lists every obstacle (expected or not), `tracks` every reported
  // track. Ids must be unique within a frame.
  MotFrame AddFrame(const std::vector<MotTruth>& truths, const std::vector<MotTrack>& tracks);

  const MotSummary& summary() const { return summary_; }

 private:
  enum class Coverage { kNever, kTracked, kLost };

  MotOptions options_;
  MotSummary summary_;
  std::map<int, std::uint64_t> previous_;    // last frame's matches, truth id -> track id
  std::map<int, std::uint64_t> last_track_;  // truth id -> the track id it was last matched to
  std::map<int, Coverage> coverage_;         // truth id -> for fragmentations
};

}  // namespace stevi::testing
