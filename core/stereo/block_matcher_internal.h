// Internal to core/stereo: what SadBlockMatcher (block_matcher.cc) and its vector kernels
// (block_matcher_kernels.cc) share: one kernel call's job, the kernel for a cost width, and
// OpenCV's sub-pixel interpolation. Not part of the library's interface.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdlib>

namespace stevi::stereo::internal {

// OpenCV's fixed-point disparity of the best index with its interpolation and rounding.
template <typename T>
[[gnu::always_inline]] inline int16_t Interpolated(const T* sad, int best, int nd, int max_disp) {
  const int base = (max_disp - best) * 256;
  if (best <= 0 || best >= nd - 1) return static_cast<int16_t>((base + 15) >> 4);
  const int p = sad[best + 1];
  const int n = sad[best - 1];
  const int den = p + n - 2 * static_cast<int>(sad[best]) + std::abs(p - n);
  // (p - n) * 256 / den truncated, as C's integer division (the double quotient is exact enough:
  // |quotient| <= 128 and its fraction is at least 1 / den away from the next integer).
  const int frac = den != 0 ? static_cast<int>(static_cast<double>((p - n) * 256) / den) : 0;
  return static_cast<int16_t>((base + frac + 15) >> 4);
}

// One call of the vector kernel: the valid rectangle of one image pair.
struct Job {
  const uint8_t* left;           // pre-filtered
  const void* right;             // P: int16_t (pre-widened, for 16-bit costs) or uint8_t
  size_t left_step, right_step;  // elements
  int16_t* disp;
  size_t disp_step;    // elements
  int y0, y1, x0, x1;  // rows and columns matched
  int half;            // block_size / 2
  int nd, max_disp;
  int cap, texture_threshold, uniqueness_ratio;
  int16_t filtered;
  // Window column jj is image column x0 - half + jj: its clamped left column and the right column
  // of index 0.
  const int* left_col;
  const int* right_col;
  int* texture_col;  // 1 + window columns: a zero column, then the columns' texture sums
  void* cost;        // T[nd] SADs of the current pixel, T[nd] zeros, then T[nd] per window column
};

// A kernel: matches the rows [y0, y1) of its job.
using Kernel = void (*)(const Job&);

// The kernel for 16-bit costs (`costs16`: Job::right is the pre-widened int16_t right image) or
// 32-bit ones (Job::right holds bytes): AVX2 when `avx2` (with the costs in registers for 32, 64
// and 128 disparities), else the portable vectors.
Kernel SelectKernel(bool costs16, int nd, bool avx2);

}  // namespace stevi::stereo::internal
