#include "core/extraction/segmentation.h"

#include "core/common/error.h"

#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include <opencv2/imgproc.hpp>
#include <opencv2/ximgproc/segmentation.hpp>

namespace stevi::extraction {
namespace {

bool InRange(double v, double lo, double hi) { return v >= lo && v <= hi; }

// Problems of one HSV channel's bound, named e.g. "low.h".
void CheckChannel(const char* name, double value, double max, std::vector<std::string>& problems) {
  if (!InRange(value, 0, max) || std::isnan(value)) {
    char range[32];
    std::snprintf(range, sizeof(range), ": must be in 0..%g", max);
    problems.push_back(std::string(name) + range + Got(value));
  }
}

}  // namespace

std::vector<std::string> IntensityOptions::Validate() const {
  std::vector<std::string> problems;
  if (!InRange(offset, -255, 255)) {
    problems.push_back("offset: must be in [-255, 255] grey levels" + Got(offset));
  }
  if (blur_size < 1 || blur_size % 2 == 0 || blur_size > 31) {
    problems.push_back("blur_size: must be odd and in 1..31 pixels" + Got(blur_size));
  }
  return problems;
}

cv::Mat1b SegmentByIntensity(const cv::Mat1b& grey, const IntensityOptions& options,
                             double* threshold_out) {
  cv::Mat1b mask;
  if (grey.empty()) {
    if (threshold_out != nullptr) *threshold_out = 0;
    return mask;
  }
  // A fresh buffer: blurring into a header that shares `grey`'s data would overwrite the input.
  cv::Mat1b smoothed;
  if (options.blur_size > 1) {
    cv::GaussianBlur(grey, smoothed, cv::Size(options.blur_size, options.blur_size), 0);
  } else {
    smoothed = grey;
  }
  cv::Mat1b unused;
  const double otsu = cv::threshold(smoothed, unused, 0, 255, cv::THRESH_BINARY | cv::THRESH_OTSU);
  const double threshold = otsu + options.offset;
  // THRESH_BINARY keeps src > threshold; THRESH_BINARY_INV keeps src <= threshold.
  cv::threshold(smoothed, mask, threshold, 255,
                options.dark_objects ? cv::THRESH_BINARY_INV : cv::THRESH_BINARY);
  if (threshold_out != nullptr) *threshold_out = threshold;
  return mask;
}

std::vector<std::string> HsvRange::Validate() const {
  std::vector<std::string> problems;
  CheckChannel("low.h", low[0], 179, problems);
  CheckChannel("high.h", high[0], 179, problems);
  CheckChannel("low.s", low[1], 255, problems);
  CheckChannel("high.s", high[1], 255, problems);
  CheckChannel("low.v", low[2], 255, problems);
  CheckChannel("high.v", high[2], 255, problems);
  // Hue may wrap (low > high); saturation and value may not.
  if (low[1] > high[1]) problems.push_back("high.s: must be >= low.s" + Got(high[1]));
  if (low[2] > high[2]) problems.push_back("high.v: must be >= low.v" + Got(high[2]));
  return problems;
}

std::vector<std::string> ValidateHsvRanges(const std::vector<HsvRange>& ranges) {
  std::vector<std::string> problems;
  for (size_t i = 0; i < ranges.size(); ++i) {
    for (const std::string& p : ranges[i].Validate()) {
      problems.push_back("ranges[" + std::to_string(i) + "]." + p);
    }
  }
  return problems;
}

cv::Mat1b SegmentByColour(const cv::Mat3b& bgr, const std::vector<HsvRange>& ranges) {
  cv::Mat1b mask(bgr.size(), uchar{0});
  if (bgr.empty() || ranges.empty()) return mask;
  cv::Mat3b hsv;
  cv::cvtColor(bgr, hsv, cv::COLOR_BGR2HSV);
  cv::Mat1b part;
  const auto add = [&](const cv::Scalar& low, const cv::Scalar& high) {
    cv::inRange(hsv, low, high, part);
    mask |= part;
  };
  for (const HsvRange& r : ranges) {
    if (r.low[0] <= r.high[0]) {
      add(r.low, r.high);
    } else {  // Wraps through red: [low.h, 179] and [0, high.h].
      add(r.low, cv::Scalar(179, r.high[1], r.high[2]));
      add(cv::Scalar(0, r.low[1], r.low[2]), r.high);
    }
  }
  return mask;
}

std::vector<std::string> GraphSegmentationOptions::Validate() const { return fields::Check(*this); }

cv::Mat1i SegmentGraph(const cv::Mat& image, const GraphSegmentationOptions& options) {
  cv::Mat1i labels;
  if (image.empty()) return labels;
  CV_Assert(image.depth() == CV_8U && image.channels() >= 1 && image.channels() <= 4);
  const cv::Ptr<cv::ximgproc::segmentation::GraphSegmentation> segmenter =
      cv::ximgproc::segmentation::createGraphSegmentation(
          options.sigma, static_cast<float>(options.k), options.min_size);
  cv::Mat out;
  segmenter->processImage(image, out);
  labels = out;
  return labels;
}

}  // namespace stevi::extraction
