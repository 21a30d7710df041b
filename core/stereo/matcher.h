// Stereo matchers: SAD block matching and semi-global matching behind one interface.
#pragma once

#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/fields.h"
#include "core/stereo/block_matcher.h"
#include "core/stereo/dense_matcher.h"
#include "core/stereo/disparity.h"

namespace stevi::stereo {

// Sane upper bounds of the options: far beyond any rig we fly, small enough that buffers stay
// bounded.
inline constexpr int kMaxNumDisparities = 512;
inline constexpr int kMaxMinDisparity = 512;
inline constexpr int kMaxSpeckleRange = 1024;

// The fields both matchers have: the disparity search, the pre-filter cap, the uniqueness and
// speckle filters and the left padding (part of each options struct's field list).
template <class Self, class V>
void VisitSharedMatcherFields(Self& s, V& v) {
  using fields::Field;
  v.Number(s.num_disparities, Field("num_disparities", "pixels", "disparities searched")
                                  .MultipleOf(16)
                                  .AtMost(kMaxNumDisparities));
  v.Number(s.min_disparity,
           Field("min_disparity", "pixels", "smallest disparity searched").In(0, kMaxMinDisparity));
  v.Number(s.prefilter_cap, Field("prefilter_cap", "", "pre-filter output cap").In(1, 63));
  v.Number(s.uniqueness_ratio,
           Field("uniqueness_ratio", "percent", "margin of the best cost over the second best")
               .In(0, 100));
  v.Number(s.speckle_window_size,
           Field("speckle_window_size", "pixels", "largest speckle region; 0 disables the filter")
               .AtLeast(0));
  v.Number(s.speckle_range,
           Field("speckle_range", "pixels", "largest disparity variation within a speckle")
               .In(0, kMaxSpeckleRange));
  v.Flag(s.pad_left, Field("pad_left", "", "pad on the left so the leftmost columns match"));
}

// SAD block matching with every parameter the thesis tunes: cv::StereoBM's output, computed by
// SadBlockMatcher (block_matcher.h) for the x-Sobel pre-filter and by cv::StereoBM otherwise.
struct BlockMatchingOptions {
  // Pre-filter applied to both images before the SAD. The x-Sobel pre-filter is the default: it
  // gives fewer bad pixels on the Middlebury pairs than the normalized response (middlebury_test;
  // figures: core/stereo/README.md, "Measured").
  enum class PreFilter { kXSobel, kNormalizedResponse };
  PreFilter prefilter_type = PreFilter::kXSobel;
  // Normalized-response window, odd, 5..255 (validated always, used by kNormalizedResponse only).
  int prefilter_size = 9;
  // Pre-filter output cap, 1..63.
  int prefilter_cap = 31;
  // SAD window (block) size in pixels, odd, 5..255.
  int block_size = 15;
  // Number of disparities searched, a positive multiple of 16.
  int num_disparities = 64;
  // Smallest disparity searched, pixels, >= 0.
  int min_disparity = 0;
  // Minimum texture (sum of pre-filtered absolute values) for a match, >= 0.
  int texture_threshold = 10;
  // Margin in percent by which the best cost must beat the second best, 0..100.
  int uniqueness_ratio = 15;
  // Speckle filter: largest region (pixels) treated as speckle, 0 disables; and the largest
  // disparity variation within a region (pixels), >= 0. (cv::StereoBM itself takes the range in
  // 1/16 pixel; the matcher converts, so 2 here is OpenCV's usual 32.)
  int speckle_window_size = 100;
  int speckle_range = 2;
  // Pad the images on the left by min_disparity + num_disparities (+ block_size / 2) columns,
  // replicating the border, so that the leftmost columns get disparities too (OpenCV leaves them
  // unmatched otherwise); the padding is cropped from the result.
  bool pad_left = true;
  // Halo gate: a pixel keeps its disparity only when the mean |x-Sobel| of the left image over the
  // 5x5 window centred on it reaches this (the measure of SemiGlobalOptions::texture_threshold).
  // Block matching gives the flat sky within half a block of an object the object's disparity;
  // the gate trims that halo to about 2 px, so boxes fit their objects. 0 disables. The value is
  // for a pixel noise of 2 grey levels: each frame's gate scales it by its measured noise / 2
  // (EstimateNoiseSigma), down to 3.
  int local_texture_threshold = 14;

  std::vector<std::string> Validate() const;
  friend bool operator==(const BlockMatchingOptions&, const BlockMatchingOptions&) = default;

  static constexpr fields::ChoiceName<PreFilter> kPreFilterNames[] = {
      {PreFilter::kXSobel, "x_sobel"}, {PreFilter::kNormalizedResponse, "normalized_response"}};
  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Choice(s.prefilter_type, Field("prefilter_type", "", "pre-filter of both images"),
             kPreFilterNames);
    v.Number(s.prefilter_size,
             Field("prefilter_size", "pixels", "normalized-response window").Odd().In(5, 255));
    v.Number(s.block_size, Field("block_size", "pixels", "SAD window").Odd().In(5, 255));
    VisitSharedMatcherFields(s, v);
    v.Number(s.texture_threshold,
             Field("texture_threshold", "", "minimum window sum of the pre-filtered left image")
                 .AtLeast(0));
    v.Number(s.local_texture_threshold,
             Field("local_texture_threshold", "",
                   "halo gate: mean |x-Sobel| over 5x5 that keeps a disparity; 0 disables")
                 .AtLeast(0));
  }
};

// Semi-global matching (cv::StereoSGBM).
struct SemiGlobalOptions {
  enum class Mode { kSgbm5Path, kFull8Path, kThreeWay, kHH4 };

