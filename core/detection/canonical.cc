#include "core/detection/canonical.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "core/detection/stereo_blobs.h"

namespace stevi::detection {
namespace {

// threshold_range_m 0: candidates down to this many disparity sigmas (5 % of depth).
constexpr double kAutoThresholdSigmas = 20.0;

// The smallest fixed-point disparity that is an obstacle candidate: nearer than the threshold
// range, above the trusted floor and, when set, within the trusted maximum range.
int16_t CandidateFloorFixed(const geometry::StereoRig& rig, const geometry::RangeOptions& range,
                            const CanonicalOptions& options) {
  const double fb = rig.f_px() * rig.baseline_m();
  const double threshold_px = options.threshold_range_m > 0
                                  ? fb / options.threshold_range_m
                                  : kAutoThresholdSigmas * range.disparity_sigma_px;
  double floor_px = std::max(range.min_disparity_px, threshold_px);
  if (range.max_range_m > 0) floor_px = std::max(floor_px, fb / range.max_range_m);
  const double fixed = std::ceil(floor_px * stereo::DisparityMap::kScale - 1e-9);
  // Disparity 0 is never a candidate (infinite range).
  return static_cast<int16_t>(std::clamp(fixed, 1.0, 32767.0));
}

}  // namespace

std::vector<std::string> CanonicalOptions::Validate() const { return fields::Check(*this); }

std::vector<Detection> DetectCanonical(const stereo::DisparityMap& disparity,
                                       const geometry::StereoRig& rig,
                                       const geometry::RangeOptions& range,
                                       const CanonicalOptions& options,
                                       const FullResolutionPair* full) {
  if (disparity.empty()) return {};

  // 1. Candidates: trusted disparities nearer than the threshold range.
  const int16_t floor_fixed = CandidateFloorFixed(rig, range, options);
  cv::Mat1b mask(disparity.fixed.size());
  for (int y = 0; y < mask.rows; ++y) {
    const int16_t* d = disparity.fixed[y];
    uchar* m = mask[y];
    for (int x = 0; x < mask.cols; ++x) m[x] = d[x] >= floor_fixed ? 255 : 0;
  }

  // 2. Opening cuts thin bridges and removes isolated speckles.
  const int open_size = ScaledKernel(options.open_size_px, mask.cols);
  if (open_size > 1) {
    const cv::Mat kernel =
        cv::getStructuringElement(cv::MORPH_RECT, cv::Size(open_size, open_size));
    cv::morphologyEx(mask, mask, cv::MORPH_OPEN, kernel);
  }

  // 3. The candidates' clusters (their own regions), split into depth modes, ranged.
  cv::Mat1b classes(mask.size());
  for (int y = 0; y < mask.rows; ++y) {
    const uchar* m = mask[y];
    const int16_t* d = disparity.fixed[y];
    uchar* c = classes[y];
    for (int x = 0; x < mask.cols; ++x)
      c[x] = m[x] ? kCandidate : (d[x] >= 0 ? kFar : kNoDisparity);
  }
  return RangeRegions(mask, classes, disparity, rig, range, options.blobs, "canonical",
                      std::nullopt, full);
}

}  // namespace stevi::detection
