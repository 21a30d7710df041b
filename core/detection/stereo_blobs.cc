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
// Blobs shorter than this (rows) are never given the slope test: too few rows to fit.
constexpr int kMinTerrainRows = 12;

double DepthFromDisparityPx(double d_px, const geometry::StereoRig& rig) {
  return rig.f_px() * rig.baseline_m() / d_px;
}

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

// The slope dZ/dH of depth over height (metres per metre; H = -y, up) of the plane
// Z = a + b H + c X fitted by least squares to the blob's pixels whose disparity lies within 30 %
// of its median. Fitting the lateral tilt c as well keeps a surface that recedes sideways (a
// hillside seen obliquely, whose blob is taller on its near side) from hiding its lean-back.
// 0 when the blob is too short to tell.
double DepthPerHeight(const stereo::DisparityMap& disparity, const cv::Mat1i& labels, int label,
                      const cv::Rect& box, double median_px, const geometry::StereoRig& rig,
                      double min_height_m) {
  const double fb = rig.f_px() * rig.baseline_m();
  if (box.height < kMinTerrainRows ||
      box.height * DepthFromDisparityPx(median_px, rig) / rig.f_px() < min_height_m) {
    return 0;
  }
  const double lo = 0.7 * median_px * stereo::DisparityMap::kScale;
  const double hi = 1.3 * median_px * stereo::DisparityMap::kScale;
  // Normal equations of [1 H X] (centred on the first sample for conditioning).
  cv::Matx33d ata = cv::Matx33d::zeros();
  cv::Vec3d atz(0, 0, 0);
  int n = 0;
  for (int y = box.y; y < box.y + box.height; ++y) {
    const int* lab = labels[y];
    const int16_t* d = disparity.fixed[y];
    for (int x = box.x; x < box.x + box.width; ++x) {
      if (lab[x] != label || d[x] < lo || d[x] > hi) continue;
      const double z = fb * stereo::DisparityMap::kScale / d[x];
      const cv::Vec3d row(1.0, -(y - rig.cy()) * z / rig.f_px(), (x - rig.cx()) * z / rig.f_px());
      ata += row * row.t();
      atz += row * z;
      ++n;
    }
  }
  if (n < 30) return 0;
  cv::Vec3d plane;
  if (!cv::solve(ata, atz, plane, cv::DECOMP_CHOLESKY)) return 0;
  return plane[1];
}

// The fraction of the trusted disparities in a ring around the blob (kRingInPx to kRingOutPx
// from its mask) that lie at the blob's own range: within max(1 px, 10 %) of its median. A patch of
// terrain that a threshold cut out of a continuous surface (the ground margin, the disparity
// floor, an edge mask) is surrounded by that surface continuing at its range (fraction near 1); an
// obstacle stands out in depth from what lies around it (near 0). The ring starts a few pixels out
// because block matching spreads an object's disparity into its surroundings. -1 when the ring holds
// fewer than kMinRingPixels trusted disparities: no evidence either way.
double AttachedFraction(const stereo::DisparityMap& disparity, const cv::Mat1i& labels, int label,
                        const cv::Rect& box, double median_px, double min_disparity_px) {
  constexpr int kRingInPx = 6, kRingOutPx = 12, kMinRingPixels = 20;
  const cv::Rect outer =
      (box + cv::Point(-kRingOutPx, -kRingOutPx) + cv::Size(2 * kRingOutPx, 2 * kRingOutPx)) &
      cv::Rect(0, 0, labels.cols, labels.rows);
  const cv::Mat1b mask = (labels(outer) == label);
  cv::Mat1b inner_disc, outer_disc;
  cv::dilate(mask, inner_disc,
             cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * kRingInPx + 1, 2 * kRingInPx + 1)));
  cv::dilate(mask, outer_disc,
             cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * kRingOutPx + 1, 2 * kRingOutPx + 1)));
  const double band = std::max(1.0, 0.1 * median_px);
  const double lo = std::max((median_px - band), min_disparity_px) * stereo::DisparityMap::kScale;
  const double hi = (median_px + band) * stereo::DisparityMap::kScale;
  int ring = 0, attached = 0;
  for (int y = 0; y < outer.height; ++y) {
    const int16_t* d = disparity.fixed[outer.y + y] + outer.x;
    const uchar* in = inner_disc[y];
    const uchar* out = outer_disc[y];
    for (int x = 0; x < outer.width; ++x) {
      if (!out[x] || in[x] || d[x] < 0 ||
          d[x] < min_disparity_px * stereo::DisparityMap::kScale) {
        continue;
      }
      ++ring;
      if (d[x] >= lo && d[x] <= hi) ++attached;
    }
  }
  return ring < kMinRingPixels ? -1.0 : static_cast<double>(attached) / ring;
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
  if (min_valid_px < 0 || min_valid_px > 100000) {
    problems.push_back("min_valid_px: must be in 0..100000" + Got(min_valid_px));
  }
  if (!(join_gap_fraction >= 0 && join_gap_fraction <= 10)) {
    problems.push_back("join_gap_fraction: must be in [0, 10]" + Got(join_gap_fraction));
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
  if (!(max_attached_fraction >= 0 && max_attached_fraction <= 1)) {
    problems.push_back("max_attached_fraction: must be in [0, 1]" + Got(max_attached_fraction));
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
  const double sigma_px = d.disparity_sigma_px > 0 ? d.disparity_sigma_px : range.disparity_sigma_px;
  const double depth_sigma = geometry::DepthSigma(d.depth_m, f, b, sigma_px);
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
                                  const StereoBlobOptions& options, std::string_view extractor,
                                  const std::optional<GroundModel>& ground) {
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
    // A blob too short for the slope test, reaching below the horizon (where terrain is), whose
    // surroundings continue at its range is a patch of terrain cut out by a threshold.
    const double height_m = blob.bbox.height * DepthFromDisparityPx(*median, rig) / rig.f_px();
    const bool too_short = blob.bbox.height < kMinTerrainRows || height_m < options.min_terrain_height_m;
    if (options.max_attached_fraction < 1 && too_short && ground &&
        blob.bbox.y + blob.bbox.height > ground->horizon_row &&
        AttachedFraction(disparity, blobs.labels, blob.label, blob.bbox, *median,
                         range.min_disparity_px) > options.max_attached_fraction) {
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
