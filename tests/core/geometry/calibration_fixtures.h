// The calibrations and calibration YAML that the core/geometry tests share (calibration_io_test,
// stereo_rig_test); the calibration store's test (core/calibration/store_test) varies the raw rig.
#pragma once

#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "core/geometry/calibration_io.h"

namespace stevi::geometry::fixtures {

// Largest absolute element difference of two matrices of the same shape.
inline double MaxAbsDiff(const cv::Mat& a, const cv::Mat& b) {
  EXPECT_EQ(a.size(), b.size());
  if (a.size() != b.size()) return 1e300;
  cv::Mat a64, b64;
  a.convertTo(a64, CV_64F);
  b.convertTo(b64, CV_64F);
  return cv::norm(a64, b64, cv::NORM_INF);
}

// A raw (unrectified) rig: distorted cameras with different intrinsics, a small rotation and a
// 10 cm baseline with a little vertical and forward offset.
inline StereoCalibration RawCalibration() {
  StereoCalibration c;
  c.image_size = cv::Size(640, 480);
  c.M1 = cv::Matx33d(520, 0, 318.5, 0, 522, 244.0, 0, 0, 1);
  c.M2 = cv::Matx33d(515, 0, 325.0, 0, 516, 238.5, 0, 0, 1);
  c.D1 = (cv::Mat_<double>(1, 5) << -0.12, 0.05, 0.001, -0.0005, 0.0);
  c.D2 = (cv::Mat_<double>(1, 5) << -0.10, 0.03, -0.0008, 0.0006, 0.0);
  cv::Mat r;
  cv::Rodrigues(cv::Vec3d(0.01, -0.02, 0.005), r);
  c.R = cv::Matx33d(r);
  c.T = cv::Vec3d(-0.1, 0.002, -0.001);
  return c;
}

inline std::string WriteFile(const std::string& dir, const std::string& name,
                             const std::string& text) {
  const std::string path = dir + "/" + name;
  std::ofstream(path) << text;
  return path;
}

inline constexpr char kIdealYaml[] = R"(%YAML:1.0
---
image_width: 640
image_height: 480
M1: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 500., 0., 320., 0., 500., 240., 0., 0., 1. ]
D1: !!opencv-matrix
   rows: 1
   cols: 5
   dt: d
   data: [ 0., 0., 0., 0., 0. ]
M2: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 500., 0., 320., 0., 500., 240., 0., 0., 1. ]
D2: !!opencv-matrix
   rows: 5
   cols: 1
   dt: d
   data: [ 0., 0., 0., 0., 0. ]
R: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 1., 0., 0., 0., 1., 0., 0., 0., 1. ]
T: !!opencv-matrix
   rows: 1
   cols: 3
   dt: d
   data: [ -0.12, 0., 0. ]
)";

// Replaces the first occurrence of `from` in `text` (which must be there).
inline std::string Replace(std::string text, const std::string& from, const std::string& to) {
  const std::size_t at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at != std::string::npos) text.replace(at, from.size(), to);
  return text;
}

}  // namespace stevi::geometry::fixtures
