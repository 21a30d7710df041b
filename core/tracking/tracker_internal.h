// Internal to core/tracking: the helpers tracker.cc, tracker_measurement.cc and
// tracker_ego_motion.cc share (a detection's depth and range, ratios, boxes). Not part of the
// library's interface.
#pragma once

#include <algorithm>
#include <cmath>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "core/detection/detection.h"

namespace stevi::tracking::internal {

// Points closer than this along the optical axis (metres) cannot be projected: a prediction that
// gets there has passed the camera and only coasts to its deletion.
inline constexpr double kMinDepthM = 1e-3;

inline cv::Vec3d ToCv(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

// The detection's range, or the norm of its position when the range field is not set.
inline double RawRange(const detection::Detection& d) {
  if (std::isfinite(d.range_m) && d.range_m > 0) return d.range_m;
  return cv::norm(d.position_cam_m);
}

// True when max(a, b) <= max_ratio * min(a, b), or when either value is unknown (<= 0).
inline bool WithinRatio(double a, double b, double max_ratio) {
  if (!(a > 0) || !(b > 0)) return true;
  return std::max(a, b) <= max_ratio * std::min(a, b);
}

inline double DepthOf(const detection::Detection& d) {
  return std::isfinite(d.depth_m) && d.depth_m > 0 ? d.depth_m : d.position_cam_m[2];
}

inline double DepthSigmaOf(const detection::Detection& d) {
  const double range = RawRange(d);
  if (!(std::isfinite(d.range_sigma_m) && d.range_sigma_m > 0 && range > 0)) return 0;
  return d.range_sigma_m * DepthOf(d) / range;
}

inline double Area(const cv::Rect& r) { return static_cast<double>(r.width) * r.height; }

inline cv::Rect RectAround(double u, double v, double w, double h) {
  // Clamped: a prediction near the camera plane must not overflow an int.
  const auto px = [](double x) { return static_cast<int>(std::lround(std::clamp(x, -1e6, 1e6))); };
  const int x0 = px(u - 0.5 * w), y0 = px(v - 0.5 * h);
  return {x0, y0, std::max(1, px(u + 0.5 * w) - x0), std::max(1, px(v + 0.5 * h) - y0)};
}

}  // namespace stevi::tracking::internal
