#include "tests/testing/track_level.h"

#include <algorithm>
#include <cmath>
#include <map>

#include "tests/testing/truth_match.h"

namespace stevi::testing {

void TrackLevelTotals::Add(const TrackLevelTotals& o) {
  sequences += o.sequences;
  frames += o.frames;
  obstacles += o.obstacles;
  scored += o.scored;
  confirmed_in_window += o.confirmed_in_window;
  censored += o.censored;
  confirmed_ever += o.confirmed_ever;
  frames_to_confirm.insert(frames_to_confirm.end(), o.frames_to_confirm.begin(),
                           o.frames_to_confirm.end());
  confirmed_tracks += o.confirmed_tracks;
  false_tracks += o.false_tracks;
  normalised_error.insert(normalised_error.end(), o.normalised_error.begin(),
                          o.normalised_error.end());
}

double TrackLevelTotals::MedianFramesToConfirm() const {
  if (frames_to_confirm.empty()) return -1;
  std::vector<int> v = frames_to_confirm;
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

double TrackLevelTotals::ErrorOverSigmaRms() const {
  double s = 0;
  for (double x : normalised_error) s += x * x;
  return normalised_error.empty() ? 0.0
                                  : std::sqrt(s / static_cast<double>(normalised_error.size()));
}

TrackLevelTotals ScoreTrackLevel(const std::vector<TlFrame>& frames,
                                 const TrackLevelOptions& options) {
  TrackLevelTotals t;
  t.sequences = 1;
  t.frames = static_cast<int>(frames.size());
  const int n = static_cast<int>(frames.size());
  std::map<int, int> first_measurable;     // obstacle id -> k0
  std::map<int, int> first_confirmed;      // obstacle id -> first k >= k0 confirmed
  std::map<uint64_t, bool> track_matched;  // confirmed tracks -> matched an obstacle (or dc)
  for (int k = 0; k < n; ++k) {
    const TlFrame& f = frames[static_cast<size_t>(k)];
    for (const TlTruth& o : f.truths) {
      if (o.expected && !first_measurable.count(o.id)) first_measurable[o.id] = k;
    }
    for (const TlTrack& track : f.tracks) {
      if (!track.confirmed) continue;
      bool& matched = track_matched[track.id];
      for (const TlTruth& o : f.truths) {
        if (!o.visible && !o.expected) continue;
        const double iou = IoU(track.box, o.box);
        const bool match = o.expected && iou >= options.min_iou;
        const bool dont_care =
            !o.expected &&
            (iou >= options.min_iou || InsideFraction(track.box, o.box) >= options.inside_fraction);
        if (match || dont_care) matched = true;
        if (!match) continue;
        if (first_measurable.count(o.id) && !first_confirmed.count(o.id)) {
          first_confirmed[o.id] = k;
        }
        if (track.depth_sigma_m > 0 && o.depth_m > 0) {
          t.normalised_error.push_back((track.depth_m - o.depth_m) / track.depth_sigma_m);
        }
      }
    }
  }
  for (const auto& [id, k0] : first_measurable) {
    ++t.obstacles;
    const auto it = first_confirmed.find(id);
    const bool in_window = it != first_confirmed.end() && it->second - k0 < options.window_frames;
    if (it != first_confirmed.end()) {
      ++t.confirmed_ever;
      t.frames_to_confirm.push_back(it->second - k0);
    }
    if (in_window || k0 + options.window_frames <= n) {
      ++t.scored;
      t.confirmed_in_window += in_window;
    } else {
      ++t.censored;
    }
  }
  for (const auto& [id, matched] : track_matched) {
    ++t.confirmed_tracks;
    t.false_tracks += !matched;
  }
  return t;
}

}  // namespace stevi::testing
