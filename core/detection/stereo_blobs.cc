#include "core/detection/stereo_blobs.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>

namespace stevi::detection {

std::vector<std::string> StereoBlobOptions::Validate() const { return fields::Check(*this); }

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
