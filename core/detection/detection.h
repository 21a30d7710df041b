// A detected obstacle in one frame.
#pragma once

#include <string>

#include <opencv2/core.hpp>

namespace stevi::detection {

struct Detection {
  cv::Rect bbox;  // rectified left image, pixels
  cv::Point2d centroid_px;
  int area_px = 0;
  double perimeter_px = 0;
  double disparity_px = 0;    // the hypothesis' disparity: sub-pixel fit, else the median
  int valid_disparities = 0;  // how many pixels of the mask had a trusted disparity at its range
  double valid_fraction = 0;  // valid_disparities over the box's area: how much of it had one
  double disparity_sigma_px = 0;  // 1-sigma of disparity_px (from the fit, else the range options)
  double depth_m = 0;             // along the optical axis
  double range_m = 0;             // Euclidean, from the left camera centre
  double range_sigma_m = 0;       // 1-sigma, from the disparity uncertainty
  cv::Vec3d position_cam_m;       // the blob's centroid at its disparity, cam frame
  double score = 0;               // 0..1, the detector's confidence
  std::string extractor;          // which extractor produced it ("canonical", ...)
};

}  // namespace stevi::detection
