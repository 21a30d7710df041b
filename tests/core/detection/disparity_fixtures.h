// The rig and hand-painted disparity maps that the core/detection tests share (canonical_test,
// regions_test).
#pragma once

#include <cmath>

#include <opencv2/core.hpp>

#include "core/geometry/stereo_rig.h"
#include "core/stereo/disparity.h"

namespace stevi::detection::fixtures {

inline constexpr double kF = 700.0;
inline constexpr double kB = 0.6;

// An ideal 640x480 rig: f = kF px, baseline kB m, principal point at the centre.
inline geometry::StereoRig TestRig() {
  return geometry::StereoRig::Ideal(cv::Size(640, 480), kF, kB, 320.0, 240.0);
}

// A map of `size` with no disparity anywhere (64 disparities searched).
inline stereo::DisparityMap EmptyMap(cv::Size size) {
  stereo::DisparityMap map;
  map.fixed = cv::Mat1s(size, stereo::DisparityMap::kInvalid);
  map.num_disparities = 64;
  return map;
}

// Sets `disparity_px` over `r`.
inline void Paint(stereo::DisparityMap& map, const cv::Rect& r, double disparity_px) {
  map.fixed(r).setTo(cv::Scalar(std::lround(disparity_px * stereo::DisparityMap::kScale)));
}

}  // namespace stevi::detection::fixtures