  // Matched block size, odd, 1..11.
  int block_size = 5;
  int num_disparities = 64;  // a positive multiple of 16
  int min_disparity = 0;     // >= 0
  // Smoothness penalties; 0 picks OpenCV's usual 8 * cn * block^2 and 32 * cn * block^2.
  // When given, P2 must be greater than P1.
  int p1 = 0;
  int p2 = 0;
  // Left-right check: maximum allowed difference in pixels, -1 disables.
  int disp12_max_diff = 1;
  int prefilter_cap = 63;     // 1..63
  int uniqueness_ratio = 10;  // 0..100
  int speckle_window_size = 100;
  int speckle_range = 2;  // pixels
  Mode mode = Mode::kThreeWay;
  // Pad on the left by min_disparity + num_disparities columns (border replicated), as above.
  bool pad_left = true;
  // Texture gate (cv::StereoSGBM has none; like cv::StereoBM's texture_threshold, but a mean, not
  // a window sum): after the matching, every pixel whose local texture is below this threshold is
  // set to DisparityMap::kInvalid. 0 disables the gate; must be >= 0.
  // Local texture: the mean over the max(block_size, 5)-square window centred on the pixel of
  // |x-Sobel| of the left image (3x3 kernel, each value capped at 255). Units: a horizontal ramp
  // of g grey levels per pixel gives 8 * g; Gaussian pixel noise of sigma s on a flat surface
  // gives about 2.8 * s (5.5 at s = 2).
  // The default 14 is for noisy imagery; use 0 for nearly noise-free imagery such as Middlebury.
  // Like the block matcher's gate, it is scaled by each frame's measured noise / 2 (down to 3).
  // Why 14, and its cost: core/stereo/README.md, "Texture gates" and "Measured".
  int texture_threshold = 14;

  std::vector<std::string> Validate() const;
  friend bool operator==(const SemiGlobalOptions&, const SemiGlobalOptions&) = default;

  static constexpr fields::ChoiceName<Mode> kModeNames[] = {{Mode::kSgbm5Path, "sgbm_5_path"},
                                                            {Mode::kFull8Path, "full_8_path"},
                                                            {Mode::kThreeWay, "three_way"},
                                                            {Mode::kHH4, "hh4"}};
  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Number(s.block_size, Field("block_size", "pixels", "matched block").Odd().In(1, 11));
    VisitSharedMatcherFields(s, v);
    v.Number(s.p1, Field("p1", "", "smoothness penalty; 0 = 8 * block_size^2").AtLeast(0));
    v.Number(s.p2, Field("p2", "", "> p1 when set; 0 = 32 * block_size^2").AtLeast(0));
    v.Number(s.disp12_max_diff,
             Field("disp12_max_diff", "pixels", "left-right check; -1 disables").AtLeast(-1));
    v.Choice(s.mode, Field("mode", "", "cv::StereoSGBM's mode"), kModeNames);
    v.Number(s.texture_threshold,
             Field("texture_threshold", "",
                   "texture gate: mean |x-Sobel| over the block that keeps a disparity; 0 disables")
                 .AtLeast(0));
  }
};

enum class MatcherKind { kBlockMatching, kSemiGlobal, kDense };

std::string_view MatcherKindName(MatcherKind kind);

struct MatcherOptions {
  MatcherKind kind = MatcherKind::kBlockMatching;
  BlockMatchingOptions block_matching;
  SemiGlobalOptions semi_global;
  // Census semi-global matching with a calibrated per-pixel confidence (dense_matcher.h).
  DenseMatcherOptions dense;

  // Validates the options of the selected kind only, with field names prefixed
  // ("block_matching.num_disparities: ...").
  std::vector<std::string> Validate() const;
  friend bool operator==(const MatcherOptions&, const MatcherOptions&) = default;

  static constexpr fields::ChoiceName<MatcherKind> kKindNames[] = {
      {MatcherKind::kBlockMatching, "block_matching"},
      {MatcherKind::kSemiGlobal, "semi_global"},
      {MatcherKind::kDense, "dense"}};
  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Choice(s.kind, Field("kind", "", "which matcher runs"), kKindNames);
    v.Nested(s.block_matching, Field("block_matching"));
    v.Nested(s.semi_global, Field("semi_global"));
    v.Nested(s.dense, Field("dense"));
  }
  int num_disparities() const;
  int min_disparity() const;
};

// The 1-sigma pixel noise of a grey image (grey levels), by Immerkaer's method with a median:
// robust to the edges and texture of a minority of the pixels.
double EstimateNoiseSigma(const cv::Mat& grey);

// Thread-compatible: one instance per thread (OpenCV matchers keep state between calls, and the
// padded images are reused buffers).
class DisparityMatcher {
 public:
  virtual ~DisparityMatcher() = default;
  // Computes the disparity of rectified 8-bit grey images of the same size. Unmatched pixels are
  // DisparityMap::kInvalid. Images smaller than the block give an all-unmatched map. Images of
  // another type, or of different sizes, are a programming error (cv::Exception).
  virtual DisparityMap Compute(const cv::Mat& left_rect, const cv::Mat& right_rect) = 0;
  virtual const MatcherOptions& options() const = 0;
};

// Builds the matcher for valid options (call Validate() first; invalid options are a bug).
std::unique_ptr<DisparityMatcher> MakeMatcher(const MatcherOptions& options);

// The columns block matching pads on the left when options.pad_left: cv::StereoBM's first valid
// column is min + num - 1 + block / 2, so that far plus one. 0 without padding.
int BlockMatchingLeftPad(const BlockMatchingOptions& options);

// What MakeMatcher gives the SAD matcher for these options (x-Sobel pre-filter), stripes aside
// (1 here; MakeMatcher sets them from the thread count).
SadBlockMatcherParams SadParamsFor(const BlockMatchingOptions& options);

}  // namespace stevi::stereo
