// SAD block matching with the output of cv::StereoBM (x-Sobel pre-filter), bit for bit, at a
// fraction of its cost: AVX2 when the CPU has it, a portable vector path otherwise.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace stevi::stereo {

struct SadBlockMatcherParams {
  int num_disparities = 64;       // a positive multiple of 16
  int min_disparity = 0;          // pixels
  int block_size = 15;            // SAD window in pixels, odd, 5..255
  int prefilter_cap = 31;         // x-Sobel pre-filter output cap, 1..63
  int texture_threshold = 10;     // >= 0: minimum window sum of |pre-filtered left - cap|
  int uniqueness_ratio = 15;      // percent, 0..100; 0 disables the test
  int speckle_window_size = 100;  // pixels, >= 0; 0 disables the speckle filter
  int speckle_range = 32;         // 1/16 px, as cv::StereoBM::setSpeckleRange takes it; >= 0
  // Horizontal stripes matched at once, each on a thread of its own (the caller's and
  // stripes - 1 more), 1..8; fewer when the image is short. The output does not depend on it.
  int stripes = 1;

  // Problems as "field: must be ... (got v)"; empty when valid.
  std::vector<std::string> Validate() const;
};

// Thread-compatible: one instance per thread. Runs on the caller's thread, plus stripes - 1
// threads of its own during Compute (no cv::parallel_for_).
class SadBlockMatcher {
 public:
  // Invalid params (see Validate()) are a programming error: throws cv::Exception.
  explicit SadBlockMatcher(SadBlockMatcherParams p);

  // left, right: CV_8UC1, the same size. disparity: CV_16SC1 of that size in 1/16 px, exactly what
  // cv::StereoBM (PREFILTER_XSOBEL, these parameters, disp12MaxDiff -1, no ROI, one thread)
  // computes, unmatched pixels being (min_disparity - 1) * 16. Where cv::StereoBM has no defined
  // output the map is all unmatched: images not larger than the block (cv::StereoBM throws), and
  // images too narrow for any valid column (cv::StereoBM leaves its output uninitialised).
  // Buffers are reused: after the first call at a size, Compute allocates nothing.
  void Compute(const cv::Mat& left, const cv::Mat& right, cv::Mat& disparity);

  const SadBlockMatcherParams& params() const { return p_; }

  // Test hook, process-wide: true makes every matcher take the portable path even on AVX2 CPUs.
  static void ForcePortable(bool force);
  // Whether Compute takes the AVX2 path (the CPU has AVX2 and ForcePortable is off).
  static bool UsesAvx2();

 private:
  // The vector kernel over the valid rectangle [x0, x1) x [y0, y1) of the pre-filtered images, in
  // row stripes on threads of their own.
  void RunKernel(int x0, int x1, int y0, int y1, cv::Mat& disparity);
  // OpenCV's overrun past the row end (block_matcher.cc's top comment): columns w .. x_end - 1 of
  // the last matched row y1 - 1, computed one by one into the next row's first pixels.
  void ComputeOverrun(int x_end, int y1, cv::Mat& disparity);

  SadBlockMatcherParams p_;
  cv::Mat left_filtered_, right_filtered_;  // CV_8UC1 pre-filtered images
  cv::Mat right_wide_;                      // CV_16SC1 copy of right_filtered_ (16-bit kernel)
  std::vector<int> left_col_, right_col_;   // per window column: clamped image columns
  std::vector<int> texture_col_;            // per stripe and window column: texture column sums
  std::vector<int16_t> cost16_;             // per stripe: column sums then the row's SADs, 16-bit
  std::vector<int32_t> cost32_;             // the same, 32-bit kernel (large blocks and caps)
  std::vector<int> sad_scalar_;             // SADs of the few pixels computed one by one
  cv::Mat speckle_buf_;
};

}  // namespace stevi::stereo
