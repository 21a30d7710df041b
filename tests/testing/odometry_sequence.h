// A real street sequence with true ego-motion (the KITTI odometry excerpt in the shared data,
// kitti_odom_seq_b: 41 rectified grey pairs, 1241x376, 10 Hz, the left camera's poses), our own
// car labels for it (tests/testing/kitti_odom_seq_b_cars.txt), an independent reference road
// plane per frame (OpenCV SGBM 3-way and the RANSAC plane of gt_obstacles.h), and the scores of
// confirmed tracks against them: static-world consistency, obstacles on the road, labelled cars
// confirmed. Independent of the pipeline's types (tracks come in as OdoTrackFrame), so a ctest test
// can hold bounds. The pipeline run with the poses is in odometry_pipeline.h. See
// tests/bench/README.md ("The KITTI odometry sequence").
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "tests/testing/gt_obstacles.h"

namespace stevi::testing {

constexpr const char* kKittiOdomSeqB = "kitti-odom-seq-b";  // --scenario name
constexpr const char* kKittiOdomSeqBFolder = "kitti_odom_seq_b";

// world_from_cam of one frame: p_world = R p_cam + t (world = the first camera's frame, x right,
// y down, z forward, metres).
struct CamPose {
  cv::Matx33d R = cv::Matx33d::eye();
  cv::Vec3d t;
  cv::Vec3d ToWorld(const cv::Vec3d& p_cam) const { return R * p_cam + t; }
};

struct OdometrySequence {
  std::string name;    // kKittiOdomSeqB
  std::string folder;  // absolute
  double f_px = 718.856, cx = 607.1928, cy = 185.2157, baseline_m = 0.537166;
  double fps = 10.0;
  std::vector<cv::Mat1b> left, right;  // rectified grey
  std::vector<CamPose> poses;          // one per frame
  int frames() const { return static_cast<int>(left.size()); }
};

// Loads the sequence (images, poses.txt; the rig from README.txt's figures) from
// data_dir/kitti_odom_seq_b. nullopt with `problem` when a file is missing or malformed.
std::optional<OdometrySequence> LoadOdometrySequence(const std::string& data_dir,
                                                     std::string& problem);

// One labelled box: car `car` in frame `frame`, camera pixels.
struct LabelledBox {
  int car = 0;
  int frame = 0;
  cv::Rect box;
};

// Reads a label file: '#' comments, then lines "car frame x y width height". Empty with
// `problem` when the file is missing or a line is malformed.
std::vector<LabelledBox> LoadCarLabels(const std::string& path, std::string& problem);

// The label file in the source tree (STEVI_SOURCE_DIR/tests/testing/kitti_odom_seq_b_cars.txt).
std::string CarLabelPath();

// The reference road of one frame: OpenCV StereoSGBM (3-way, 128 disparities, block 5, the left
// image padded by the disparity range so the left columns match) and the RANSAC disparity plane of
// ExtractGtObstacles on that map (its ground step only). nullopt when no plane is found.
struct ReferenceGround {
  GroundPlane plane;
  cv::Mat1f disparity_px;  // SGBM, 0 = unmatched
};
std::optional<ReferenceGround> FitReferenceGround(const cv::Mat1b& left, const cv::Mat1b& right,
                                                  double f_px, double baseline_m, double cx,
                                                  double cy);

// Height (metres) of a camera point above the plane (positive above the road, towards the
// camera's side of it).
double HeightAbovePlane(const GroundPlane& plane, double f_px, double baseline_m, double cx,
                        double cy, const cv::Vec3d& p_cam);

// One confirmed track in one frame (tracks in state confirmed only).
struct OdoTrackFrame {
  int frame = 0;
  uint64_t id = 0;
  cv::Rect box;  // camera pixels
  cv::Vec3d position_cam_m;
  cv::Vec3d position_sigma_m;  // per axis, 1-sigma
};

// Static-world consistency: each confirmed track-frame's world point (the frame's pose times
// position_cam_m) against the track's own median world point (per axis), consistent when within
// max(range_fraction * range, sigmas * |position_sigma_m|, floor_m). Tracks with fewer than
// min_frames confirmed frames are left out (one frame is trivially consistent with itself).
struct StaticWorldOptions {
  double range_fraction = 0.05;
  double sigmas = 3.0;
  double floor_m = 0.0;
  int min_frames = 2;
};
struct StaticWorldScore {
  int tracks = 0, track_frames = 0, consistent = 0;
  std::vector<double> deviation_m;  // per scored track-frame
  double Pct() const { return track_frames ? 100.0 * consistent / track_frames : 0.0; }
};
// `exclude` (optional, per frame): boxes whose track-frames are left out (e.g. the labelled
// moving cars: the world is static apart from them); a track-frame is left out when its box
// overlaps one at IoU >= 0.3 or covers >= 50 % of it.
StaticWorldScore ScoreStaticWorld(const std::vector<OdoTrackFrame>& tracks,
                                  const std::vector<CamPose>& poses,
                                  const StaticWorldOptions& options,
                                  const std::vector<LabelledBox>& exclude = {});

// Confirmed track-frames on the road: the 3-D point of the box's top row (centre column) at the
// track's depth stands less than max_height_m above the frame's reference plane (on_ground). Frames
// without a plane are not scored. Two more views of the same question, because a box over the
// road surface that takes its depth from the near road has its top row, at that depth, well above
// the road: below_road = the box's bottom row at its depth lies more than 0.5 m under the road
// (the box reaches over nearer road); road_box = at least half of the box's pixels that have a
// reference disparity lie on the reference plane (within max(1 px, 5 %)), when the reference
// disparities are given (one per frame, camera pixels, 0 = none).
struct GroundScore {
  int track_frames = 0, scored = 0, on_ground = 0, below_road = 0, road_box = 0;
  double Pct() const { return scored ? 100.0 * on_ground / scored : 0.0; }
  double BelowRoadPct() const { return scored ? 100.0 * below_road / scored : 0.0; }
  double RoadBoxPct() const { return scored ? 100.0 * road_box / scored : 0.0; }
};
GroundScore ScoreOnGround(const std::vector<OdoTrackFrame>& tracks,
                          const std::vector<std::optional<GroundPlane>>& planes, double f_px,
                          double baseline_m, double cx, double cy, double max_height_m = 0.3,
                          const std::vector<cv::Mat1f>* reference_disparity = nullptr);

// Labelled cars: a car is confirmed in a labelled frame when a confirmed track's box overlaps its
// box at IoU >= 0.3 or covers >= 50 % of it. The first `skip_frames` labelled frames of each car
// (a confirmation needs hits) are not scored.
struct CarScore {
  int car = 0;
  int labelled_frames = 0, scored_frames = 0, confirmed_frames = 0;
  // Confirmed by the IoU rule alone (IoU >= 0.3): a box much larger than the car that covers it
  // (a whole street front) passes the "covers >= 50 %" rule, not this one.
  int confirmed_iou_frames = 0;
  int first_frame = 0, last_frame = 0;
  std::vector<int> missed;  // scored frames without a confirmation
  double Pct() const { return scored_frames ? 100.0 * confirmed_frames / scored_frames : 0.0; }
  double IoUPct() const {
    return scored_frames ? 100.0 * confirmed_iou_frames / scored_frames : 0.0;
  }
};
std::vector<CarScore> ScoreCars(const std::vector<OdoTrackFrame>& tracks,
                                const std::vector<LabelledBox>& labels, int skip_frames = 2);

// Whether `box` hits `label`: IoU >= 0.3 or covers >= 50 % of the label.
bool HitsLabel(const cv::Rect& box, const cv::Rect& label);

}  // namespace stevi::testing
