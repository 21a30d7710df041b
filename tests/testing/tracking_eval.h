// The tracking evaluation on the synthetic scenarios (shared by stevi-eval-tracking and
// tracking_scenarios_test): render a scenario, run the full pipeline over every frame, and score
// the reported tracks against the truth with CLEAR-MOT (mot_metrics.h).
//
// Ground truth per frame (the rule of stevi-eval): an obstacle is expected when at least 100 of
// its pixels are visible and its truth disparity f B / depth is at least 8 px. Reported tracks are
// the confirmed and coasting ones (not tentative). An obstacle's full box, for the don't-care
// rule, is the bounding box of its 8 corners projected with the rig's f, cx, cy (not clipped).
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/error.h"
#include "core/common/stereo_frame.h"
#include "core/detection/detection.h"
#include "core/geometry/stereo_rig.h"
#include "core/pipeline/config.h"
#include "core/tracking/tracker.h"
#include "drivers/synthetic/synthetic_source.h"
#include "tests/testing/mot_metrics.h"

namespace stevi::testing {

constexpr int kMinVisiblePx = 100;
constexpr double kMinDisparityPx = 8.0;
constexpr double kMinIoU = 0.3;
// The time to collision is scored once a track has this many hits (MotOptions::min_ttc_hits).
constexpr int kMinTtcHits = 10;
// An obstacle is on a collision course, and gets a truth time to collision, when its straight-line
// miss distance (closest approach to the camera) is at most this (metres) and still ahead.
constexpr double kCollisionCourseM = 10.0;

// A scenario rendered once, to be tracked by several algorithms.
struct RenderedScenario {
  drivers::Scenario scenario;
  std::shared_ptr<const geometry::StereoRig> rig;  // the renderer's
  std::vector<StereoFrame> frames;
  std::vector<drivers::FrameTruth> truths;  // obstacles only: the truth images are dropped
};

// Renders the first `max_frames` frames (all of them when 0 or more than the scenario has).
RenderedScenario RenderScenario(const drivers::Scenario& scenario, int max_frames = 0);

// The bounding box of the obstacle's 8 corners at time t_s, projected into the left image of the
// rig (f, cx, cy), not clipped to the image: the pixels whose centres its silhouette covers. Empty
// when a corner is not in front of the camera.
cv::Rect ProjectedBox(const drivers::Obstacle& obstacle, double t_s,
                      const geometry::StereoRig& rig);

// The velocity (m/s) of the path at time t_s.
cv::Vec3d PathVelocity(const drivers::Path& path, double t_s);

// The truth time of the closest approach of the obstacle's front-face centre (the truth's
// position_cam_m), extrapolated in a straight line from its position and velocity at t_s: set only
// when it is ahead (t* > 0) and the miss distance is at most kCollisionCourseM.
std::optional<double> TruthTimeToCollision(const drivers::Obstacle& obstacle, double t_s);

// Every obstacle of the frame for scoring: expected or not, visible box, full box, range, TTC.
// `options` holds the scene the truth was rendered from, `rig` the renderer's rig.
std::vector<MotTruth> ScoringTruth(const drivers::FrameTruth& truth,
                                   const drivers::SyntheticOptions& options,
                                   const geometry::StereoRig& rig);

// The reported tracks (confirmed and coasting) for scoring.
std::vector<MotTrack> ScoringTracks(const std::vector<tracking::Track>& tracks);

// One frame of a run.
struct TrackedFrame {
  std::vector<detection::Detection> detections;
  std::vector<tracking::Track> tracks;  // every live track, tentative ones included
  std::vector<MotTruth> truths;
  MotFrame scored;
};

struct TrackingRun {
  std::string algorithm;
  std::vector<TrackedFrame> frames;
  MotSummary summary;
};

// Runs a fresh pipeline with `config` over every rendered frame, in order, and scores its tracks.
// Fails with the pipeline's error, naming the frame.
Result<TrackingRun> RunTracking(const RenderedScenario& rendered,
                                const pipeline::PipelineConfig& config);

}  // namespace stevi::testing
