// Shared by the benchmarks (pipeline_bench.cc, stevi_bench.cc):
//
// 1. The naive baseline: the 2013 thesis pipeline done the straightforward way, on one thread
//    (cv::setNumThreads(1)), at full resolution, with stock OpenCV:
//      - rectify:    cv::remap of both images with float (CV_32FC1) maps, bilinear;
//      - disparity:  cv::StereoSGBM in MODE_SGBM (the 5-path single pass, not 3-way), no padding;
//      - saliency:   cv::saliency::StaticSaliencyFineGrained (opencv_contrib, the intensity
//                    centre-surround of Montabone & Soto, a VOCUS relative) on the full image;
//      - segmentation: cv::ximgproc::segmentation::GraphSegmentation (Felzenszwalb-Huttenlocher)
//                    on the full image, with the same sigma, k and min_size as SteViS.
//    Each stage is a function so that the caller times it; SingleThreadScope pins OpenCV to one
//    thread while it lives.
//
// 2. Fixtures: the synthetic rig at a given image size, a raw (distorted, unrectified) rig of the
//    same size for timing a real remap, and a field of moving targets for timing the tracker.
#pragma once

#include <cstdint>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/error.h"
#include "core/detection/detection.h"
#include "core/geometry/stereo_rig.h"
#include "core/tracking/kalman.h"
#include "drivers/synthetic/synthetic_source.h"

namespace stevi::bench {

// ---------------------------------------------------------------------------------------------
// Fixtures
// ---------------------------------------------------------------------------------------------

// The synthetic rig at `size`: 640x480 is the default rig (f = 700 px, B = 0.6 m); another size
// keeps the horizontal field of view, so f scales with the width (1280x1024: f = 1400 px, the
// disparities double and the vertical field of view grows from 480 to 512 rows' worth at f 700).
drivers::SyntheticOptions SyntheticAt(cv::Size size);

// "640x480".
std::string SizeName(cv::Size size);

// A raw rig of the ideal rig's size: the same focal length and principal point with lens
// distortion (k1 = -0.12, k2 = 0.03) and a 0.5 degree rotation between the cameras, so that
// StereoRig::Rectify really remaps. Only for timing: the synthetic images are not distorted.
Result<geometry::StereoRig> RawRigLike(const geometry::StereoRig& ideal);

// `count` obstacles laid out on a grid over the image, at depths 25..60 m, each circling a grid
// point (radius 12 px in the image) at its own rate: detections without clutter, seeded noise on
// the centroid (0.5 px) and the disparity (0.1 px). With count = 100 on 640x480 the grid is
// 10 x 10, 64 x 48 px apart, so several detections fall within each track's distance gate (80 px)
// and the assignment is a real 100 x 100 problem.
class MovingTargets {
 public:
  MovingTargets(int count, const tracking::CameraModel& camera, uint64_t seed = 1);
  // The detections of frame `frame` (time frame * dt_s); draws noise, so not const.
  std::vector<detection::Detection> Detections(int64_t frame, double dt_s);
  const tracking::CameraModel& camera() const { return camera_; }
  int count() const { return static_cast<int>(targets_.size()); }

 private:
  struct Target {
    double u0, v0;  // grid point, pixels
    double z_m;     // depth
    double rate;    // rad/s
    double phase;   // rad
    double width_m, height_m;
  };
  tracking::CameraModel camera_;
  std::vector<Target> targets_;
  std::mt19937_64 rng_;
};

// ---------------------------------------------------------------------------------------------
// Naive baseline
// ---------------------------------------------------------------------------------------------

// Pins OpenCV to one thread while alive, then restores the previous setting.
class SingleThreadScope {
 public:
  SingleThreadScope();
  ~SingleThreadScope();
  SingleThreadScope(const SingleThreadScope&) = delete;
  SingleThreadScope& operator=(const SingleThreadScope&) = delete;

 private:
  int saved_;
};

struct NaiveOptions {
  int num_disparities = 64;
  int sgbm_block_size = 5;  // as the project's SGBM default
  // Graph segmentation: SteViS's defaults (GraphSegmentationOptions).
  double graph_sigma = 0.5;
  double graph_k = 300.0;
  int graph_min_size = 50;
};

// The thesis stages. Build once (the remap tables and OpenCV objects), call per frame. Not
// thread-safe. The stages do not pin the thread count themselves: wrap the calls in a
// SingleThreadScope for the baseline.
class NaiveThesisPipeline {
 public:
  // `raw_rig` supplies the remap (its calibration's M, D, R1, P1...); a rig without remap gets
  // identity float maps (cv::remap still runs: the cost is the same).
  NaiveThesisPipeline(const geometry::StereoRig& raw_rig, NaiveOptions options = {});
  ~NaiveThesisPipeline();
  NaiveThesisPipeline(const NaiveThesisPipeline&) = delete;
  NaiveThesisPipeline& operator=(const NaiveThesisPipeline&) = delete;

  // cv::remap of both images, bilinear, float maps.
  void Rectify(const cv::Mat& left, const cv::Mat& right, cv::Mat& rect_left, cv::Mat& rect_right);
  // cv::StereoSGBM, MODE_SGBM, fixed-point CV_16S disparity.
  cv::Mat Disparity(const cv::Mat& left, const cv::Mat& right);
  // StaticSaliencyFineGrained on the full image (CV_8U map); empty without the saliency module.
  cv::Mat Saliency(const cv::Mat& left);
  // GraphSegmentation on the full image (CV_32S labels).
  cv::Mat Segment(const cv::Mat& left);

  const NaiveOptions& options() const { return options_; }

 private:
  struct Impl;
  NaiveOptions options_;
  std::unique_ptr<Impl> impl_;
};

// Percentile (0..100) of `values` by nearest rank; 0 for none. Copies (does not reorder).
double Percentile(std::vector<double> values, double pct);
double Mean(const std::vector<double>& values);

}  // namespace stevi::bench
