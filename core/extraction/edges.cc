#include "core/extraction/edges.h"

#include "core/common/error.h"

#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include <opencv2/imgproc.hpp>

namespace stevi::extraction {
std::vector<std::string> EdgeOptions::Validate() const {
  std::vector<std::string> problems = fields::Check(*this);
  if (canny_high >= 0 && std::isfinite(canny_high) && canny_high < canny_low) {
    problems.push_back("canny_high: must be >= canny_low" + Got(canny_high));
  }
  return problems;
}

cv::Mat1b DetectEdges(const cv::Mat1b& grey, const EdgeOptions& options) {
  cv::Mat1b edges;
  if (grey.empty()) return edges;
  // A fresh buffer: blurring into a header that shares `grey`'s data would overwrite the input.
  cv::Mat1b smoothed;
  if (options.blur_size > 1) {
    cv::GaussianBlur(grey, smoothed, cv::Size(options.blur_size, options.blur_size),
                     options.blur_sigma, options.blur_sigma);
  } else {
    smoothed = grey;
  }
  if (options.canny_aperture == 7) {
    // OpenCV rescales the 7x7 Sobel inside Canny: only its own derivatives give its result.
    cv::Canny(smoothed, edges, options.canny_low, options.canny_high, options.canny_aperture,
              options.l2_gradient);
    return edges;
  }
  // The derivatives Canny would take (Sobel, replicated border), into buffers this thread keeps:
  // the same edges (edges_test checks the equality), sooner than cv::Canny on the image
  // (core/extraction/README.md, "Measured").
  thread_local cv::Mat dx, dy;
  cv::Sobel(smoothed, dx, CV_16S, 1, 0, options.canny_aperture, 1, 0, cv::BORDER_REPLICATE);
  cv::Sobel(smoothed, dy, CV_16S, 0, 1, options.canny_aperture, 1, 0, cv::BORDER_REPLICATE);
  cv::Canny(dx, dy, edges, options.canny_low, options.canny_high, options.l2_gradient);
  return edges;
}

}  // namespace stevi::extraction
