// Obstacles delimited from a ground-truth disparity map alone (no hand labels), and the scoring of
// a detector's boxes against them. For KITTI 2015 (road scenes, a level camera about 1.65 m up).
//
// 1. Ground: a plane d = a u + b v + c fitted to the truth disparity by RANSAC, then least squares
//    over its inliers. Every 3-D plane is such a linear function of (u, v) in disparity space, with
//    normal n ~ (a, b, d(cx, cy) / f) and camera height B / |n|; a sample is only accepted when its
//    normal lies within max_ground_tilt_deg of the camera's down axis, so walls and facades (the
//    other large planes of a street) can not win.
// 2. The truth is made denser along columns: LiDAR truth comes in scan lines (KITTI's HDL-64E:
//    about 0.4 deg apart, 5 rows at f = 721 px), so a thin pole has a few known pixels every 4-6
//    rows. An unknown run of at most fill_gap_px rows between two known pixels of one column whose
//    disparities agree (the join tolerance below) is filled by linear interpolation; across
//    occlusion edges they disagree and nothing is filled. Without this a pole at 7 m is a stack of
//    1-row fragments, and pixel counts would measure the scanner, not the object.
// 3. Each known pixel's 3-D point gets its height above that plane. Obstacle pixels stand at least
//    min_height_m above it (above kerbs and sidewalk edges).
// 4. Obstacle pixels join into one obstacle when they lie within join_radius_px of each other (the
//    scan lines' remaining gaps) and their disparities differ by at most
//    join_px + join_fraction * the larger one: surfaces that continue in depth join, occlusion
//    edges separate.
// 5. Components with at least min_pixels known pixels, a box at least min_box_height_px tall and a
//    median depth of at most max_depth_m are the obstacles.
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

#include <opencv2/core.hpp>

namespace stevi::testing {

struct GtObstacleOptions {
  // Ground plane fit.
  int ransac_iterations = 400;
  uint64_t seed = 1;
  double ground_inlier_px = 0.5;  // + ground_inlier_fraction * the plane's disparity
  double ground_inlier_fraction = 0.03;
  double max_ground_tilt_deg = 15.0;
  // Filling between scan lines (rows).
  int fill_gap_px = 10;
  // Obstacle pixels.
  double min_height_m = 0.5;
  // Components.
  int join_radius_px = 2;
  double join_px = 0.5;
  double join_fraction = 0.05;
  int min_pixels = 400;
  int min_box_height_px = 15;
  double max_depth_m = 40.0;
};

// d(u, v) = a u + b v + c, camera pixels.
struct GroundPlane {
  double a = 0, b = 0, c = 0;
  int inliers = 0;       // known pixels within the inlier band of the final plane
  double height_m = 0;   // the camera's height above it
  double pitch_deg = 0;  // the plane's normal against the camera's down axis, about x (+: the
  double roll_deg = 0;   // camera looks down) and about z
  double DisparityAt(double u, double v) const { return a * u + b * v + c; }
};

enum GtPixelClass : uint8_t {
  kGtUnknown = 0,
  kGtGround = 1,  // within min_height_m of the plane (either side)
  kGtAbove = 2,   // an obstacle pixel: min_height_m or more above it
};

struct GtObstacle {
  int id = 0;  // the value in GtScene::labels
  cv::Rect bbox;
  int pixels = 0;  // pixels with truth (after the filling between scan lines)
  double median_disparity_px = 0;
  double median_depth_m = 0;  // f B / median disparity
  double depth_p10_m = 0, depth_p90_m = 0;
  double height_top_m = 0;  // the highest pixel's height above the ground
};

struct GtScene {
  std::optional<GroundPlane> ground;
  cv::Mat1f dense_px;  // the truth filled between scan lines (step 2), 0 = unknown
  cv::Mat1b classes;   // GtPixelClass per pixel
  cv::Mat1i labels;    // obstacle id (GtObstacle::id) of kept obstacles' pixels, else 0
  std::vector<GtObstacle> obstacles;
  int components = 0;  // before the filters
};

// `truth_px`: disparity, 0 = unknown. The rig: rectified focal length, baseline, principal point.
GtScene ExtractGtObstacles(const cv::Mat1f& truth_px, double f_px, double baseline_m, double cx,
                           double cy, const GtObstacleOptions& options = {});

// A detection in camera pixels (boxes of binned frames multiplied by the binning).
struct ScoredBox {
  cv::Rect bbox;
  double depth_m = 0;
};

enum class BoxVerdict {
  kMatched,       // IoU >= 0.3 with a truth obstacle, one-to-one, best first
  kFragment,      // not matched, >= 50 % of it inside a truth obstacle's box
  kFpStructure,   // false positive on above-ground truth (not a kept obstacle) at its depth
  kFpWrongDepth,  // false positive on above-ground truth, but not at its depth (+-15 %)
  kFpFree,        // false positive on an obstacle-free region: its known truth is ground
  kFpNoTruth,     // false positive where under 10 % of the box has truth (sky, top rows)
};

struct ObstacleResult {
  int detection = -1;  // the matched detection, -1 = missed
  double iou = 0;
  double range_error_pct = 0;  // (depth - truth median depth) / truth, when matched
  int fragments = 0;           // unmatched detections >= 50 % inside its box
};

struct DetectionScore {
  std::vector<ObstacleResult> obstacles;  // per truth obstacle
  std::vector<BoxVerdict> boxes;          // per detection
  int found = 0, fragments = 0;
  int fp = 0, fp_structure = 0, fp_wrong_depth = 0, fp_free = 0, fp_no_truth = 0;
};

// The truth under a false positive is read from scene.classes and scene.dense_px.
DetectionScore ScoreDetections(const GtScene& scene, double f_px, double baseline_m,
                               const std::vector<ScoredBox>& boxes);

const char* BoxVerdictName(BoxVerdict verdict);

}  // namespace stevi::testing
