#include "core/stereo/matcher.h"

#include <algorithm>
#include <array>
#include <cstdint>
#include <utility>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/error.h"
#include "core/stereo/block_matcher.h"
#include "core/stereo/dense_matcher.h"

namespace stevi::stereo {
namespace {

std::vector<std::string> Prefixed(std::vector<std::string> problems, const std::string& prefix) {
  for (std::string& p : problems) p = prefix + p;
  return problems;
}

int AutoP1(int block_size) { return 8 * block_size * block_size; }
int AutoP2(int block_size) { return 32 * block_size * block_size; }

int ToOpenCvMode(SemiGlobalOptions::Mode mode) {
  switch (mode) {
    case SemiGlobalOptions::Mode::kSgbm5Path: return cv::StereoSGBM::MODE_SGBM;
    case SemiGlobalOptions::Mode::kFull8Path: return cv::StereoSGBM::MODE_HH;
    case SemiGlobalOptions::Mode::kThreeWay: return cv::StereoSGBM::MODE_SGBM_3WAY;
    case SemiGlobalOptions::Mode::kHH4: return cv::StereoSGBM::MODE_HH4;
  }
  return cv::StereoSGBM::MODE_SGBM_3WAY;
}

// The texture gates' thresholds are given for this pixel noise (grey levels, 1-sigma) and scale
// with the noise measured in each frame, down to kMinGateThreshold.
constexpr double kGateReferenceNoise = 2.0;
constexpr int kMinGateThreshold = 3;

// Smallest window of the SGBM texture gate: with smaller blocks (1, 3) the mean of |x-Sobel| over
// the block would follow the pixel noise too closely to separate it from texture.
constexpr int kMinTextureWindow = 5;

// The texture gate of SemiGlobalOptions::texture_threshold: a pixel is matched only when the mean
// of |x-Sobel| of the left image over the window centred on it reaches the threshold.
struct TextureGate {
  int threshold = 0;  // 0: no gate
  int window = 1;     // odd
};

// Every matcher behind one implementation: optional left padding, compute, crop, the optional
// texture gate, and normalisation of every unmatched value to DisparityMap::kInvalid. The raw map
// comes from an OpenCV matcher or from SadBlockMatcher (cv::StereoBM's output, faster).
class OpenCvMatcher final : public DisparityMatcher {
 public:
  OpenCvMatcher(MatcherOptions options, cv::Ptr<cv::StereoMatcher> matcher, int pad_columns,
                int block_size, TextureGate gate = {})
      : options_(std::move(options)),
        matcher_(std::move(matcher)),
        pad_columns_(pad_columns),
        block_size_(block_size),
        gate_(gate) {}
  OpenCvMatcher(MatcherOptions options, std::unique_ptr<SadBlockMatcher> matcher, int pad_columns,
                int block_size, TextureGate gate = {})
      : options_(std::move(options)),
        sad_(std::move(matcher)),
        pad_columns_(pad_columns),
        block_size_(block_size),
        gate_(gate) {}

