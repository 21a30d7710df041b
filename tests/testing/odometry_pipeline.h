// The pipeline over the KITTI odometry sequence (odometry_sequence.h), frame by frame with its
// tracker, with or without the true poses fed through pipeline::Snapshot::pose_at. Compiled into
// its users (it links the pipeline and GeographicLib; the stevi_testing library does not).
#pragma once

#include <optional>
#include <vector>

#include "core/common/error.h"
#include "core/geo/pose_buffer.h"
#include "core/geo/vehicle_state.h"
#include "core/pipeline/config.h"
#include "tests/testing/odometry_sequence.h"

namespace stevi::testing {

// The arbitrary fixed origin of the sequence's world (the first camera) on WGS84.
constexpr double kOdometryOriginLatDeg = 49.0, kOdometryOriginLonDeg = 8.4,
                 kOdometryOriginAltM = 0.0;

// The vehicle state of frame k of the sequence: NED axes with north = the first camera's z,
// east = its x, down = its y; the body (forward-right-down) is the camera through the default
// mount (camera z -> body x, x -> y, y -> z; no lever arm), so ned_from_body = M R M^T and the
// NED position M t, with M the axis permutation; WGS84 through GeographicLib::LocalCartesian from
// the origin above; the velocity by central differences of the positions at the sequence's rate.
// t_ns = k / fps.
geo::VehicleState VehicleStateOfFrame(const OdometrySequence& sequence, int k);

struct OdometryRunOptions {
  pipeline::Algorithm algorithm = pipeline::Algorithm::kCanonical;
  std::optional<int> max_width_px;    // unset: the default
  bool with_poses = false;            // Snapshot::pose_at from the true poses
  std::vector<std::string> settings;  // pipeline::ApplySettings over the algorithm's own config
};

// One frame of a run.
struct OdometryFrame {
  int detections = 0;
  int live_tracks = 0;
  int binning = 1;
  bool pose_ok = false;   // the pipeline reported a pose for the frame
  int georeferenced = 0;  // tracks with a WGS84 position
  // With poses: the largest distance (m), over the frame's georeferenced tracks, between the
  // pipeline's WGS84 point (back to the local NED frame of the sequence's origin) and the track's
  // camera point carried by the true pose: a check of the pose conversion and the georeferencing.
  double geo_mismatch_m = 0;
  double total_ms = 0;
  std::vector<cv::Rect> detection_boxes;  // camera pixels
  std::vector<OdoTrackFrame> confirmed;   // tracks in state confirmed, camera-pixel boxes
};

// A fresh pipeline (default configuration but the algorithm and max width) on an ideal rig of
// the sequence, over every frame in order (t_ns = k / fps). Fails with the pipeline's error.
Result<std::vector<OdometryFrame>> RunOdometrySequence(const OdometrySequence& sequence,
                                                       const OdometryRunOptions& options);

}  // namespace stevi::testing
