// Compares streamed TrackFrames with the synthetic truth: recall and depth error.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "core/common/error.h"
#include "core/geo/georeferencer.h"
#include "drivers/synthetic/synthetic_source.h"
#include "stevi/v1/obstacle_service.pb.h"
#include "tests/testing/truth_match.h"

namespace stevi::testing {

struct DepthCheck {
  int expected = 0;  // visible obstacles with truth disparity >= min_disparity_px
  int matched = 0;   // of those, matched by a track (IoU >= 0.3)
  int within = 0;    // of those, depth within max_relative_error
  double worst_relative_error = 0;
  std::vector<std::string> failures;
  // Per truth obstacle id: how many times each track id matched it.
  std::map<int, std::map<uint64_t, int>> ids;

  double recall() const { return expected > 0 ? static_cast<double>(matched) / expected : 0; }
  // The share of matches that went to each obstacle's most frequent track id: 1 when every
  // obstacle kept one id over the frames.
  double IdConsistency() const {
    int total = 0, majority = 0;
    for (const auto& [truth_id, counts] : ids) {
      int best = 0;
      for (const auto& [track_id, n] : counts) {
        total += n;
        best = std::max(best, n);
      }
      majority += best;
    }
    return total > 0 ? static_cast<double>(majority) / total : 0;
  }
};

// Where `georeferencer` puts truth obstacle `o` (its centre in the cam frame) seen from `state`:
// the geodetic point a track of it should carry.
inline Result<geo::GeoPoint> TruthGeodetic(const geo::Georeferencer& georeferencer,
                                           const geo::VehicleState& state,
                                           const drivers::ObstacleTruth& o) {
  geo::VehiclePose pose;
  pose.state = state;
  geo::PointInCam point;
  const cv::Vec3d& p = o.position_cam_m;
  point.position_m = Eigen::Vector3d(p[0], p[1], p[2]);
  return georeferencer.Georeference(pose, point);
}

// Obstacles smaller than min_visible_px in the image are not expected. Only tracks detected in this
// frame take part (COASTING ones carry a prediction, not a measurement).
inline void CheckFrame(const v1::TrackFrame& frame, const drivers::FrameTruth& truth, double fB,
                       DepthCheck& check, double min_disparity_px = 8.0,
                       double max_relative_error = 0.02, int min_visible_px = 300) {
  std::vector<cv::Rect> boxes, truth_boxes;
  std::vector<const v1::Track*> tracks;
  std::vector<const drivers::ObstacleTruth*> expected;
  for (const v1::Track& t : frame.tracks()) {
    if (t.state() == v1::TRACK_STATE_COASTING) continue;
    boxes.emplace_back(t.bbox().x(), t.bbox().y(), t.bbox().width(), t.bbox().height());
    tracks.push_back(&t);
  }
  for (const drivers::ObstacleTruth& o : truth.obstacles) {
    if (o.visible_px < min_visible_px || fB / o.depth_m < min_disparity_px) continue;
    expected.push_back(&o);
    truth_boxes.push_back(o.bbox);
  }
  check.expected += static_cast<int>(expected.size());
  for (const auto& [d, t] : MatchByIoU(boxes, truth_boxes, 0.3)) {
    ++check.matched;
    ++check.ids[expected[t]->id][tracks[d]->track_id()];
    // The obstacle's depth: of the median disparity of its visible pixels (a box seen from below
    // shows its underside beyond its front face).
    const double truth_depth = expected[t]->median_disparity_px > 0
                                   ? fB / expected[t]->median_disparity_px
                                   : expected[t]->depth_m;
    const double error = std::abs(tracks[d]->depth_m() - truth_depth) / truth_depth;
    check.worst_relative_error = std::max(check.worst_relative_error, error);
    if (error <= max_relative_error) {
      ++check.within;
    } else {
      std::ostringstream out;
      out << "frame " << frame.source_index() << " " << expected[t]->name << ": depth "
          << tracks[d]->depth_m() << " m, truth " << truth_depth << " m";
      check.failures.push_back(out.str());
    }
  }
}

}  // namespace stevi::testing
