#include "core/stereo/disparity.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <opencv2/imgproc.hpp>

namespace stevi::stereo {

// The median is exact on the fixed-point values (1/16 px): a histogram of the valid values, and
// for an even count the mean of the two middle values.
std::optional<double> MedianDisparityInMask(const DisparityMap& disparity, const cv::Mat1i& labels,
                                            int label, const cv::Rect& box, double min_disparity_px,
                                            int* valid_count) {
  if (valid_count != nullptr) *valid_count = 0;
  if (disparity.fixed.empty() || labels.size() != disparity.fixed.size()) return std::nullopt;
  const cv::Rect area = box & cv::Rect(0, 0, labels.cols, labels.rows);
  if (area.empty()) return std::nullopt;

  // Values below the floor (and every negative "unmatched" value) are not counted.
  const double floor_scaled = std::ceil(min_disparity_px * DisparityMap::kScale - 1e-9);
  const int floor_fixed = static_cast<int>(std::clamp(floor_scaled, 0.0, 32768.0));

  // One bin per int16 value; only the touched range is cleared afterwards.
  thread_local std::vector<int> histogram(32768, 0);
  int lo = 32768, hi = -1, count = 0;
  for (int y = area.y; y < area.y + area.height; ++y) {
    const int* label_row = labels.ptr<int>(y);
    const int16_t* disparity_row = disparity.fixed.ptr<int16_t>(y);
    for (int x = area.x; x < area.x + area.width; ++x) {
      if (label_row[x] != label) continue;
      const int v = disparity_row[x];
      if (v < floor_fixed) continue;
      ++histogram[v];
      lo = std::min(lo, v);
      hi = std::max(hi, v);
      ++count;
    }
  }
  if (count == 0) return std::nullopt;

  // 0-based ranks of the middle values: equal for an odd count.
  const int rank_low = (count - 1) / 2;
  const int rank_high = count / 2;
  int value_low = -1, value_high = -1, seen = 0;
  for (int v = lo; v <= hi && value_high < 0; ++v) {
    seen += histogram[v];
    if (value_low < 0 && seen > rank_low) value_low = v;
    if (seen > rank_high) value_high = v;
  }
  std::fill(histogram.begin() + lo, histogram.begin() + hi + 1, 0);
  if (valid_count != nullptr) *valid_count = count;
  return 0.5 * (value_low + value_high) / DisparityMap::kScale;
}

cv::Mat1w ToFixedPoint16U(const DisparityMap& disparity) {
  cv::Mat1w out(disparity.fixed.size());
  for (int y = 0; y < out.rows; ++y) {
    const int16_t* src = disparity.fixed.ptr<int16_t>(y);
    uint16_t* dst = out.ptr<uint16_t>(y);
    for (int x = 0; x < out.cols; ++x) dst[x] = src[x] < 0 ? 0 : static_cast<uint16_t>(src[x]);
  }
  return out;
}

DisparityMap TrustedOnly(const DisparityMap& disparity, double min_confidence) {
  if (disparity.confidence.empty() || min_confidence <= 0) return disparity;
  DisparityMap out = disparity;
  out.fixed = disparity.fixed.clone();
  const int threshold = static_cast<int>(std::ceil(255.0 * min_confidence));
  for (int y = 0; y < out.fixed.rows; ++y) {
    int16_t* d = out.fixed[y];
    const uint8_t* c = disparity.confidence[y];
    for (int x = 0; x < out.fixed.cols; ++x) {
      if (c[x] < threshold) d[x] = DisparityMap::kInvalid;
    }
  }
  return out;
}

// Colour scale: 0 px (far) to min_disparity + num_disparities (near) over TURBO; when the map
// does not carry its search range, its largest value is used instead.
cv::Mat3b ToColour(const DisparityMap& disparity) {
  if (disparity.fixed.empty()) return {};
  double top = static_cast<double>(disparity.min_disparity + disparity.num_disparities) *
               DisparityMap::kScale;
  if (top <= 0) {
    double max_value = 0;
    cv::minMaxLoc(disparity.fixed, nullptr, &max_value);
    top = std::max(1.0, max_value);
  }
  const double scale = 255.0 / top;
  cv::Mat1b grey(disparity.fixed.size());
  cv::Mat1b invalid(disparity.fixed.size());
  for (int y = 0; y < grey.rows; ++y) {
    const int16_t* src = disparity.fixed.ptr<int16_t>(y);
    uint8_t* dst = grey.ptr<uint8_t>(y);
    uint8_t* bad = invalid.ptr<uint8_t>(y);
    for (int x = 0; x < grey.cols; ++x) {
      bad[x] = src[x] < 0 ? 255 : 0;
      dst[x] = src[x] < 0 ? 0 : cv::saturate_cast<uint8_t>(src[x] * scale);
    }
  }
  cv::Mat3b colour;
  cv::applyColorMap(grey, colour, cv::COLORMAP_TURBO);
  colour.setTo(cv::Scalar::all(0), invalid);
  return colour;
}

}  // namespace stevi::stereo
