// The rectified stereo rig: what every stage after rectification needs to know.
#pragma once

#include <memory>
#include <string>

#include <opencv2/core.hpp>

#include "core/common/error.h"
#include "core/geometry/calibration_io.h"

namespace stevi::geometry {

// Immutable after construction; cheap to copy (the remap tables are shared). Thread-safe.
class StereoRig {
 public:
  // Builds the rig from a calibration: Bouguet rectification (cv::stereoRectify, alpha 0, zero
  // disparity) unless the file carried R1 R2 P1 P2 Q, then the remap tables
  // (cv::initUndistortRectifyMap, fixed-point CV_16SC2). A rig that is already rectified
  // (identity R, zero distortion, T along x, equal square-pixel cameras) needs no remap and
  // Rectify() only converts to grey. kInvalidArgument lists every problem of the calibration; a
  // rig whose camera named left sits to the right (T_x > 0) is refused with a message saying to
  // swap left and right. calibration() then also holds the rectification terms used.
  static Result<StereoRig> FromCalibration(const StereoCalibration& calibration,
                                           std::string calibration_id = "");

  // Loads a calibration YAML and builds the rig; calibration_id is the file's stem (the name
  // without folder and extension). A missing file gives kNotFound.
  static Result<StereoRig> FromFile(const std::string& path);

  // An ideal rectified rig (no remap).
  static StereoRig Ideal(cv::Size image_size, double f_px, double baseline_m, double cx, double cy,
                         std::string calibration_id = "ideal");

  // The rig of this rig's rectified images binned by `factor` (BinImage): an ideal rectified rig
  // of image_size() / factor (rounded down), focal length f / factor, principal point moved to
  // the binned grid ((c - (factor - 1) / 2) / factor), the same baseline and calibration id.
  // factor >= 1; 1 gives an ideal copy of the rectified geometry.
  StereoRig Binned(int factor) const;

  // Rectified focal length (pixels), baseline (metres, > 0), principal point (pixels).
  double f_px() const { return f_px_; }
  double baseline_m() const { return baseline_m_; }
  double cx() const { return cx_; }
  double cy() const { return cy_; }
  cv::Size image_size() const { return image_size_; }
  // Reprojection matrix: [x y z w]^T = Q [u v d 1]^T, point = (x, y, z) / w, metres, cam frame.
  const cv::Matx44d& Q() const { return Q_; }
  const StereoCalibration& calibration() const { return calibration_; }
  const std::string& calibration_id() const { return calibration_id_; }
  // True when Rectify() remaps (a raw, unrectified rig).
  bool needs_remap() const { return maps_ != nullptr; }

  // Rectifies a raw pair into 8-bit grey images of image_size(). Inputs are CV_8UC1 or CV_8UC3
  // of image_size(); anything else gives kInvalidArgument. Output buffers are reused when they
  // already have the right size and type.
  Status Rectify(const cv::Mat& raw_left, const cv::Mat& raw_right, cv::Mat& rect_left,
                 cv::Mat& rect_right) const;

 private:
  struct Maps {
    cv::Mat left_x, left_y, right_x, right_y;
  };
  StereoRig() = default;

  StereoCalibration calibration_;
  std::string calibration_id_;
  cv::Size image_size_;
  double f_px_ = 0, baseline_m_ = 0, cx_ = 0, cy_ = 0;
  cv::Matx44d Q_ = cv::Matx44d::eye();
  std::shared_ptr<const Maps> maps_;
};

// Binning divides every disparity by its factor: below about this many pixels a block matcher no
// longer finds the rig's farthest trusted disparity.
inline constexpr double kMinBinnedDisparityPx = 1.25;

// The smallest whole binning factor that brings `width` to at most `max_width` pixels (1 when
// max_width <= 0: never bin), but no larger than keeps the disparity floor `floor_px` (camera
// pixels; 0 = no limit) at kMinBinnedDisparityPx or more in the binned images: binning is chosen
// for what it costs in range, not by width alone.
int BinningFactor(int width, int max_width, double floor_px = 0);

// Averages each factor x factor block of the 8-bit grey image `in` into one pixel of `out`
// (rounded to nearest): out is in.cols / factor by in.rows / factor; the last columns and rows that
// do not fill a block are dropped. Pixel (j, i) of out covers in's pixels factor*j ..
// factor*j + factor - 1, so its centre lies at factor*j + (factor - 1) / 2 of in. factor 1 copies.
// `out` is reused when it already has the size and type.
void BinImage(const cv::Mat& in, int factor, cv::Mat& out);

}  // namespace stevi::geometry
