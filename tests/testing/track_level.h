// Track-level scoring in the autopilot's terms, independent of the detector and the tracker's
// types: is each obstacle CONFIRMED soon after it becomes measurable, how many confirmed tracks
// are false, and is the range of the confirmed tracks as good as their published sigma says.
// Used by stevi-eval --family (tests/bench/eval_family.cc); see tests/bench/README.md.
//
// Definitions (one sequence of frames, e.g. one synthetic scene):
// - An obstacle is measurable in a frame when it is expected there (the caller decides: in
//   stevi-eval, visible >= 100 px and truth disparity >= 3 disparity sigmas). It becomes
//   measurable at the first such frame k0.
// - It is confirmed in frame k when a track in state confirmed (measured this frame: not
//   tentative, not coasting) has a box matching its truth box at IoU >= min_iou in that frame.
// - Confirmed within the window: confirmed in one of frames k0 .. k0 + window_frames - 1.
//   frames-to-confirm = k - k0 of the first such frame (0 = confirmed in its first measurable
//   frame). An obstacle whose sequence ends before its window does and that is not confirmed by
//   then is censored: counted apart, in neither the numerator nor the denominator.
// - A false confirmed track is a track that was confirmed in at least one frame and in none of its
//   confirmed frames matches an expected obstacle (IoU >= min_iou) or a don't-care one (a visible,
//   not expected obstacle: IoU >= min_iou or >= inside_fraction of the track's box inside its
//   box). Each such track counts once; the rate is per 1000 frames.
// - Range error over sigma: for each confirmed track-frame matching an expected obstacle,
//   (depth - truth depth) / depth sigma, its rms (~1 for an honest sigma).
#pragma once

#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

namespace stevi::testing {

struct TlTruth {
  int id = 0;
  cv::Rect box;           // visible box in camera pixels
  bool expected = false;  // measurable in this frame
  bool visible = false;   // any visible pixel (a not-expected visible obstacle is don't care)
  double depth_m = 0;     // truth depth (e.g. f B / median truth disparity)
};

struct TlTrack {
  uint64_t id = 0;
  bool confirmed = false;  // TrackState::kConfirmed this frame
  cv::Rect box;            // camera pixels (processed box times the binning)
  double depth_m = 0;      // the track's depth (Kalman position z)
  double depth_sigma_m = 0;
};

struct TlFrame {
  std::vector<TlTruth> truths;
  std::vector<TlTrack> tracks;  // every live track
};

struct TrackLevelOptions {
  double min_iou = 0.3;
  double inside_fraction = 0.5;
  int window_frames = 5;
};

// Totals over one or more sequences (Add() sums them).
struct TrackLevelTotals {
  int sequences = 0, frames = 0;
  int obstacles = 0;            // obstacles that became measurable
  int scored = 0;               // ... whose window fits in the sequence, or confirmed in time
  int confirmed_in_window = 0;  // of `scored`
  int censored = 0;             // obstacles - scored
  int confirmed_ever = 0;       // confirmed at any frame after becoming measurable
  std::vector<int> frames_to_confirm;  // per obstacle confirmed at any frame: k - k0
  int confirmed_tracks = 0;            // tracks confirmed in at least one frame
  int false_tracks = 0;
  std::vector<double> normalised_error;  // (depth - truth) / sigma per matched track-frame

  void Add(const TrackLevelTotals& other);
  double ConfirmedPct() const { return scored ? 100.0 * confirmed_in_window / scored : 0.0; }
  double FalsePer1000Frames() const { return frames ? 1000.0 * false_tracks / frames : 0.0; }
  // The median of frames_to_confirm (-1 when empty).
  double MedianFramesToConfirm() const;
  double ErrorOverSigmaRms() const;
};

// Scores one sequence.
TrackLevelTotals ScoreTrackLevel(const std::vector<TlFrame>& frames,
                                 const TrackLevelOptions& options = {});

}  // namespace stevi::testing
