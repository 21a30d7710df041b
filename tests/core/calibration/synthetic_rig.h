// The synthetic stereo rig and board the calibration tests share.
#pragma once

#include <cmath>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "core/calibration/chessboard.h"
#include "core/geometry/calibration_io.h"

namespace stevi::calibration::testing {

inline const cv::Size kImageSize(640, 480);

// A 9x6 board of 30 mm squares (10x7 squares).
inline BoardSpec TestBoard() { return BoardSpec{9, 6, 0.030}; }

// Distorted cameras with off-centre principal points and different intrinsics, a small rotation,
// and T = (-92.5, 1, 0.5) mm: the camera named left is on the left.
inline geometry::StereoCalibration TruthRig() {
  geometry::StereoCalibration c;
  c.image_size = kImageSize;
  c.M1 = cv::Matx33d(520, 0, 331.5, 0, 521, 236.5, 0, 0, 1);
  c.M2 = cv::Matx33d(516, 0, 312.0, 0, 517, 247.0, 0, 0, 1);
  c.D1 = (cv::Mat_<double>(1, 5) << -0.20, 0.05, 0.0008, -0.0005, 0.0);
  c.D2 = (cv::Mat_<double>(1, 5) << -0.18, 0.04, -0.0006, 0.0004, 0.0);
  cv::Matx33d r;
  cv::Rodrigues(cv::Vec3d(0.006, -0.012, 0.004), r);
  c.R = r;
  c.T = cv::Vec3d(-0.0925, 0.001, 0.0005);
  return c;
}

// Angle of the rotation a^T b (degrees).
inline double RotationAngleDeg(const cv::Matx33d& a, const cv::Matx33d& b) {
  const cv::Matx33d d = a.t() * b;
  const double c = std::clamp((d(0, 0) + d(1, 1) + d(2, 2) - 1) / 2, -1.0, 1.0);
  return std::acos(c) * 180 / CV_PI;
}

}  // namespace stevi::calibration::testing