  DisparityMap Compute(const cv::Mat& left_rect, const cv::Mat& right_rect) override {
    CV_Assert(left_rect.type() == CV_8UC1 && right_rect.type() == CV_8UC1);
    CV_Assert(left_rect.size() == right_rect.size());

    DisparityMap out;
    out.min_disparity = options_.min_disparity();
    out.num_disparities = options_.num_disparities();
    out.block_size = block_size_;
    if (left_rect.empty()) return out;
    out.fixed.create(left_rect.size());
    const int width = left_rect.cols + pad_columns_;
    if (left_rect.rows < block_size_ || width < block_size_) {
      out.fixed.setTo(DisparityMap::kInvalid);
      return out;
    }

    const cv::Mat* left = &left_rect;
    const cv::Mat* right = &right_rect;
    if (pad_columns_ > 0) {
      // Member buffers: copyMakeBorder reallocates only when the size changes.
      cv::copyMakeBorder(left_rect, left_padded_, 0, 0, pad_columns_, 0, cv::BORDER_REPLICATE);
      cv::copyMakeBorder(right_rect, right_padded_, 0, 0, pad_columns_, 0, cv::BORDER_REPLICATE);
      left = &left_padded_;
      right = &right_padded_;
    }
    if (sad_ != nullptr) {
      sad_->Compute(*left, *right, raw_);
    } else {
      matcher_->compute(*left, *right, raw_);
    }
    CV_Assert(raw_.type() == CV_16SC1 && raw_.size() == left->size());

    // Crop the padding and map every value below the search range (OpenCV's (min - 1) * 16
    // marker, speckles, negatives) to kInvalid in one pass.
    const int16_t floor_fixed = static_cast<int16_t>(out.min_disparity * DisparityMap::kScale);
    if (gate_.threshold <= 0) {
      for (int y = 0; y < out.fixed.rows; ++y) {
        const int16_t* src = raw_.ptr<int16_t>(y) + pad_columns_;
        int16_t* dst = out.fixed.ptr<int16_t>(y);
        for (int x = 0; x < out.fixed.cols; ++x) {
          dst[x] = src[x] < floor_fixed ? DisparityMap::kInvalid : src[x];
        }
      }
      return out;
    }

    // Texture gate, in the same pass: the window sum of |x-Sobel| against threshold * area
    // (exact integer form of "window mean >= threshold"). The threshold is given for the pixel
    // noise it was chosen at (kGateReferenceNoise) and follows the frame's own noise: a noisy
    // sensor's sky must not pass for texture, nor a clean sensor's faint object fail.
    ComputeTextureSum(left_rect);
    const double noise = EstimateNoiseSigma(left_rect);
    const int threshold =
        std::max(kMinGateThreshold,
                 static_cast<int>(std::lround(gate_.threshold * noise / kGateReferenceNoise)));
    last_gate_threshold_ = threshold;
    const int64_t min_sum = int64_t{threshold} * gate_.window * gate_.window;
    for (int y = 0; y < out.fixed.rows; ++y) {
      const int16_t* src = raw_.ptr<int16_t>(y) + pad_columns_;
      const TextureSum* texture = texture_sum_.ptr<TextureSum>(y);
      int16_t* dst = out.fixed.ptr<int16_t>(y);
      for (int x = 0; x < out.fixed.cols; ++x) {
        dst[x] = src[x] < floor_fixed || texture[x] < min_sum ? DisparityMap::kInvalid : src[x];
      }
    }
    return out;
  }

  const MatcherOptions& options() const override { return options_; }
  int last_gate_threshold() const { return last_gate_threshold_; }

 private:
  int last_gate_threshold_ = 0;
  // texture_sum_ (CV_16UC1, the left image's size) = sum over the gate window of
  // min(|x-Sobel|, 255) of `left`. The border is replicated, so the first and last columns get a
  // one-sided derivative rather than 0. Member buffers: allocated again only on a size change.
  // Window sums of |d/dx| (saturated to 255): 16 bits hold them for windows up to 16x16
  // (256 * 255 < 65536), and a 16-bit box filter costs less than a 32-bit one
  // (core/stereo/README.md, "Measured").
  using TextureSum = uint16_t;
  static constexpr int kMax16BitWindow = 16;

  void ComputeTextureSum(const cv::Mat& left) {
    cv::Sobel(left, gradient_, CV_16S, 1, 0, 3, 1.0, 0.0, cv::BORDER_REPLICATE);
    cv::convertScaleAbs(gradient_, abs_gradient_);
    CV_Assert(gate_.window <= kMax16BitWindow);
    cv::boxFilter(abs_gradient_, texture_sum_, CV_16U, cv::Size(gate_.window, gate_.window),
                  cv::Point(-1, -1), /*normalize=*/false, cv::BORDER_REPLICATE);
  }

  MatcherOptions options_;
  cv::Ptr<cv::StereoMatcher> matcher_;  // or
  std::unique_ptr<SadBlockMatcher> sad_;
  int pad_columns_;
  int block_size_;
  TextureGate gate_;
  cv::Mat left_padded_, right_padded_, raw_;
  cv::Mat gradient_, abs_gradient_, texture_sum_;
};

// The dense matcher behind the interface (it pads, crops and gates nothing: it matches every
// column and says how far each value can be trusted).
class DenseAdapter final : public DisparityMatcher {
 public:
  explicit DenseAdapter(MatcherOptions options)
      : options_(std::move(options)), matcher_(options_.dense) {}
  DisparityMap Compute(const cv::Mat& left_rect, const cv::Mat& right_rect) override {
    return matcher_.Compute(left_rect, right_rect);
  }
  const MatcherOptions& options() const override { return options_; }

