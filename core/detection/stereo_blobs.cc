#include "core/detection/stereo_blobs.h"

#include "core/common/error.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>

namespace stevi::detection {

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
  if (!(region_gap_fraction >= 0 && region_gap_fraction <= 100)) {
    problems.push_back("region_gap_fraction: must be in [0, 100]" + Got(region_gap_fraction));
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
  const double sigma_px =
      d.disparity_sigma_px > 0 ? d.disparity_sigma_px : range.disparity_sigma_px;
  const double depth_sigma = geometry::DepthSigma(d.depth_m, f, b, sigma_px);
  d.range_sigma_m = d.depth_m > 0 ? depth_sigma * d.range_m / d.depth_m : depth_sigma;
}

}  // namespace stevi::detection
