// One stereo pair as delivered by a source.
#pragma once

#include <cstdint>

#include <opencv2/core.hpp>

namespace stevi {

struct StereoFrame {
  // Left and right images, 8-bit grey (CV_8UC1) or BGR (CV_8UC3), the same size.
  // Raw camera images unless `rectified` is true.
  cv::Mat left;
  cv::Mat right;
  // Capture time: camera clock where there is one, else std::chrono::steady_clock at arrival.
  int64_t t_ns = 0;
  // Wall-clock (Unix epoch) time of the capture, published alongside t_ns.
  int64_t unix_time_ns = 0;
  // Index of the frame in its source (0-based, increasing; a sequence's frame number).
  int64_t index = 0;
  // True when the source already delivers rectified pairs (the synthetic rig does).
  bool rectified = false;
  // Right capture time minus left, for a pair of separately clocked cameras; 0 for sources whose
  // two images are taken at one instant (synthetic, files).
  int64_t pair_skew_ns = 0;
};

}  // namespace stevi
