// A stereo detection made from what the detector measured (centroid and disparity), for the
// tracker's tests and the benchmarks' synthetic targets: the fields a real detector derives from
// them, derived the way it does.
#pragma once

#include <cmath>

#include <opencv2/core.hpp>

#include "core/detection/detection.h"
#include "core/tracking/kalman.h"

namespace stevi::testing {

// A detection centred at pixel (u, v) with disparity d: its depth f b / d, its position
// back-projected through `camera`, its range, and the range's sigma for a disparity sigma of
// `disparity_sigma_px`. The box (see SetObstacleBox), score and the rest are left to the caller.
inline detection::Detection MeasuredDetection(const tracking::CameraModel& camera, double u,
                                              double v, double d, double disparity_sigma_px) {
  const double fb = camera.f_px * camera.baseline_m;
  const double z = fb / d;
  detection::Detection det;
  det.centroid_px = cv::Point2d(u, v);
  det.disparity_px = d;
  det.depth_m = z;
  det.position_cam_m =
      cv::Vec3d((u - camera.cx) * z / camera.f_px, (v - camera.cy) * z / camera.f_px, z);
  det.range_m = cv::norm(det.position_cam_m);
  det.range_sigma_m = z * z / fb * disparity_sigma_px * det.range_m / z;
  return det;
}

// Gives `det` the box of an obstacle width_m x height_m at its measured depth, centred on its
// centroid (rounded to pixels), with the box's area (all of it with a valid disparity) and
// perimeter.
inline void SetObstacleBox(detection::Detection& det, const tracking::CameraModel& camera,
                           double width_m, double height_m) {
  const double z = det.depth_m, u = det.centroid_px.x, v = det.centroid_px.y;
  const double w = camera.f_px * width_m / z, h = camera.f_px * height_m / z;
  det.bbox =
      cv::Rect(static_cast<int>(std::lround(u - w / 2)), static_cast<int>(std::lround(v - h / 2)),
               static_cast<int>(std::lround(w)), static_cast<int>(std::lround(h)));
  det.area_px = static_cast<int>(std::lround(w * h));
  det.valid_disparities = det.area_px;
  det.perimeter_px = 2 * (w + h);
}

}  // namespace stevi::testing
