// DenseMatcher's confidence (dense_matcher.h, DenseCues): the fitted logistic model over the
// margin, the texture and the wide window's structure relative to the frame's noise, whether the
// value was filled and how its neighbours agree with it, times the structure prior.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>

#include <opencv2/imgproc.hpp>

#include "core/stereo/dense_matcher.h"
#include "core/stereo/dense_matcher_internal.h"
#include "core/stereo/matcher.h"
#include "core/stereo/vector_memory.h"

namespace stevi::stereo {

using internal::kMarginBins;
using internal::kZRange;
using internal::kZSteps;

// Fitted on the tuning split (Middlebury 2001 + KITTI training 000000..000002) by
// dense_real_test's DISABLED_FitConfidence (logistic regression, inlier = within 3 px).
const DenseConfidenceVector kDenseConfidenceWeights = {-1.6815, -1.2320, 0.5054,  -0.9779, 0.2015,
                                                       0.1324,  2.7250,  0.2905,  -0.5481, 1.1380,
                                                       -0.2069, 0.3728,  -0.2347, 0.3593,  0.0411};

DenseConfidenceVector DenseConfidenceFeatures(const DenseConfidenceInputs& in, int num_paths) {
  const double m =
      std::log1p(static_cast<double>(std::clamp(in.margin, 0, 255)) / std::max(1, num_paths));
  const double t = std::log(std::clamp(in.texture_ratio, 0.25, 16.0));
  const double s = std::log(std::clamp(in.structure_ratio, 0.5, 8.0));
  const double f = in.filled ? 1.0 : 0.0;
  const double a =
      static_cast<double>(std::clamp(in.agreement, 0, kDenseAgreementMax)) / kDenseAgreementMax;
  return {1.0, m, t, f, f * t, m * t, a, a * m, a * t, a * a, t * t, m * m, s, s * a, s * t};
}

namespace {

constexpr double kNoiseSobelMean = 2.76;  // mean |x-Sobel| of Gaussian noise of sigma 1

constexpr int kWideWindow = 15;  // DenseCues::structure's window
// The structure prior: the fitted model's confidence times a ramp of the structure ratio from 0 at
// kStructureFloor to 1 at kStructureFull (kDenseStructureFull). A flat noisy surface (a clear sky,
// ratio about 1) matches at random, and the smoothness then carries whatever disparity lies
// nearest into it: the values agree with their neighbours and the aggregated margins look sure,
// so no cue of the match itself can tell. Where there is no structure there is no information.
constexpr float kStructureFloor = 1.1f, kStructureFull = static_cast<float>(kDenseStructureFull);
// Filled values (left-right failures filled along the row) never go above this confidence.
constexpr int kFilledCap = 100;

// DenseCues::agreement of every pixel of `fixed`: eight pixels at a time in 16-byte vectors
// (SSE2 or NEON), the few at the borders one by one.
void CountAgreement(const cv::Mat1s& fixed, cv::Mat1b& agreement) {
  constexpr int kR = 2;                                 // the 5x5 window
  constexpr int16_t kTolerance = DisparityMap::kScale;  // 1 px
  typedef int16_t V8 __attribute__((vector_size(16)));
  const int w = fixed.cols, h = fixed.rows;
  agreement.create(fixed.size());
  const auto count_one = [&](int y, int x) {
    const int16_t d = fixed(y, x);
    if (d < 0) return 0;
    int n = 0;
    for (int yy = std::max(0, y - kR); yy <= std::min(h - 1, y + kR); ++yy) {
      for (int xx = std::max(0, x - kR); xx <= std::min(w - 1, x + kR); ++xx) {
        const int16_t v = fixed(yy, xx);
        n += (yy != y || xx != x) && v >= 0 && std::abs(v - d) <= kTolerance;
      }
    }
    return n;
  };
  const V8 tolerance = V8{} + kTolerance, zero = V8{};
  for (int y = 0; y < h; ++y) {
    uint8_t* out = agreement.ptr<uint8_t>(y);
    const int16_t* d = fixed.ptr<int16_t>(y);
    int x = 0;
    for (; x < std::min(w, kR); ++x) out[x] = static_cast<uint8_t>(count_one(y, x));
    if (y >= kR && y + kR < h) {
      for (; x + 8 + kR <= w; x += 8) {
        V8 centre, count = zero;
        simd::Load(centre, d + x);
        for (int dy = -kR; dy <= kR; ++dy) {
          const int16_t* n = fixed.ptr<int16_t>(y + dy) + x;
          for (int dx = -kR; dx <= kR; ++dx) {
            if (dx == 0 && dy == 0) continue;
            V8 v;
            simd::Load(v, n + dx);
            const V8 diff = centre - v;
            // Lanes are -1 where true: subtracting counts.
            count -= (v >= zero) & (diff <= tolerance) & (diff >= -tolerance);
          }
        }
        count &= (centre >= zero);
        for (int i = 0; i < 8; ++i) out[x + i] = static_cast<uint8_t>(count[i]);
      }
    }
    for (; x < w; ++x) out[x] = static_cast<uint8_t>(count_one(y, x));
  }
}

}  // namespace

// The confidence of every matched pixel: the fitted model over the margin, the texture and the
// wide window's structure relative to the frame's pixel noise, whether the value was filled and how
// its neighbours agree with it.
void DenseMatcher::Confidence(const cv::Mat& left, DisparityMap& out) {
  CountAgreement(out.fixed, cues_.agreement);
  cv::Sobel(left, gradient_, CV_16S, 1, 0, 3, 1.0, 0.0, cv::BORDER_REPLICATE);
  cv::convertScaleAbs(gradient_, abs_gradient_);
  cv::boxFilter(abs_gradient_, texture_sum_, CV_16U, cv::Size(5, 5), cv::Point(-1, -1), false,
                cv::BORDER_REPLICATE);
  cv::boxFilter(abs_gradient_, wide_sum_, CV_32S, cv::Size(kWideWindow, kWideWindow),
                cv::Point(-1, -1), false, cv::BORDER_REPLICATE);
  cues_.noise_sigma = EstimateNoiseSigma(left);
  const double noise_mean = kNoiseSobelMean * std::max(cues_.noise_sigma, 0.5);
  const float to_ratio = static_cast<float>(1.0 / (noise_mean * 25.0));
  const float wide_to_ratio = static_cast<float>(1.0 / (noise_mean * kWideWindow * kWideWindow));
  cues_.texture_ratio.create(left.size());
  cues_.structure.create(left.size());
  // The logs of the two texture ratios, tabulated by their window sums for this frame's noise
  // (the wide sum in steps of kWideStep grey levels: a 0.1 % change of the ratio at most).
  constexpr int kWideStep = 16;
  texture_log_.resize(25 * 255 + 1);
  for (size_t i = 0; i < texture_log_.size(); ++i) {
    texture_log_[i] = std::log(std::clamp(static_cast<float>(i) * to_ratio, 0.25f, 16.0f));
  }
  wide_log_.resize(kWideWindow * kWideWindow * 255 / kWideStep + 1);
  for (size_t i = 0; i < wide_log_.size(); ++i) {
    wide_log_[i] = std::log(
        std::clamp((static_cast<float>(i) + 0.5f) * kWideStep * wide_to_ratio, 0.5f, 8.0f));
  }
  std::array<float, kDenseConfidenceFeatures> w;
  for (int i = 0; i < kDenseConfidenceFeatures; ++i)
    w[i] = static_cast<float>(kDenseConfidenceWeights[i]);
  const float filled_cap = kFilledCap;
  for (int y = 0; y < left.rows; ++y) {
    const uint16_t* tex = texture_sum_.ptr<uint16_t>(y);
    const int32_t* wide = wide_sum_.ptr<int32_t>(y);
    const int16_t* d = out.fixed.ptr<int16_t>(y);
    const uint16_t* margin = cues_.margin.ptr<uint16_t>(y);
    const uint8_t* filled = cues_.filled.ptr<uint8_t>(y);
    const uint8_t* agree = cues_.agreement.ptr<uint8_t>(y);
    float* ratio = cues_.texture_ratio.ptr<float>(y);
    float* structure = cues_.structure.ptr<float>(y);
    uint8_t* conf = out.confidence.ptr<uint8_t>(y);
    for (int x = 0; x < left.cols; ++x) {
      ratio[x] = static_cast<float>(tex[x]) * to_ratio;
      structure[x] = static_cast<float>(wide[x]) * wide_to_ratio;
    }
    for (int x = 0; x < left.cols; ++x) {
      if (d[x] < 0) {
        conf[x] = 0;
        continue;
      }
      // DenseConfidenceFeatures, term by term, in floats.
      const float m = margin_log_[std::min<int>(kMarginBins - 1, margin[x])];
      const float t = texture_log_[tex[x]];
      const float s = wide_log_[static_cast<size_t>(wide[x] / kWideStep)];
      const float f = filled[x] ? 1.0f : 0.0f;
      const float a = static_cast<float>(agree[x]) * (1.0f / kDenseAgreementMax);
      const float z = w[0] + w[1] * m + w[2] * t + w[3] * f + w[4] * f * t + w[5] * m * t +
                      w[6] * a + w[7] * a * m + w[8] * a * t + w[9] * a * a + w[10] * t * t +
                      w[11] * m * m + w[12] * s + w[13] * s * a + w[14] * s * t;
      const auto i = static_cast<int>(
          (std::clamp(z, -static_cast<float>(kZRange), static_cast<float>(kZRange)) + kZRange) *
              kZSteps +
          0.5f);
      const float prior = std::clamp(
          (structure[x] - kStructureFloor) / (kStructureFull - kStructureFloor), 0.0f, 1.0f);
      const auto c = static_cast<uint8_t>(
          std::max(1.0f, std::round(logistic_[static_cast<size_t>(i)] * prior)));
      conf[x] = filled[x] ? static_cast<uint8_t>(std::min<float>(c, filled_cap)) : c;
    }
  }
}

}  // namespace stevi::stereo
