#include "core/stereo/block_matcher.h"

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <thread>

#include <opencv2/calib3d.hpp>

#include "core/common/error.h"
#include "core/common/thread_name.h"
#include "core/stereo/block_matcher_internal.h"

// What cv::StereoBM (OpenCV 4.6, modules/calib3d/src/stereobm.cpp) computes, as implemented here:
//
// - Pre-filter (x-Sobel): out = clamp(dx(y-1) + 2 dx(y) + dx(y+1) + cap, 0, 2 cap) with
//   dx(r) = img[r][x+1] - img[r][x-1]; rows mirror at the top and bottom (row -1 is row 1, row h
//   is row h-2); the first and last columns are `cap`; and, when the height is odd, so is the
//   whole last row (OpenCV filters rows in pairs and fills the unpaired last row with `cap`).
// - Cost of disparity index k (disparity max_disp - k, max_disp = min_disparity + nd - 1) at
//   (x, y): the sum over the block of |L[r][lcol(j)] - R[r][rcol(j) + k]|, with
//   lcol(j) = clamp(j, 0, w-1) and rcol(j) = clamp(j - max_disp, 0, w - nd). Inside the valid
//   area below neither clamp is ever active for min_disparity >= 0.
// - Only the valid rectangle is matched: rows [h/2.. , h - b/2), columns
//   [max(max_disp, 0) + b/2, w - b/2) (cv::getValidDisparityROI) and within the columns OpenCV
//   matches at all ([lofs, lofs + width1)). Everything else is the unmatched marker.
// - Best index: the first (smallest k, i.e. largest disparity) minimum of the cost.
// - Texture: the block sum of |L_prefiltered - cap| must reach texture_threshold.
// - Uniqueness: thresh = min + min * ratio / 100 (integers); unmatched if any index outside
//   [best - 1, best + 1] has cost <= thresh.
// - Sub-pixel: p = cost[best + 1], n = cost[best - 1], den = p + n - 2 cost[best] + |p - n|,
//   d16 = ((max_disp - best) * 256 + (den ? (p - n) * 256 / den : 0) + 15) >> 4, with no
//   interpolation at the first and last index.
// - Quirk reproduced: with min_disparity > 0, OpenCV's column loop runs min_disparity columns past
//   the row end, so the last matched row's results for columns w .. w + min_disparity - 1 (costs
//   with clamped columns) land in the first min_disparity pixels of the next row, which is the
//   first row of the bottom border and is not reset afterwards. (With several threads OpenCV
//   splits the rows into stripes and each stripe's overrun into the next stripe's first row races
//   with that stripe's own border reset; with one thread there is a single stripe.)
// - Then cv::filterSpeckles, as StereoBM calls it.

