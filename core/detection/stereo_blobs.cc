#include "core/detection/stereo_blobs.h"

#include "core/common/error.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <optional>

#include <opencv2/imgproc.hpp>

#include "core/extraction/blobs.h"

namespace stevi::detection {
namespace {

// Fewer interior pixels than this and the whole blob gives the disparity.
constexpr int kMinInteriorPixels = 30;

// Fraction of the blob's valid disparities within a band around the median: near 1 for one
// surface at one range, lower for blobs that merge surfaces at different ranges.
double Consistency(const stereo::DisparityMap& disparity, const cv::Mat1i& labels, int label,
                   const cv::Rect& box, double median_px, double min_disparity_px) {
  const double band = std::max(1.0, 0.1 * median_px) * stereo::DisparityMap::kScale;
  const double median_fixed = median_px * stereo::DisparityMap::kScale;
  const double floor_fixed = min_disparity_px * stereo::DisparityMap::kScale;
  int valid = 0, consistent = 0;
  for (int y = box.y; y < box.y + box.height; ++y) {
    const int* lab = labels[y];
    const int16_t* d = disparity.fixed[y];
    for (int x = box.x; x < box.x + box.width; ++x) {
      if (lab[x] != label || d[x] < 0 || d[x] < floor_fixed) continue;
      ++valid;
      if (std::abs(d[x] - median_fixed) <= band) ++consistent;
    }
  }
  return valid == 0 ? 0.0 : static_cast<double>(consistent) / valid;
}

// Least-squares slope dZ/dH of depth over height (metres per metre; H = -y, up) over the blob's
// pixels whose disparity lies within 30 % of its median. 0 when the blob is too short to tell.
double DepthPerHeight(const stereo::DisparityMap& disparity, const cv::Mat1i& labels, int label,
                      const cv::Rect& box, double median_px, const geometry::StereoRig& rig,
                      double min_height_m) {
  const double fb = rig.f_px() * rig.baseline_m();
  if (box.height < 12 || box.height * (fb / median_px) / rig.f_px() < min_height_m) return 0;
  const double lo = 0.7 * median_px * stereo::DisparityMap::kScale;
  const double hi = 1.3 * median_px * stereo::DisparityMap::kScale;
  double n = 0, sh = 0, sz = 0, shh = 0, shz = 0;
  for (int y = box.y; y < box.y + box.height; ++y) {
    const int* lab = labels[y];
    const int16_t* d = disparity.fixed[y];
    for (int x = box.x; x < box.x + box.width; ++x) {
      if (lab[x] != label || d[x] < lo || d[x] > hi) continue;
      const double z = fb * stereo::DisparityMap::kScale / d[x];
      const double h = -(y - rig.cy()) * z / rig.f_px();
      n += 1;
      sh += h;
      sz += z;
      shh += h * h;
      shz += h * z;
    }
  }
  const double var = n * shh - sh * sh;
  if (n < 30 || var <= 1e-9) return 0;
  return (n * shz - sh * sz) / var;
}

}  // namespace

std::vector<std::string> StereoBlobOptions::Validate() const {
  std::vector<std::string> problems;
  if (min_area_px < 1) problems.push_back("min_area_px: must be >= 1" + Got(min_area_px));
  if (!(max_width_fraction > 0 && max_width_fraction <= 1)) {
    problems.push_back("max_width_fraction: must be in (0, 1]" + Got(max_width_fraction));
  }
  if (!(min_valid_fraction >= 0 && min_valid_fraction <= 1)) {
    problems.push_back("min_valid_fraction: must be in [0, 1]" + Got(min_valid_fraction));
  }
  if (!(max_disparity_step_px >= 0 && max_disparity_step_px <= 1000)) {
    problems.push_back("max_disparity_step_px: must be in [0, 1000] pixels" +
                       Got(max_disparity_step_px));
  }
  if (!(max_depth_per_height >= 0 && max_depth_per_height <= 100)) {
    problems.push_back("max_depth_per_height: must be in [0, 100]" + Got(max_depth_per_height));
  }
  if (!(min_terrain_height_m >= 0 && min_terrain_height_m <= 1000)) {
    problems.push_back("min_terrain_height_m: must be in [0, 1000]" + Got(min_terrain_height_m));
  }
  if (interior_erode_px < 0 || interior_erode_px > 50) {
    problems.push_back("interior_erode_px: must be in 0..50" + Got(interior_erode_px));
  }
  return problems;
}

void FillRange(Detection& d, const geometry::StereoRig& rig, const geometry::RangeOptions& range) {
  const double f = rig.f_px();
  const double b = rig.baseline_m();
  if (!(d.disparity_px > 0)) {
    d.depth_m = d.range_m = d.range_sigma_m = std::numeric_limits<double>::infinity();
    d.position_cam_m = cv::Vec3d(0, 0, std::numeric_limits<double>::infinity());
    return;
  }
  d.depth_m = geometry::DepthFromDisparity(d.disparity_px, f, b);
  const std::optional<cv::Vec3d> point =
      geometry::PointFromDisparity(d.centroid_px.x, d.centroid_px.y, d.disparity_px, rig.Q());
  if (point) {
    d.position_cam_m = *point;
  } else {
    // Pinhole fallback with the rectified intrinsics.
    d.position_cam_m = cv::Vec3d((d.centroid_px.x - rig.cx()) * d.depth_m / f,
                                 (d.centroid_px.y - rig.cy()) * d.depth_m / f, d.depth_m);
  }
  d.range_m = geometry::RangeFromPoint(d.position_cam_m);
  const double depth_sigma = geometry::DepthSigma(d.depth_m, f, b, range.disparity_sigma_px);
  d.range_sigma_m = d.depth_m > 0 ? depth_sigma * d.range_m / d.depth_m : depth_sigma;
}

cv::Mat1b StereoCandidates(const cv::Mat1b& appearance, const stereo::DisparityMap& disparity,
                           const geometry::StereoRig& rig, const geometry::RangeOptions& range,
                           const std::optional<GroundModel>& ground, const GroundOptions& ground_options) {
  const cv::Mat1s& fixed = disparity.fixed;
  cv::Mat1b out(fixed.size(), uchar{0});
  if (!appearance.empty() && appearance.size() != fixed.size()) return out;
  const double fb = rig.f_px() * rig.baseline_m();
  double floor_px = range.min_disparity_px;
  if (range.max_range_m > 0) floor_px = std::max(floor_px, fb / range.max_range_m);
  const int floor_fixed = static_cast<int>(std::ceil(floor_px * stereo::DisparityMap::kScale - 1e-9));
  for (int y = 0; y < fixed.rows; ++y) {
    const int16_t* d = fixed[y];
    const uchar* a = appearance.empty() ? nullptr : appearance[y];
    uchar* o = out[y];
    // The ground's threshold is the same along a row.
    const double ground_d = ground ? ground->DisparityAt(y) : 0.0;
    const double above_fixed =
        ground ? (ground_d + std::max(ground_options.margin_px,
                                      ground_options.margin_fraction * ground_d)) *
                     stereo::DisparityMap::kScale
               : -1.0;
    for (int x = 0; x < fixed.cols; ++x) {
      if ((a != nullptr && a[x] == 0) || d[x] < floor_fixed || d[x] <= above_fixed) continue;
      o[x] = 255;
    }
  }
  return out;
}

std::vector<Detection> RangeBlobs(const cv::Mat1b& candidates, const stereo::DisparityMap& disparity,
                                  const geometry::StereoRig& rig,
                                  const geometry::RangeOptions& range,
                                  const StereoBlobOptions& options, std::string_view extractor) {
  std::vector<Detection> out;
  if (disparity.empty() || candidates.empty()) return out;
  const extraction::BlobSet blobs =
      options.max_disparity_step_px > 0
          ? extraction::ExtractDisparityBlobs(
                candidates, disparity.fixed,
                static_cast<int>(std::lround(options.max_disparity_step_px *
                                             stereo::DisparityMap::kScale)),
                options.min_area_px)
          : extraction::ExtractBlobs(candidates, options.min_area_px);
  // The blobs' interiors: block matching spreads an object's disparity a few pixels into its
  // surroundings (and ramps across its borders), so the range comes from the interior when there is
  // enough of it.
  cv::Mat1i interior;
  if (options.interior_erode_px > 0) {
    interior = blobs.labels.clone();
    cv::Mat1b eroded;
    const int k = 2 * options.interior_erode_px + 1;
    cv::erode(candidates, eroded, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(k, k)));
    interior.setTo(0, eroded == 0);
  }
  const double max_width_px = options.max_width_fraction * candidates.cols;
  for (const extraction::Blob& blob : blobs.blobs) {
    if (blob.bbox.width > max_width_px) continue;  // the skyline, the ground
    int valid = 0;
    std::optional<double> median = stereo::MedianDisparityInMask(
        disparity, blobs.labels, blob.label, blob.bbox, range.min_disparity_px, &valid);
    if (median && options.interior_erode_px > 0) {
      int interior_valid = 0;
      const std::optional<double> inner = stereo::MedianDisparityInMask(
          disparity, interior, blob.label, blob.bbox, range.min_disparity_px, &interior_valid);
      if (inner && interior_valid >= kMinInteriorPixels) median = inner;
    }
    if (!median || valid == 0) continue;
    const double valid_fraction = static_cast<double>(valid) / blob.area_px;
    if (valid_fraction < options.min_valid_fraction) continue;
    if (!geometry::IsTrustedDisparity(*median, rig.f_px(), rig.baseline_m(), range)) continue;
    if (options.max_depth_per_height > 0 &&
        DepthPerHeight(disparity, blobs.labels, blob.label, blob.bbox, *median, rig,
                       options.min_terrain_height_m) >
            options.max_depth_per_height) {
      continue;  // terrain
    }

    Detection d;
    d.bbox = blob.bbox;
    d.centroid_px = blob.centroid_px;
    d.area_px = blob.area_px;
    d.perimeter_px = blob.perimeter_px;
    d.disparity_px = *median;
    d.valid_disparities = valid;
    FillRange(d, rig, range);
    d.score = std::clamp(valid_fraction, 0.0, 1.0) * Consistency(disparity, blobs.labels,
                                                                 blob.label, blob.bbox, *median,
                                                                 range.min_disparity_px);
    d.extractor = std::string(extractor);
    out.push_back(std::move(d));
  }
  return out;
}

}  // namespace stevi::detection
