#include "tests/testing/mot_metrics.h"

#include <cmath>

#include "tests/testing/truth_match.h"

namespace stevi::testing {

double MotSummary::Mota() const {
  if (ground_truth == 0) return 1.0;
  return 1.0 - static_cast<double>(misses + false_positives + id_switches) / ground_truth;
}

double MotSummary::MeanIoU() const { return matches > 0 ? iou_sum / matches : 0.0; }

double Rms(const std::vector<double>& values) {
  double sum = 0;
  for (double v : values) sum += v * v;
  return values.empty() ? 0.0 : std::sqrt(sum / static_cast<double>(values.size()));
}

MotAccumulator::MotAccumulator(MotOptions options) : options_(options) {}

MotFrame MotAccumulator::AddFrame(const std::vector<MotTruth>& truths,
                                  const std::vector<MotTrack>& tracks) {
  MotFrame frame;
  ++summary_.frames;
  for (const MotTrack& track : tracks) summary_.track_ids.insert(track.id);

  std::vector<int> expected;  // indices into truths
  for (int i = 0; i < static_cast<int>(truths.size()); ++i) {
    if (!truths[i].expected) continue;
    expected.push_back(i);
    ++summary_.expected_frames[truths[i].id];
  }
  summary_.ground_truth += static_cast<int>(expected.size());

  std::vector<char> truth_done(truths.size(), 0), track_done(tracks.size(), 0);
  std::vector<std::pair<int, int>> pairs;  // (truth index, track index)

  // 1. Last frame's correspondences that still overlap.
  for (int t : expected) {
    const auto it = previous_.find(truths[t].id);
    if (it == previous_.end()) continue;
    for (int k = 0; k < static_cast<int>(tracks.size()); ++k) {
      if (track_done[k] || tracks[k].id != it->second) continue;
      if (IoU(truths[t].box, tracks[k].box) >= options_.min_iou) {
        truth_done[t] = track_done[k] = 1;
        pairs.emplace_back(t, k);
      }
      break;
    }
  }

  // 2. The rest, one-to-one by IoU, best first.
  std::vector<int> open_truths, open_tracks;
  std::vector<cv::Rect> truth_boxes, track_boxes;
  for (int t : expected) {
    if (truth_done[t]) continue;
    open_truths.push_back(t);
    truth_boxes.push_back(truths[t].box);
  }
  for (int k = 0; k < static_cast<int>(tracks.size()); ++k) {
    if (track_done[k]) continue;
    open_tracks.push_back(k);
    track_boxes.push_back(tracks[k].box);
  }
  for (const auto& [k, t] : MatchByIoU(track_boxes, truth_boxes, options_.min_iou)) {
    truth_done[open_truths[t]] = track_done[open_tracks[k]] = 1;
    pairs.emplace_back(open_truths[t], open_tracks[k]);
  }

  // 3. Matches, ID switches, fragmentations, errors.
  previous_.clear();
  for (const auto& [t, k] : pairs) {
    const MotTruth& truth = truths[t];
    const MotTrack& track = tracks[k];
    frame.matches.emplace_back(truth.id, track.id);
    ++summary_.matches;
    ++summary_.matched_frames[truth.id];
    summary_.iou_sum += IoU(truth.box, track.box);
    previous_[truth.id] = track.id;
    const auto last = last_track_.find(truth.id);
    if (last != last_track_.end() && last->second != track.id) {
      frame.id_switches.push_back(truth.id);
      ++summary_.id_switches;
    }
    last_track_[truth.id] = track.id;
    Coverage& coverage = coverage_[truth.id];
    if (coverage == Coverage::kLost) {
      frame.fragmentations.push_back(truth.id);
      ++summary_.fragmentations;
    }
    coverage = Coverage::kTracked;
    if (track.measured) {
      summary_.range_errors_m.push_back(track.range_m - truth.range_m);
      summary_.smoothed_range_errors_m.push_back(track.smoothed_range_m - truth.range_m);
    }
    if (truth.time_to_collision_s && track.time_to_collision_s &&
        track.hits >= options_.min_ttc_hits) {
      summary_.ttc_errors_s.push_back(*track.time_to_collision_s - *truth.time_to_collision_s);
    }
  }

  // 4. Misses.
  for (int t : expected) {
    if (truth_done[t]) continue;
    frame.misses.push_back(truths[t].id);
    ++summary_.misses;
    Coverage& coverage = coverage_[truths[t].id];
    if (coverage == Coverage::kTracked) coverage = Coverage::kLost;
  }

  // 5. Unmatched tracks: don't care on an obstacle that is not expected, else false positives.
  std::vector<int> hidden;
  std::vector<cv::Rect> hidden_boxes;
  for (int i = 0; i < static_cast<int>(truths.size()); ++i) {
    if (truths[i].expected || truths[i].full_box.empty()) continue;
    hidden.push_back(i);
    hidden_boxes.push_back(truths[i].full_box);
  }
  open_tracks.clear();
  track_boxes.clear();
  for (int k = 0; k < static_cast<int>(tracks.size()); ++k) {
    if (track_done[k]) continue;
    open_tracks.push_back(k);
    track_boxes.push_back(tracks[k].box);
  }
  for (const auto& [k, h] : MatchByIoU(track_boxes, hidden_boxes, options_.min_iou)) {
    track_done[open_tracks[k]] = 1;
    frame.dont_care.emplace_back(tracks[open_tracks[k]].id, truths[hidden[h]].id);
    ++summary_.dont_care;
  }
  for (int k = 0; k < static_cast<int>(tracks.size()); ++k) {
    if (track_done[k]) continue;
    frame.false_positives.push_back(tracks[k].id);
    ++summary_.false_positives;
  }
  return frame;
}

}  // namespace stevi::testing
