// The disparity map shared by matchers, detectors and the snapshot.
#pragma once

#include <cstdint>
#include <optional>

#include <opencv2/core.hpp>

namespace stevi::stereo {

// Fixed-point disparity of the rectified left image: value = disparity_px * kScale.
// x_right = x_left - d, d >= 0. Any negative value means "no disparity" (unmatched).
struct DisparityMap {
  static constexpr int kScale = 16;
  static constexpr int16_t kInvalid = -1;

  cv::Mat1s fixed;        // CV_16SC1, the left image's size
  int min_disparity = 0;  // search range used, pixels
  int num_disparities = 0;
  // The matcher's window (pixels): its errors are correlated over about this distance.
  int block_size = 1;
  // Per pixel, how far the disparity can be trusted: round(255 x P(inlier)), the probability that
  // the value lies within its noise of the truth (0 where unmatched). Empty when the matcher gives
  // none (block matching, cv::StereoSGBM); consumers then treat every matched pixel alike.
  cv::Mat1b confidence;

  bool empty() const { return fixed.empty(); }
  // Disparity in pixels at (x, y), or nullopt when unmatched.
  std::optional<float> At(int x, int y) const {
    const int16_t v = fixed(y, x);
    if (v < 0) return std::nullopt;
    return static_cast<float>(v) / kScale;
  }
};

// Median of the valid disparities (pixels) of `disparity` at the pixels where
// labels(y, x) == label, inside `box` (the label's bounding box, to keep it cheap).
// Values below min_disparity_px are not counted as valid. nullopt when there are none.
// Exact on the fixed-point values (a histogram); for an even count, the mean of the two middle
// values.
// `valid_count`, when given, receives the number of valid disparities used.
std::optional<double> MedianDisparityInMask(const DisparityMap& disparity, const cv::Mat1i& labels,
                                            int label, const cv::Rect& box, double min_disparity_px,
                                            int* valid_count = nullptr);

// The map with every disparity whose confidence is below min_confidence (a probability, 0..1)
// unmatched, for consumers that read no confidence. A map without confidence, or min_confidence
// <= 0, is returned as it is (sharing its pixels).
DisparityMap TrustedOnly(const DisparityMap& disparity, double min_confidence);

// 16-bit image of the raw fixed-point disparity (value = d * 16, 0 = unmatched), for PNG output.
cv::Mat1w ToFixedPoint16U(const DisparityMap& disparity);

// 8-bit colour-mapped picture of the disparity (near = warm), black where unmatched.
cv::Mat3b ToColour(const DisparityMap& disparity);

}  // namespace stevi::stereo
