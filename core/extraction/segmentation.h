// Segmentation for the extra extractors (thesis sections 4.3 and 4.4): intensity (Otsu), HSV
// colour, and Felzenszwalb-Huttenlocher graph segmentation for SteViS.
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/fields.h"

namespace stevi::extraction {

struct IntensityOptions {
  // true: objects darker than the background (a hull against a bright sky); false: brighter.
  bool dark_objects = true;
  // Added to Otsu's threshold (grey levels, in [-255, 255]). Negative values make a dark-object
  // mask stricter.
  double offset = 0.0;
  // Gaussian kernel size applied before thresholding (pixels, odd; 1 = none).
  int blur_size = 5;

  std::vector<std::string> Validate() const;
};

// Foreground (255) where the (smoothed) grey level is at or below (dark objects) or above (bright
// objects) Otsu's threshold of the image's histogram plus options.offset. The threshold used
// (grey levels) goes to *threshold_out when given. `options` must be valid.
cv::Mat1b SegmentByIntensity(const cv::Mat1b& grey, const IntensityOptions& options,
                             double* threshold_out = nullptr);

// An inclusive box in OpenCV's 8-bit HSV space: [0] hue 0..179 (degrees / 2), [1] saturation
// 0..255, [2] value 0..255 ([3] is ignored). When low[0] > high[0] the hue range wraps through
// red: hue >= low[0] or hue <= high[0].
struct HsvRange {
  cv::Scalar low{0, 0, 0};
  cv::Scalar high{179, 255, 255};

  std::vector<std::string> Validate() const;
};

// Every problem of every range, prefixed with "ranges[i].".
std::vector<std::string> ValidateHsvRanges(const std::vector<HsvRange>& ranges);

// Foreground (255) where the pixel's HSV colour lies in any of `ranges` (none: empty mask). The
// ranges must be valid.
cv::Mat1b SegmentByColour(const cv::Mat3b& bgr, const std::vector<HsvRange>& ranges);

struct GraphSegmentationOptions {
  // Felzenszwalb-Huttenlocher scale k: larger values give larger segments (grey levels; the
  // merge threshold between components is k / component size).
  double k = 300.0;
  // Gaussian smoothing before segmentation (pixels, standard deviation; 0 = none).
  double sigma = 0.5;
  // Segments smaller than this (pixels) are merged into a neighbour.
  int min_size = 50;

  std::vector<std::string> Validate() const;

  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Number(s.k, Field("k", "grey levels", "scale: larger values give larger segments").Above(0));
    v.Number(s.sigma, Field("sigma", "pixels", "Gaussian smoothing first; 0 = none").In(0, 20));
    v.Number(s.min_size,
             Field("min_size", "pixels", "smaller segments join a neighbour").AtLeast(0));
  }
};

// Felzenszwalb-Huttenlocher graph segmentation (OpenCV ximgproc) of an 8-bit image with 1 to 4
// channels. Returns one label per pixel, 0..n-1 with every label used; n is the maximum + 1.
// `options` must be valid. Cost grows as O(pixels log pixels).
cv::Mat1i SegmentGraph(const cv::Mat& image, const GraphSegmentationOptions& options);

}  // namespace stevi::extraction
