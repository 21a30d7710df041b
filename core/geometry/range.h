// Disparity to depth, 3-D point and range, with the quantisation uncertainty.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/fields.h"

namespace stevi::geometry {

// Which disparities and ranges are trusted.
struct RangeOptions {
  // Disparities below this floor (camera pixels, before any binning) are not trusted (thesis: 5 px,
  // 3 px on a long baseline). Each hypothesis's disparity is fitted to a small fraction of a pixel
  // on the camera's images (detection/regions.h), so 2.5 px still ranges to a few per cent.
  double min_disparity_px = 2.5;
  // Ranges beyond this (metres) are not trusted. 0 means no limit other than the disparity floor.
  double max_range_m = 0.0;
  // 1-sigma disparity error used for range_sigma_m (pixels). Block matching with sub-pixel
  // interpolation is good to about a quarter pixel on textured surfaces.
  double disparity_sigma_px = 0.25;
  // Disparities whose confidence (DisparityMap::confidence, the matcher's P(inlier), where it
  // gives one) is below this are not trusted by the consumers that read no confidence: the
  // ground plane, the range scan and the thesis detectors. The stixel world weighs every value by
  // its confidence instead.
  double min_confidence = 0.5;

  // Lists every problem ("min_disparity_px: must be > 0 pixels (got -1)", ...).
  std::vector<std::string> Validate() const;

  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Number(s.min_disparity_px,
             Field("min_disparity_px", "pixels", "disparity floor, camera pixels before binning")
                 .Above(0));
    v.Number(s.max_range_m,
             Field("max_range_m", "m", "farthest trusted range; 0 = no limit beyond the floor")
                 .AtLeast(0));
    v.Number(s.disparity_sigma_px,
             Field("disparity_sigma_px", "pixels", "1-sigma disparity error behind range_sigma_m")
                 .Above(0));
    v.Number(s.min_confidence,
             Field("min_confidence", "", "least matcher confidence (P(inlier)) that is trusted")
                 .In(0, 1));
  }
};

// Depth along the optical axis, Z = f B / d (metres). d must be > 0.
double DepthFromDisparity(double disparity_px, double f_px, double baseline_m);

// Disparity of a point at depth Z: d = f B / Z (pixels).
double DisparityFromDepth(double depth_m, double f_px, double baseline_m);

// Depth uncertainty dZ = Z^2 / (f B) * dd (metres).
double DepthSigma(double depth_m, double f_px, double baseline_m, double disparity_sigma_px);

// 3-D point in the rectified left camera frame (x right, y down, z forward, metres) of pixel
// (u, v) with disparity d, through Q. nullopt when the point is at infinity (w == 0).
std::optional<cv::Vec3d> PointFromDisparity(double u_px, double v_px, double disparity_px,
                                            const cv::Matx44d& Q);

// Euclidean range from the left camera centre (metres).
double RangeFromPoint(const cv::Vec3d& point_in_cam);

// True when the disparity passes the floor and its range passes max_range_m.
bool IsTrustedDisparity(double disparity_px, double f_px, double baseline_m,
                        const RangeOptions& options);

}  // namespace stevi::geometry
