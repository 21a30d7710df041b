#include "core/geometry/range.h"

namespace stevi::geometry {

std::vector<std::string> RangeOptions::Validate() const { return fields::Check(*this); }

double DepthFromDisparity(double disparity_px, double f_px, double baseline_m) {
  return f_px * baseline_m / disparity_px;
}

double DisparityFromDepth(double depth_m, double f_px, double baseline_m) {
  return f_px * baseline_m / depth_m;
}

double DepthSigma(double depth_m, double f_px, double baseline_m, double disparity_sigma_px) {
  return depth_m * depth_m / (f_px * baseline_m) * disparity_sigma_px;
}

std::optional<cv::Vec3d> PointFromDisparity(double u_px, double v_px, double disparity_px,
                                            const cv::Matx44d& Q) {
  const cv::Vec4d h = Q * cv::Vec4d(u_px, v_px, disparity_px, 1.0);
  if (h[3] == 0.0) return std::nullopt;
  return cv::Vec3d(h[0] / h[3], h[1] / h[3], h[2] / h[3]);
}

double RangeFromPoint(const cv::Vec3d& point_in_cam) { return cv::norm(point_in_cam); }

bool IsTrustedDisparity(double disparity_px, double f_px, double baseline_m,
                        const RangeOptions& options) {
  if (!(disparity_px >= options.min_disparity_px)) return false;
  if (options.max_range_m == 0.0) return true;
  return DepthFromDisparity(disparity_px, f_px, baseline_m) <= options.max_range_m;
}

}  // namespace stevi::geometry
