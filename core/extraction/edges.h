// Edge detection for the SteViE extractor (thesis section 4.2): Gaussian smoothing, then Canny.
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/fields.h"

namespace stevi::extraction {

struct EdgeOptions {
  // Gaussian kernel size (pixels, odd); 1 disables the smoothing.
  int blur_size = 3;
  // Gaussian standard deviation (pixels); 0 derives it from blur_size as OpenCV does.
  double blur_sigma = 0.0;
  // Canny hysteresis thresholds on the gradient magnitude (grey levels per pixel, in the units of
  // the Sobel operator of size canny_aperture): edges start above canny_high and continue above
  // canny_low.
  double canny_low = 25.0;
  double canny_high = 75.0;
  // Sobel aperture for Canny's gradients: 3, 5 or 7.
  int canny_aperture = 3;
  // true: gradient magnitude sqrt(gx^2 + gy^2); false: |gx| + |gy|.
  bool l2_gradient = true;

  // The field checks, and canny_high >= canny_low.
  std::vector<std::string> Validate() const;

  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Number(
        s.blur_size,
        Field("blur_size", "pixels", "Gaussian kernel; 1 disables the smoothing").Odd().In(1, 31));
    v.Number(s.blur_sigma,
             Field("blur_sigma", "pixels", "Gaussian sigma; 0 = from blur_size").AtLeast(0));
    v.Number(s.canny_low,
             Field("canny_low", "", "Canny: edges continue above this gradient").AtLeast(0));
    v.Number(
        s.canny_high,
        Field("canny_high", "", "Canny: edges start above this gradient; >= canny_low").AtLeast(0));
    v.Number(s.canny_aperture,
             Field("canny_aperture", "pixels", "Sobel aperture of Canny's gradients: 3, 5 or 7")
                 .Odd()
                 .In(3, 7));
    v.Flag(s.l2_gradient,
           Field("l2_gradient", "", "true: sqrt(gx^2 + gy^2); false: the sum of the absolutes"));
  }
};

// Edges of a grey image: 255 on edge pixels, 0 elsewhere, the input's size. `options` must be
// valid.
cv::Mat1b DetectEdges(const cv::Mat1b& grey, const EdgeOptions& options);

}  // namespace stevi::extraction
