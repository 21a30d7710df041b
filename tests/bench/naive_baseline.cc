#include "tests/bench/naive_baseline.h"
#include "tests/testing/measured_detection.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <utility>

#include <opencv2/calib3d.hpp>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/ximgproc/segmentation.hpp>
#include <opencv2/saliency.hpp>

namespace stevi::bench {

// ---------------------------------------------------------------------------------------------
// Fixtures
// ---------------------------------------------------------------------------------------------

drivers::SyntheticOptions SyntheticAt(cv::Size size) {
  drivers::SyntheticOptions options;
  const double scale = static_cast<double>(size.width) / options.width;
  options.f_px *= scale;
  options.width = size.width;
  options.height = size.height;
  return options;
}

std::string SizeName(cv::Size size) {
  return std::to_string(size.width).append("x").append(std::to_string(size.height));
}

Result<geometry::StereoRig> RawRigLike(const geometry::StereoRig& ideal) {
  geometry::StereoCalibration c;
  c.image_size = ideal.image_size();
  c.M1 = cv::Matx33d(ideal.f_px(), 0, ideal.cx(), 0, ideal.f_px(), ideal.cy(), 0, 0, 1);
  c.M2 = c.M1;
  c.D1 = (cv::Mat_<double>(1, 5) << -0.12, 0.03, 0.0, 0.0, 0.0);
  c.D2 = (cv::Mat_<double>(1, 5) << -0.11, 0.028, 0.0, 0.0, 0.0);
  const double angle = 0.5 * CV_PI / 180.0;  // about y
  c.R = cv::Matx33d(std::cos(angle), 0, std::sin(angle), 0, 1, 0, -std::sin(angle), 0,
                    std::cos(angle));
  c.T = cv::Vec3d(-ideal.baseline_m(), 0.0, 0.0);
  return geometry::StereoRig::FromCalibration(c, "bench-raw");
}

MovingTargets::MovingTargets(int count, const tracking::CameraModel& camera, uint64_t seed)
    : camera_(camera), rng_(seed) {
  const int cols = std::max(1, static_cast<int>(std::ceil(std::sqrt(static_cast<double>(count)))));
  const int rows = std::max(1, (count + cols - 1) / cols);
  const double cell_w = static_cast<double>(camera.width) / cols;
  const double cell_h = static_cast<double>(camera.height) / rows;
  std::uniform_real_distribution<double> depth(25.0, 60.0);
  std::uniform_real_distribution<double> rate(0.5, 1.5);
  std::uniform_real_distribution<double> phase(0.0, 2.0 * CV_PI);
  for (int i = 0; i < count; ++i) {
    Target t;
    t.u0 = (i % cols + 0.5) * cell_w;
    t.v0 = (i / cols + 0.5) * cell_h;
    t.z_m = depth(rng_);
    t.rate = rate(rng_);
    t.phase = phase(rng_);
    t.width_m = 1.2;
    t.height_m = 0.6;
    targets_.push_back(t);
  }
}

std::vector<detection::Detection> MovingTargets::Detections(int64_t frame, double dt_s) {
  constexpr double kRadiusPx = 12.0;
  std::normal_distribution<double> centroid_noise(0.0, 0.5);
  std::normal_distribution<double> disparity_noise(0.0, 0.1);
  const double fb = camera_.f_px * camera_.baseline_m;
  const double t_s = static_cast<double>(frame) * dt_s;
  std::vector<detection::Detection> out;
  out.reserve(targets_.size());
  for (const Target& target : targets_) {
    const double angle = target.phase + target.rate * t_s;
    const double u = target.u0 + kRadiusPx * std::cos(angle) + centroid_noise(rng_);
    const double v = target.v0 + kRadiusPx * std::sin(angle) + centroid_noise(rng_);
    const double d = fb / target.z_m + disparity_noise(rng_);
    detection::Detection det = testing::MeasuredDetection(camera_, u, v, d, 0.25);
    testing::SetObstacleBox(det, camera_, target.width_m, target.height_m);
    det.score = 1.0;
    det.extractor = "bench";
    out.push_back(std::move(det));
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// Naive baseline
// ---------------------------------------------------------------------------------------------

SingleThreadScope::SingleThreadScope() : saved_(cv::getNumThreads()) { cv::setNumThreads(1); }
SingleThreadScope::~SingleThreadScope() { cv::setNumThreads(saved_); }

struct NaiveThesisPipeline::Impl {
  cv::Mat left_x, left_y, right_x, right_y;  // CV_32FC1
  cv::Ptr<cv::StereoSGBM> sgbm;
  cv::Ptr<cv::saliency::StaticSaliencyFineGrained> saliency;
  cv::Ptr<cv::ximgproc::segmentation::GraphSegmentation> graph;
};

NaiveThesisPipeline::NaiveThesisPipeline(const geometry::StereoRig& raw_rig, NaiveOptions options)
    : options_(options), impl_(std::make_unique<Impl>()) {
  const cv::Size size = raw_rig.image_size();
  const geometry::StereoCalibration& c = raw_rig.calibration();
  if (raw_rig.needs_remap() && c.R1 && c.R2 && c.P1 && c.P2) {
    cv::initUndistortRectifyMap(cv::Mat(c.M1), c.D1, cv::Mat(*c.R1), cv::Mat(*c.P1), size, CV_32FC1,
                                impl_->left_x, impl_->left_y);
    cv::initUndistortRectifyMap(cv::Mat(c.M2), c.D2, cv::Mat(*c.R2), cv::Mat(*c.P2), size, CV_32FC1,
                                impl_->right_x, impl_->right_y);
  } else {
    const cv::Matx33d k(raw_rig.f_px(), 0, raw_rig.cx(), 0, raw_rig.f_px(), raw_rig.cy(), 0, 0, 1);
    cv::initUndistortRectifyMap(cv::Mat(k), cv::Mat(), cv::Mat(), cv::Mat(k), size, CV_32FC1,
                                impl_->left_x, impl_->left_y);
    impl_->right_x = impl_->left_x;
    impl_->right_y = impl_->left_y;
  }
  const int block = options_.sgbm_block_size;
  // OpenCV's usual smoothness penalties for one channel, uniqueness and speckle as the project's
  // SGBM defaults (speckle range 2 px = 32 in OpenCV's 1/16 px).
  impl_->sgbm =
      cv::StereoSGBM::create(0, options_.num_disparities, block, 8 * block * block,
                             32 * block * block, 1, 63, 10, 100, 32, cv::StereoSGBM::MODE_SGBM);
  impl_->saliency = cv::saliency::StaticSaliencyFineGrained::create();
  impl_->graph = cv::ximgproc::segmentation::createGraphSegmentation(
      options_.graph_sigma, static_cast<float>(options_.graph_k), options_.graph_min_size);
}

NaiveThesisPipeline::~NaiveThesisPipeline() = default;

void NaiveThesisPipeline::Rectify(const cv::Mat& left, const cv::Mat& right, cv::Mat& rect_left,
                                  cv::Mat& rect_right) {
  cv::remap(left, rect_left, impl_->left_x, impl_->left_y, cv::INTER_LINEAR);
  cv::remap(right, rect_right, impl_->right_x, impl_->right_y, cv::INTER_LINEAR);
}

cv::Mat NaiveThesisPipeline::Disparity(const cv::Mat& left, const cv::Mat& right) {
  cv::Mat disparity;
  impl_->sgbm->compute(left, right, disparity);
  return disparity;
}

cv::Mat NaiveThesisPipeline::Saliency(const cv::Mat& left) {
  cv::Mat map;
  impl_->saliency->computeSaliency(left, map);
  return map;
}

cv::Mat NaiveThesisPipeline::Segment(const cv::Mat& left) {
  cv::Mat labels;
  impl_->graph->processImage(left, labels);
  return labels;
}

double Percentile(std::vector<double> values, double pct) {
  if (values.empty()) return 0.0;
  std::sort(values.begin(), values.end());
  // Nearest rank: the smallest value with at least pct % of the values at or below it.
  const double rank = std::ceil(pct / 100.0 * static_cast<double>(values.size()));
  const size_t index =
      static_cast<size_t>(std::clamp(rank, 1.0, static_cast<double>(values.size()))) - 1;
  return values[index];
}

double Mean(const std::vector<double>& values) {
  if (values.empty()) return 0.0;
  return std::accumulate(values.begin(), values.end(), 0.0) / static_cast<double>(values.size());
}

}  // namespace stevi::bench
