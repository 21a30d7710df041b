// The dense matcher: census semi-global matching with a left-right (uniqueness) check, sub-pixel
// refinement, hole filling along the row, and a calibrated per-pixel confidence.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/fields.h"
#include "core/stereo/disparity.h"

namespace stevi::stereo {

// Census window (pixels, square): 5x5, 24 comparisons, so a matching cost is 0..24.
inline constexpr int kDenseCensusWindow = 5;
inline constexpr int kDenseMaxCost = 24;
// The path costs are 8-bit: max cost + p1 + p2 must fit below 256.
inline constexpr int kDenseMaxPenaltySum = 255 - kDenseMaxCost;

struct DenseMatcherOptions {
  int num_disparities = 64;  // a positive multiple of 16
  int min_disparity = 0;     // >= 0
  // Smoothness penalties in census bits (a cost is 0..24): p1 for a one-pixel disparity step, p2
  // for larger steps. p1 < p2, p1 + p2 <= 231 (8-bit path costs).
  int p1 = 6;
  int p2 = 48;
  // Aggregation paths: 4 (left-to-right, top, top-left, top-right: one raster pass) or 5 (plus
  // right-to-left, on the same row).
  int num_paths = 5;
  // Left-right check: a pixel whose right-image pixel is claimed by another left pixel with a lower
  // aggregated cost at a disparity more than this many pixels away is an occlusion or a mismatch.
  // -1 disables.
  int lr_max_diff = 1;
  // Fill pixels that fail the left-right check with the background (smaller) disparity of their
  // nearest measured neighbours along the row; their confidence stays low. Without it they are
  // unmatched.
  bool fill_holes = true;

  std::vector<std::string> Validate() const;
  friend bool operator==(const DenseMatcherOptions&, const DenseMatcherOptions&) = default;

  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Number(s.num_disparities,
             Field("num_disparities", "pixels", "disparities searched").MultipleOf(16).In(16, 256));
    v.Number(s.min_disparity,
             Field("min_disparity", "pixels", "smallest disparity searched").In(0, 512));
    v.Number(s.p1, Field("p1", "census bits", "penalty of a one-pixel disparity step").In(1, 100));
    v.Number(s.p2, Field("p2", "census bits", "penalty of a larger step, > p1").In(2, 230));
    v.Number(s.num_paths, Field("num_paths", "", "aggregation paths, 4 or 5").In(4, 5));
    v.Number(s.lr_max_diff,
             Field("lr_max_diff", "pixels", "left-right check tolerance; -1 disables").In(-1, 64));
    v.Flag(s.fill_holes,
           Field("fill_holes", "", "fill left-right failures with the background disparity"));
  }
};

// The cues behind the confidence of the last Compute, per pixel of the left image (for the
// calibration and the tests).
struct DenseCues {
  // Second-best minus best aggregated cost (the second best at least 2 px from the best), summed
  // over the paths; 0 where unmatched.
  cv::Mat1w margin;
  // Local texture (mean |x-Sobel| over 5x5) over what pixel noise alone gives (2.76 x sigma).
  cv::Mat1f texture_ratio;
  // 1 where the disparity was filled along the row (failed the left-right check), else 0.
  cv::Mat1b filled;
  // The texture ratio over a wide window (15x15): whether there is any structure around a pixel.
  // A flat noisy surface (a clear sky) has about 1 and matches at random; real low-texture
  // surfaces (road, walls) still hold some structure, and the smoothness carries them.
  cv::Mat1f structure;
  // How many of the 24 other pixels of the 5x5 window around a matched pixel are matched within
  // 1 px of it (0..24; 0 where unmatched): a surface agrees with itself, a random match in a flat
  // noisy sky does not.
  cv::Mat1b agreement;
  double noise_sigma = 0;  // the frame's measured pixel noise (EstimateNoiseSigma)
};

// The confidence model: P(inlier) = 1 / (1 + exp(-w . features)), inlier = within 1 px of the
// truth, times the structure prior. Fitted on the tuning split, real pairs and synthetic scenes
// (dense_real_test, DISABLED_FitConfidence).
struct DenseConfidenceInputs {
  int margin = 0;              // DenseCues::margin, capped at 255
  double texture_ratio = 0;    // DenseCues::texture_ratio
  bool filled = false;         // DenseCues::filled
  int agreement = 0;           // DenseCues::agreement
  double structure_ratio = 0;  // DenseCues::structure
};
inline constexpr int kDenseConfidenceFeatures = 15;
// The fitted model speaks alone where DenseCues::structure is at least this; below it a prior
// lowers the confidence to 0 at 1.1 (dense_confidence.cc).
inline constexpr double kDenseStructureFull = 1.5;
inline constexpr int kDenseAgreementMax = 24;
using DenseConfidenceVector = std::array<double, kDenseConfidenceFeatures>;
DenseConfidenceVector DenseConfidenceFeatures(const DenseConfidenceInputs& in, int num_paths);
extern const DenseConfidenceVector kDenseConfidenceWeights;

// Thread-compatible (buffers are members; after the first call at a size, Compute allocates
// only its output).
class DenseMatcher {
 public:
  explicit DenseMatcher(const DenseMatcherOptions& options);
  ~DenseMatcher();
  DenseMatcher(const DenseMatcher&) = delete;
  DenseMatcher& operator=(const DenseMatcher&) = delete;

  // Rectified 8-bit grey images of the same size. Images smaller than the census window give an
  // all-unmatched map. The map carries `confidence`.
  DisparityMap Compute(const cv::Mat& left_rect, const cv::Mat& right_rect);
  const DenseMatcherOptions& options() const { return options_; }
  const DenseCues& last_cues() const { return cues_; }
  // The vector code: the widest the CPU has (AVX-512, AVX2, else the portable 16-byte vectors),
  // or a narrower one for the tests and benchmarks. Every path gives the same map.
  enum class SimdPath { kBest, kAvx2, kPortable };
  void set_simd_path(SimdPath path) { path_ = path; }

  struct Buffers;

 private:
  void Confidence(const cv::Mat& left, DisparityMap& out);

  DenseMatcherOptions options_;
  SimdPath path_ = SimdPath::kBest;
  std::unique_ptr<Buffers> buffers_;
  DenseCues cues_;
  cv::Mat gradient_, abs_gradient_, texture_sum_, wide_sum_;
  // The model's terms tabulated: log1p(margin / paths) by margin, and the logistic by z.
  std::vector<float> margin_log_;
  std::vector<uint8_t> logistic_;
  std::vector<float> texture_log_, wide_log_;  // per frame: log ratio by window sum
};

}  // namespace stevi::stereo