 private:
  MatcherOptions options_;
  DenseMatcher matcher_;
};

}  // namespace

std::vector<std::string> BlockMatchingOptions::Validate() const { return fields::Check(*this); }

std::vector<std::string> SemiGlobalOptions::Validate() const {
  std::vector<std::string> problems = fields::Check(*this);
  if (p1 >= 0 && p2 >= 0 && (p1 != 0 || p2 != 0)) {
    // Compare the penalties actually used: 0 stands for the automatic value.
    const int used_p1 = p1 != 0 ? p1 : AutoP1(block_size);
    const int used_p2 = p2 != 0 ? p2 : AutoP2(block_size);
    if (used_p2 <= used_p1) {
      if (p2 == 0) {
        problems.push_back("p1: must be less than the automatic p2 = 32 * block_size^2 = " +
                           std::to_string(used_p2) + Got(p1));
      } else if (p1 == 0) {
        problems.push_back("p2: must be greater than the automatic p1 = 8 * block_size^2 = " +
                           std::to_string(used_p1) + Got(p2));
      } else {
        problems.push_back("p2: must be greater than p1 (got p1=" + std::to_string(p1) +
                           ", p2=" + std::to_string(p2) + ")");
      }
    }
  }
  return problems;
}
std::string_view MatcherKindName(MatcherKind kind) {
  switch (kind) {
    case MatcherKind::kBlockMatching: return "block_matching";
    case MatcherKind::kSemiGlobal: return "semi_global";
    case MatcherKind::kDense: return "dense";
  }
  return "unknown";
}

std::vector<std::string> MatcherOptions::Validate() const {
  switch (kind) {
    case MatcherKind::kBlockMatching: return Prefixed(block_matching.Validate(), "block_matching.");
    case MatcherKind::kSemiGlobal: return Prefixed(semi_global.Validate(), "semi_global.");
    case MatcherKind::kDense: return Prefixed(dense.Validate(), "dense.");
  }
  return {"kind: unknown matcher kind" + Got(static_cast<int>(kind))};
}

int MatcherOptions::num_disparities() const {
  switch (kind) {
    case MatcherKind::kSemiGlobal: return semi_global.num_disparities;
    case MatcherKind::kDense: return dense.num_disparities;
    case MatcherKind::kBlockMatching: break;
  }
  return block_matching.num_disparities;
}

int MatcherOptions::min_disparity() const {
  switch (kind) {
    case MatcherKind::kSemiGlobal: return semi_global.min_disparity;
    case MatcherKind::kDense: return dense.min_disparity;
    case MatcherKind::kBlockMatching: break;
  }
  return block_matching.min_disparity;
}

int BlockMatchingLeftPad(const BlockMatchingOptions& o) {
  return o.pad_left ? o.min_disparity + o.num_disparities + o.block_size / 2 : 0;
}

SadBlockMatcherParams SadParamsFor(const BlockMatchingOptions& o) {
  SadBlockMatcherParams params;
  params.num_disparities = o.num_disparities;
  params.min_disparity = o.min_disparity;
  params.block_size = o.block_size;
  params.prefilter_cap = o.prefilter_cap;
  params.texture_threshold = o.texture_threshold;
  params.uniqueness_ratio = o.uniqueness_ratio;
  params.speckle_window_size = o.speckle_window_size;
  // Filtered on the fixed-point map: the range in 1/16 pixel.
  params.speckle_range = o.speckle_range * DisparityMap::kScale;
  return params;
}

double EstimateNoiseSigma(const cv::Mat& grey) {
  CV_Assert(grey.type() == CV_8UC1);
  if (grey.rows < 3 || grey.cols < 3) return 0.0;
  // Immerkaer's operator (the difference of two Laplacians) cancels any local plane; its response
  // to i.i.d. noise of sigma s has sigma 6 s. The median of its magnitude over every second pixel
  // of every eighth row ignores the edges and texture that a minority of the pixels hold.
  std::array<int, 4 * 255 * 4 + 1> histogram{};
  int count = 0;
  for (int y = 1; y + 1 < grey.rows; y += 8) {
    const uchar* a = grey.ptr<uchar>(y - 1);
    const uchar* b = grey.ptr<uchar>(y);
    const uchar* c = grey.ptr<uchar>(y + 1);
    for (int x = 1; x + 1 < grey.cols; x += 2) {
      const int r = a[x - 1] - 2 * a[x] + a[x + 1] - 2 * b[x - 1] + 4 * b[x] - 2 * b[x + 1] +
                    c[x - 1] - 2 * c[x] + c[x + 1];
      ++histogram[std::abs(r)];
      ++count;
    }
  }
  int seen = 0;
  for (size_t v = 0; v < histogram.size(); ++v) {
    seen += histogram[v];
    if (2 * seen >= count) {
      // |r| is quantised to whole grey levels: interpolate within the median's bin.
      const double below = seen - histogram[v];
      const double median = v - 0.5 + (0.5 * count - below) / std::max(1, histogram[v]);
      return 1.4826 * std::max(0.0, median) / 6.0;
    }
  }
  return 0.0;
}

std::unique_ptr<DisparityMatcher> MakeMatcher(const MatcherOptions& options) {
  CV_Assert(options.Validate().empty());
  if (options.kind == MatcherKind::kDense) return std::make_unique<DenseAdapter>(options);
  if (options.kind == MatcherKind::kSemiGlobal) {
    const SemiGlobalOptions& o = options.semi_global;
    // Grey input: cn = 1 in OpenCV's usual 8 * cn * block^2 and 32 * cn * block^2.
    const int p1 = o.p1 != 0 ? o.p1 : AutoP1(o.block_size);
    const int p2 = o.p2 != 0 ? o.p2 : AutoP2(o.block_size);
    cv::Ptr<cv::StereoSGBM> sgbm =
        cv::StereoSGBM::create(o.min_disparity, o.num_disparities, o.block_size, p1, p2,
                               o.disp12_max_diff, o.prefilter_cap, o.uniqueness_ratio,
                               o.speckle_window_size, o.speckle_range, ToOpenCvMode(o.mode));
    const int pad = o.pad_left ? o.min_disparity + o.num_disparities : 0;
    const TextureGate gate{o.texture_threshold, std::max(o.block_size, kMinTextureWindow)};
    return std::make_unique<OpenCvMatcher>(options, std::move(sgbm), pad, o.block_size, gate);
  }
  const BlockMatchingOptions& o = options.block_matching;
  const int pad = BlockMatchingLeftPad(o);
  const TextureGate gate{o.local_texture_threshold, kMinTextureWindow};
  if (o.prefilter_type == BlockMatchingOptions::PreFilter::kXSobel) {
    // cv::StereoBM's output, bit for bit (block_matcher_test), in less time: this Debian
    // OpenCV build runs StereoBM's SIMD code at its SSE2 baseline.
    SadBlockMatcherParams params = SadParamsFor(o);
    // Row stripes on a thread each, as many as one OpenCV call may use (cv::getNumThreads(), at
    // most 4), read when the matcher is built. The server sets that to 1 when its workers already
    // keep every core busy with a frame each: stripes on top of them cost throughput and did not
    // shorten the latency. With one worker, or offline, a frame's matching spreads over the cores.
    // Figures: core/stereo/README.md, "Measured".
    params.stripes = std::clamp(cv::getNumThreads(), 1, 4);
    return std::make_unique<OpenCvMatcher>(options, std::make_unique<SadBlockMatcher>(params), pad,
                                           o.block_size, gate);
  }
  cv::Ptr<cv::StereoBM> bm = cv::StereoBM::create(o.num_disparities, o.block_size);
  bm->setPreFilterType(o.prefilter_type == BlockMatchingOptions::PreFilter::kXSobel
                           ? cv::StereoBM::PREFILTER_XSOBEL
                           : cv::StereoBM::PREFILTER_NORMALIZED_RESPONSE);
  bm->setPreFilterSize(o.prefilter_size);
  bm->setPreFilterCap(o.prefilter_cap);
  bm->setMinDisparity(o.min_disparity);
  bm->setTextureThreshold(o.texture_threshold);
  bm->setUniquenessRatio(o.uniqueness_ratio);
  bm->setSpeckleWindowSize(o.speckle_window_size);
  // cv::StereoBM filters speckles on the fixed-point map: its range is in 1/16 pixel.
  bm->setSpeckleRange(o.speckle_range * DisparityMap::kScale);
  return std::make_unique<OpenCvMatcher>(options, std::move(bm), pad, o.block_size, gate);
}

}  // namespace stevi::stereo