namespace stevi::stereo {

using internal::Interpolated;

namespace {

std::atomic<bool> g_force_portable{false};

bool CpuHasAvx2() {
#if defined(__x86_64__) || defined(__i386__)
  return __builtin_cpu_supports("avx2");
#else
  return false;
#endif
}

void PrefilterXSobel(const cv::Mat& src, cv::Mat& dst, int cap) {
  const int w = src.cols;
  const int h = src.rows;
  dst.create(src.size(), CV_8UC1);
  const uint8_t edge = static_cast<uint8_t>(cap);
  for (int y = 0; y < h; ++y) {
    uint8_t* out = dst.ptr<uint8_t>(y);
    if (h % 2 == 1 && y == h - 1) {
      std::memset(out, edge, static_cast<size_t>(w));
      continue;
    }
    const uint8_t* up = src.ptr<uint8_t>(y > 0 ? y - 1 : 1);
    const uint8_t* mid = src.ptr<uint8_t>(y);
    const uint8_t* down = src.ptr<uint8_t>(y + 1 < h ? y + 1 : y - 1);
    out[0] = edge;
    out[w - 1] = edge;
    // 16 pixels at a time in 16-bit lanes (|v| <= 4 * 255 + 63), then the rest one by one.
    using Px = uint8_t __attribute__((vector_size(16)));
    using Wide = int16_t __attribute__((vector_size(32)));
    const auto load = [](Wide& v, const uint8_t* p) {  // by reference: no vector ABI question
      Px b;
      std::memcpy(&b, p, sizeof b);
      v = __builtin_convertvector(b, Wide);
    };
    const Wide lo = Wide{} + static_cast<int16_t>(0);
    const Wide hi = Wide{} + static_cast<int16_t>(2 * cap);
    int x = 1;
    for (; x + 16 < w; x += 16) {
      Wide a, b, c, d, e, f;
      load(a, up + x + 1);
      load(b, up + x - 1);
      load(c, mid + x + 1);
      load(d, mid + x - 1);
      load(e, down + x + 1);
      load(f, down + x - 1);
      Wide v = (a - b) + 2 * (c - d) + (e - f) + static_cast<int16_t>(cap);
      v = v < lo ? lo : v;
      v = v > hi ? hi : v;
      const Px bytes = __builtin_convertvector(v, Px);
      std::memcpy(out + x, &bytes, sizeof bytes);
    }
    for (; x < w - 1; ++x) {
      const int v = (up[x + 1] - up[x - 1]) + 2 * (mid[x + 1] - mid[x - 1]) +
                    (down[x + 1] - down[x - 1]) + cap;
      out[x] = static_cast<uint8_t>(std::clamp(v, 0, 2 * cap));
    }
  }
}

// The parts of a kernel's job every stripe shares: the pre-filtered left image, the output, the
// rectangle matched and the parameters. The right image, the window columns and the buffers are
// the caller's to set.
internal::Job BaseJob(const SadBlockMatcherParams& p, const cv::Mat& left_filtered,
                      cv::Mat& disparity, int x0, int x1, int y0, int y1) {
  internal::Job job{};
  job.left = left_filtered.ptr<uint8_t>();
  job.left_step = left_filtered.step[0];
  job.disp = disparity.ptr<int16_t>();
  job.disp_step = disparity.step1();
  job.y0 = y0;
  job.y1 = y1;
  job.x0 = x0;
  job.x1 = x1;
  job.half = p.block_size / 2;
  job.nd = p.num_disparities;
  job.max_disp = p.min_disparity + p.num_disparities - 1;
  job.cap = p.prefilter_cap;
  job.texture_threshold = p.texture_threshold;
  job.uniqueness_ratio = p.uniqueness_ratio;
  job.filtered = static_cast<int16_t>((p.min_disparity - 1) * 16);
  return job;
}

// Runs `kernel` over `stripes` horizontal stripes of the job's rows, stripes 1.. on threads of
// their own. Each stripe starts its window afresh with its own buffers (texture_size texture
// columns from `texture`, cost_bytes from `costs`): the sums are exact integers, so the output is
// the same as one pass over all rows.
void RunStripes(internal::Kernel kernel, const internal::Job& job, int stripes, int* texture,
                size_t texture_size, void* costs, size_t cost_bytes) {
  const int y0 = job.y0, y1 = job.y1;
  std::vector<internal::Job> jobs(static_cast<size_t>(stripes), job);
  for (int s = 0; s < stripes; ++s) {
    internal::Job& stripe = jobs[static_cast<size_t>(s)];
    stripe.y0 = y0 + (y1 - y0) * s / stripes;
    stripe.y1 = y0 + (y1 - y0) * (s + 1) / stripes;
    stripe.texture_col = texture + texture_size * s;
    stripe.cost = static_cast<char*>(costs) + cost_bytes * s;
  }
  std::vector<std::thread> helpers;
  for (int s = 1; s < stripes; ++s) {
    helpers.emplace_back([kernel, &stripe = jobs[static_cast<size_t>(s)]] {
      NameThisThread("stevi-bm-stripe");
      kernel(stripe);
    });
  }
  kernel(jobs[0]);
  for (std::thread& helper : helpers) helper.join();
}

}  // namespace

std::vector<std::string> SadBlockMatcherParams::Validate() const {
  std::vector<std::string> problems;
  if (num_disparities < 16 || num_disparities > 1024 || num_disparities % 16 != 0) {
    problems.push_back("num_disparities: must be a multiple of 16 in 16..1024" +
                       Got(num_disparities));
  }
  if (min_disparity < -1024 || min_disparity > 1024) {
    problems.push_back("min_disparity: must be in -1024..1024" + Got(min_disparity));
  }
  if (block_size < 5 || block_size > 255 || block_size % 2 == 0) {
    problems.push_back("block_size: must be odd, in 5..255" + Got(block_size));
  }
  if (prefilter_cap < 1 || prefilter_cap > 63) {
    problems.push_back("prefilter_cap: must be in 1..63" + Got(prefilter_cap));
  }
  if (texture_threshold < 0) {
    problems.push_back("texture_threshold: must be >= 0" + Got(texture_threshold));
  }
  if (uniqueness_ratio < 0 || uniqueness_ratio > 100) {
    problems.push_back("uniqueness_ratio: must be in 0..100" + Got(uniqueness_ratio));
  }
  if (speckle_window_size < 0) {
    problems.push_back("speckle_window_size: must be >= 0" + Got(speckle_window_size));
  }
  if (speckle_range < 0) problems.push_back("speckle_range: must be >= 0" + Got(speckle_range));
  if (stripes < 1 || stripes > 8) problems.push_back("stripes: must be in 1..8" + Got(stripes));
  return problems;
}

SadBlockMatcher::SadBlockMatcher(SadBlockMatcherParams p) : p_(p) {
  const std::vector<std::string> problems = p_.Validate();
  if (!problems.empty()) CV_Error(cv::Error::StsOutOfRange, InvalidArgument(problems).message);
}

void SadBlockMatcher::ForcePortable(bool force) { g_force_portable.store(force); }

bool SadBlockMatcher::UsesAvx2() { return !g_force_portable.load() && CpuHasAvx2(); }

void SadBlockMatcher::RunKernel(int x0, int x1, int y0, int y1, cv::Mat& disparity) {
  const int w = left_filtered_.cols;
  const int nd = p_.num_disparities;
  const int half = p_.block_size / 2;
  const int max_disp = p_.min_disparity + nd - 1;
  const int ncols = x1 - x0 + 2 * half;
  // Stripes of at least four blocks' height: below that the window set-up dominates.
  const int stripes = std::clamp((y1 - y0) / (4 * p_.block_size), 1, p_.stripes);
  const size_t texture_size = static_cast<size_t>(ncols) + 1;
  left_col_.resize(static_cast<size_t>(ncols));
  right_col_.resize(static_cast<size_t>(ncols));
  texture_col_.resize(texture_size * stripes);
  for (int jj = 0; jj < ncols; ++jj) {
    const int j = x0 - half + jj;
    left_col_[jj] = std::clamp(j, 0, w - 1);
    right_col_[jj] = std::clamp(j - max_disp, 0, w - nd);
  }
  internal::Job job = BaseJob(p_, left_filtered_, disparity, x0, x1, y0, y1);
  job.left_col = left_col_.data();
  job.right_col = right_col_.data();
  job.texture_col = texture_col_.data();
  const size_t cost_size = static_cast<size_t>(ncols + 2) * nd;
  const bool costs16 =
      p_.block_size * p_.block_size * 2 * p_.prefilter_cap < std::numeric_limits<int16_t>::max();
  void* costs = nullptr;
  size_t cost_bytes = 0;
  if (costs16) {
    if (cost16_.size() < cost_size * stripes) cost16_.resize(cost_size * stripes);
    right_filtered_.convertTo(right_wide_, CV_16SC1);
    job.right = right_wide_.ptr<int16_t>();
    job.right_step = right_wide_.step1();
    costs = cost16_.data();
    cost_bytes = cost_size * sizeof(int16_t);
  } else {
    if (cost32_.size() < cost_size * stripes) cost32_.resize(cost_size * stripes);
    job.right = right_filtered_.ptr<uint8_t>();
    job.right_step = right_filtered_.step1();
    costs = cost32_.data();
    cost_bytes = cost_size * sizeof(int32_t);
  }
  RunStripes(internal::SelectKernel(costs16, nd, UsesAvx2()), job, stripes, texture_col_.data(),
             texture_size, costs, cost_bytes);
}

void SadBlockMatcher::ComputeOverrun(int x_end, int y1, cv::Mat& disparity) {
  const int w = left_filtered_.cols;
  const int nd = p_.num_disparities;
  const int half = p_.block_size / 2;
  const int cap = p_.prefilter_cap;
  const int max_disp = p_.min_disparity + nd - 1;
  const int16_t filtered = static_cast<int16_t>((p_.min_disparity - 1) * 16);
  for (int x = w; x < x_end; ++x) {
    const int y = y1 - 1;
    sad_scalar_.assign(static_cast<size_t>(nd), 0);
    int tsum = 0;
    for (int r = y - half; r <= y + half; ++r) {
      const uint8_t* lrow = left_filtered_.ptr<uint8_t>(r);
      const uint8_t* rrow = right_filtered_.ptr<uint8_t>(r);
      for (int j = x - half; j <= x + half; ++j) {
        const int lv = lrow[std::clamp(j, 0, w - 1)];
        const uint8_t* rp = rrow + std::clamp(j - max_disp, 0, w - nd);
        for (int k = 0; k < nd; ++k) sad_scalar_[k] += std::abs(lv - rp[k]);
        tsum += std::abs(lv - cap);
      }
    }
    const int* sad = sad_scalar_.data();
    const int best = static_cast<int>(std::min_element(sad, sad + nd) - sad);
    const int thresh = sad[best] + sad[best] * p_.uniqueness_ratio / 100;
    bool unique = true;
    for (int k = 0; k < nd && p_.uniqueness_ratio > 0; ++k) {
      if ((k < best - 1 || k > best + 1) && sad[k] <= thresh) unique = false;
    }
    int16_t& out = disparity.at<int16_t>(y + 1, x - w);
    out = tsum < p_.texture_threshold || !unique ? filtered : Interpolated(sad, best, nd, max_disp);
  }
}

void SadBlockMatcher::Compute(const cv::Mat& left, const cv::Mat& right, cv::Mat& disparity) {
  CV_Assert(left.type() == CV_8UC1 && right.type() == CV_8UC1);
  CV_Assert(left.size() == right.size());
  const int w = left.cols;
  const int h = left.rows;
  const int nd = p_.num_disparities;
  const int half = p_.block_size / 2;
  const int cap = p_.prefilter_cap;
  const int max_disp = p_.min_disparity + nd - 1;
  const int16_t filtered = static_cast<int16_t>((p_.min_disparity - 1) * 16);

  disparity.create(left.size(), CV_16SC1);
  disparity.setTo(filtered);
  // cv::StereoBM throws here; it leaves its output uninitialised when the valid area is empty.
  if (p_.block_size >= std::min(w, h)) return;
  const int lofs = std::max(max_disp, 0);
  const int rofs = std::max(-max_disp, 0);
  const int width1 = w - rofs - nd + 1;  // columns OpenCV matches, from lofs
  if (lofs >= w || rofs >= w || width1 < 1) return;
  const int valid_x0 = lofs + half;
  const int valid_x1 = w - half;
  const int y0 = half;
  const int y1 = h - half;
  if (valid_x1 <= valid_x0 || y1 <= y0) return;
  const int x0 = std::max(valid_x0, lofs);
  const int x1 = std::min(valid_x1, lofs + width1);

  PrefilterXSobel(left, left_filtered_, cap);
  PrefilterXSobel(right, right_filtered_, cap);

  if (x1 > x0) RunKernel(x0, x1, y0, y1, disparity);
  ComputeOverrun(lofs + width1, y1, disparity);

  if (p_.speckle_window_size > 0) {
    cv::filterSpeckles(disparity, filtered, p_.speckle_window_size, p_.speckle_range, speckle_buf_);
  }
}

}  // namespace stevi::stereo
