#include "core/detection/canonical.h"

#include "core/common/error.h"

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

// The smallest fixed-point disparity that is an obstacle candidate: nearer than the threshold
// range, above the trusted floor and, when set, within the trusted maximum range.
int16_t CandidateFloorFixed(const geometry::StereoRig& rig, const geometry::RangeOptions& range,
                            const CanonicalOptions& options) {
  const double fb = rig.f_px() * rig.baseline_m();
  double floor_px = std::max(range.min_disparity_px, fb / options.threshold_range_m);
  if (range.max_range_m > 0) floor_px = std::max(floor_px, fb / range.max_range_m);
  const double fixed = std::ceil(floor_px * stereo::DisparityMap::kScale - 1e-9);
  // Disparity 0 is never a candidate (infinite range).
  return static_cast<int16_t>(std::clamp(fixed, 1.0, 32767.0));
}

}  // namespace

std::vector<std::string> CanonicalOptions::Validate() const {
  std::vector<std::string> problems;
  if (!(threshold_range_m > 0) || !std::isfinite(threshold_range_m)) {
    problems.push_back("threshold_range_m: must be > 0 metres" + Got(threshold_range_m));
  }
  if (open_size_px < 1 || open_size_px % 2 == 0) {
    problems.push_back("open_size_px: must be odd and >= 1" + Got(open_size_px));
  }
  for (const std::string& p : blobs.Validate()) problems.push_back("blobs." + p);
  return problems;
}

std::vector<Detection> DetectCanonical(const stereo::DisparityMap& disparity,
                                       const geometry::StereoRig& rig,
                                       const geometry::RangeOptions& range,
                                       const CanonicalOptions& options) {
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
  if (options.open_size_px > 1) {
    const cv::Mat kernel = cv::getStructuringElement(
        cv::MORPH_RECT, cv::Size(options.open_size_px, options.open_size_px));
    cv::morphologyEx(mask, mask, cv::MORPH_OPEN, kernel);
  }

  // 3. Blobs, ranged, with the thesis's filters.
  return RangeBlobs(mask, disparity, rig, range, options.blobs, "canonical");
}

}  // namespace stevi::detection
