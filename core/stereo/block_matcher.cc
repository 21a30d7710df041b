#include "core/stereo/block_matcher.h"

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <thread>
#include <type_traits>

#include <opencv2/calib3d.hpp>

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#endif

#include "core/common/error.h"
#include "core/common/thread_name.h"
#include "core/stereo/vector_memory.h"

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

// Vectors of kBytes bytes (32 for AVX2, 16 for the portable path: SSE2, NEON) of 16-bit costs
// (block^2 * 2 * cap < 32767) or 32-bit ones, and the right-image bytes of one such vector.
template <typename T, int kBytes>
struct Lanes {
  static constexpr int kCount = kBytes / static_cast<int>(sizeof(T));
  typedef T V __attribute__((vector_size(kBytes)));
  typedef uint8_t Bytes __attribute__((vector_size(kCount)));
};
using V16x16 = Lanes<int16_t, 32>::V;
using V32x8 = Lanes<int32_t, 32>::V;
using V16x8 = Lanes<int16_t, 16>::V;
using V32x4 = Lanes<int32_t, 16>::V;
typedef uint64_t Words __attribute__((vector_size(16)));

using simd::Load;
using simd::Store;

// Loads one vector of right-image pixels: stored at the cost's width (no conversion) or as bytes.
template <typename V, typename Bytes, typename P>
[[gnu::always_inline]] inline void LoadPixels(V& v, const P* p) {
  if constexpr (sizeof(P) == sizeof(v[0])) {
    Load(v, p);
  } else {
    Bytes b;
    Load(b, p);
    v = __builtin_convertvector(b, V);
  }
}

// Horizontal minima, within 128 bits after the first fold (cheap shuffles everywhere).
[[gnu::always_inline]] inline int HorizontalMin(const V16x8& v) {
  V16x8 a = v;
  V16x8 b = __builtin_shufflevector(a, a, 4, 5, 6, 7, 0, 1, 2, 3);
  a = b < a ? b : a;
  b = __builtin_shufflevector(a, a, 2, 3, 0, 1, 2, 3, 0, 1);
  a = b < a ? b : a;
  b = __builtin_shufflevector(a, a, 1, 0, 1, 0, 1, 0, 1, 0);
  a = b < a ? b : a;
  return a[0];
}
[[gnu::always_inline]] inline int HorizontalMin(const V32x4& v) {
  V32x4 a = v;
  V32x4 b = __builtin_shufflevector(a, a, 2, 3, 0, 1);
  a = b < a ? b : a;
  b = __builtin_shufflevector(a, a, 1, 0, 1, 0);
  a = b < a ? b : a;
  return a[0];
}
[[gnu::always_inline]] inline int HorizontalMin(const V16x16& v) {
  const V16x8 lo = __builtin_shufflevector(v, v, 0, 1, 2, 3, 4, 5, 6, 7);
  const V16x8 hi = __builtin_shufflevector(v, v, 8, 9, 10, 11, 12, 13, 14, 15);
  return HorizontalMin(lo < hi ? lo : hi);
}
[[gnu::always_inline]] inline int HorizontalMin(const V32x8& v) {
  const V32x4 lo = __builtin_shufflevector(v, v, 0, 1, 2, 3);
  const V32x4 hi = __builtin_shufflevector(v, v, 4, 5, 6, 7);
  return HorizontalMin(lo < hi ? lo : hi);
}

// Whether any lane of a comparison result is set.
template <typename V>
[[gnu::always_inline]] inline bool Any(const V& mask) {
  Words w;
  std::memcpy(&w, &mask, sizeof w);
  if constexpr (sizeof(V) == 32) {
    Words hi;
    std::memcpy(&hi, reinterpret_cast<const char*>(&mask) + sizeof w, sizeof hi);
    w |= hi;
  }
  return (w[0] | w[1]) != 0;
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

// Moves window column jj's cost sums down one row: adds row `add`, drops row `sub`.
template <typename T, int kBytes, typename P>
[[gnu::always_inline]] inline void SlideColumn(const Job& job, int jj, const uint8_t* left_add,
                                               const uint8_t* left_sub, const P* right_add,
                                               const P* right_sub, T* column, int* texture) {
  using V = typename Lanes<T, kBytes>::V;
  using Bytes = typename Lanes<T, kBytes>::Bytes;
  constexpr int kLanes = Lanes<T, kBytes>::kCount;
  const int lc = job.left_col[jj];
  const int a = left_add[lc];
  const int b = left_sub[lc];
  const V av = V{} + static_cast<T>(a);
  const V bv = V{} + static_cast<T>(b);
  const P* ra = right_add + job.right_col[jj];
  const P* rs = right_sub + job.right_col[jj];
  for (int k = 0; k < job.nd; k += kLanes) {
    V rav, rsv;
    LoadPixels<V, Bytes>(rav, ra + k);
    LoadPixels<V, Bytes>(rsv, rs + k);
    V da = av - rav;
    V db = bv - rsv;
    da = da < V{} ? -da : da;
    db = db < V{} ? -db : db;
    V acc;
    Load(acc, column + k);
    acc += da - db;
    Store(column + k, acc);
  }
  *texture += std::abs(a - job.cap) - std::abs(b - job.cap);
}

#if defined(__x86_64__) || defined(__i386__)
__attribute__((target("avx2"), always_inline)) inline __m256i At(const int16_t* p) {
  return _mm256_loadu_si256(reinterpret_cast<const __m256i*>(p));
}

// Bit k of `words` (k = 0 .. 16 kVectors - 1) is the sign of 16-bit lane k % 16 of
// masks[k / 16] (masks: comparison results, all ones or all zeros).
template <int kVectors>
__attribute__((target("avx2"), always_inline)) inline void LaneBits(const __m256i* masks,
                                                                    uint64_t* words) {
  static_assert(kVectors % 2 == 0);
#pragma GCC unroll 8
  for (int v = 0; v < kVectors; v += 2) {
    // packs interleaves the 128-bit halves (a.lo b.lo a.hi b.hi); the permute puts them in order.
    const __m256i packed =
        _mm256_permute4x64_epi64(_mm256_packs_epi16(masks[v], masks[v + 1]), 0xD8);
    const uint64_t bits = static_cast<uint32_t>(_mm256_movemask_epi8(packed));
    if (v % 4 == 0) {
      words[v / 4] = bits;
    } else {
      words[v / 4] |= bits << 32;
    }
  }
}

// One row of pixels of the AVX2 kernel with 16-bit costs and nd = 16 kVectors: the current pixel's
// costs stay in registers from pixel to pixel, a window column entering the block is moved down a
// row and added in the same pass, and the best index and the uniqueness test come from bit masks
// of all nd costs at once. `tsum`: the texture of the row's first window minus its last column,
// as the generic loop starts it. The same output as the generic loop, bit for bit.
template <int kVectors>
__attribute__((target("avx2"), noinline)) void MatchRowInRegisters(
    const Job& job, int16_t* cols, int* tex, int tsum, bool slide, const uint8_t* left_add,
    const uint8_t* left_sub, const int16_t* right_add, const int16_t* right_sub, int16_t* out) {
  constexpr int kLanes = 16;
  constexpr int nd = kVectors * kLanes;
  constexpr int kWords = (nd + 63) / 64;
  const int span = 2 * job.half;
  int16_t* const sad_buffer = cols - 2 * nd;  // the Job's T[nd] of the current pixel's costs
  __m256i s[kVectors];
#pragma GCC unroll 8
  for (int v = 0; v < kVectors; ++v) s[v] = At(sad_buffer + v * kLanes);
  for (int x = job.x0; x < job.x1; ++x) {
    const int jadd = x - job.x0 + span;
    const int jsub = jadd - span - 1;  // -1 (the zero column) at the first pixel
    int16_t* const add_col = cols + static_cast<ptrdiff_t>(jadd) * nd;
    const int16_t* const sub_col = cols + static_cast<ptrdiff_t>(jsub) * nd;
    if (slide) {
      const int lc = job.left_col[jadd];
      const int a = left_add[lc];
      const int b = left_sub[lc];
      const __m256i av = _mm256_set1_epi16(static_cast<int16_t>(a));
      const __m256i bv = _mm256_set1_epi16(static_cast<int16_t>(b));
      const int16_t* ra = right_add + job.right_col[jadd];
      const int16_t* rs = right_sub + job.right_col[jadd];
#pragma GCC unroll 8
      for (int v = 0; v < kVectors; ++v) {
        const __m256i da = _mm256_abs_epi16(_mm256_sub_epi16(av, At(ra + v * kLanes)));
        const __m256i db = _mm256_abs_epi16(_mm256_sub_epi16(bv, At(rs + v * kLanes)));
        const __m256i column = _mm256_add_epi16(At(add_col + v * kLanes), _mm256_sub_epi16(da, db));
        _mm256_storeu_si256(reinterpret_cast<__m256i*>(add_col + v * kLanes), column);
        s[v] = _mm256_add_epi16(s[v], _mm256_sub_epi16(column, At(sub_col + v * kLanes)));
      }
      tex[jadd] += std::abs(a - job.cap) - std::abs(b - job.cap);
    } else {
#pragma GCC unroll 8
      for (int v = 0; v < kVectors; ++v) {
        s[v] = _mm256_add_epi16(
            s[v], _mm256_sub_epi16(At(add_col + v * kLanes), At(sub_col + v * kLanes)));
      }
    }
    tsum += tex[jadd] - tex[jsub];
    if (tsum < job.texture_threshold) {
      out[x] = job.filtered;
      continue;
    }
    // The minimum (costs are >= 0: the unsigned horizontal minimum applies), then the first index
    // holding it.
    __m256i vmin = s[0];
#pragma GCC unroll 8
    for (int v = 1; v < kVectors; ++v) vmin = _mm256_min_epi16(vmin, s[v]);
    const __m128i half_min =
        _mm_min_epi16(_mm256_castsi256_si128(vmin), _mm256_extracti128_si256(vmin, 1));
    const int min_sad = _mm_extract_epi16(_mm_minpos_epu16(half_min), 0);
    const __m256i min_v = _mm256_set1_epi16(static_cast<int16_t>(min_sad));
    __m256i masks[kVectors];
    uint64_t words[kWords];
#pragma GCC unroll 8
    for (int v = 0; v < kVectors; ++v) masks[v] = _mm256_cmpeq_epi16(s[v], min_v);
    LaneBits<kVectors>(masks, words);
    int best = 0;
    for (int w = 0; w < kWords; ++w) {
      if (words[w] != 0) {
        best = 64 * w + __builtin_ctzll(words[w]);
        break;
      }
    }
    if (job.uniqueness_ratio > 0) {
      // Rivals: any cost <= thresh outside [best - 1, best + 1].
      const int thresh = std::min(min_sad + min_sad * job.uniqueness_ratio / 100,
                                  static_cast<int>(std::numeric_limits<int16_t>::max()));
      const __m256i above = _mm256_set1_epi16(static_cast<int16_t>(thresh));
#pragma GCC unroll 8
      for (int v = 0; v < kVectors; ++v) masks[v] = _mm256_cmpgt_epi16(above, s[v]);  // s < thresh
#pragma GCC unroll 8
      for (int v = 0; v < kVectors; ++v)
        masks[v] = _mm256_or_si256(masks[v], _mm256_cmpeq_epi16(above, s[v]));
      LaneBits<kVectors>(masks, words);
      for (int k = std::max(0, best - 1); k <= std::min(nd - 1, best + 1); ++k) {
        words[k / 64] &= ~(uint64_t{1} << (k % 64));
      }
      uint64_t rival = 0;
      for (int w = 0; w < kWords; ++w) rival |= words[w];
      if (rival != 0) {
        out[x] = job.filtered;
        continue;
      }
    }
#pragma GCC unroll 8
    for (int v = 0; v < kVectors; ++v)
      _mm256_storeu_si256(reinterpret_cast<__m256i*>(sad_buffer + v * kLanes), s[v]);
    out[x] = Interpolated(sad_buffer, best, nd, job.max_disp);
  }
#pragma GCC unroll 8
  for (int v = 0; v < kVectors; ++v)
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(sad_buffer + v * kLanes), s[v]);
}
#endif

// The first row's window: rows y0 - half .. y0 + half (all inside the image), summed per window
// column into `cols` (its zero column before it cleared too) and `tex`.
template <typename T, int kBytes, typename P>
[[gnu::always_inline]] inline void InitWindow(const Job& job, T* cols, int* tex, int ncols) {
  using V = typename Lanes<T, kBytes>::V;
  using Bytes = typename Lanes<T, kBytes>::Bytes;
  constexpr int kLanes = Lanes<T, kBytes>::kCount;
  const int nd = job.nd;
  const int half = job.half;
  const P* const right = static_cast<const P*>(job.right);
  std::fill(cols - nd, cols + static_cast<size_t>(ncols) * nd, T{0});
  std::fill(tex - 1, tex + ncols, 0);
  for (int r = job.y0 - half; r <= job.y0 + half; ++r) {
    const uint8_t* lrow = job.left + r * job.left_step;
    const P* rrow = right + r * job.right_step;
    for (int jj = 0; jj < ncols; ++jj) {
      const int lv = lrow[job.left_col[jj]];
      const V lvv = V{} + static_cast<T>(lv);
      const P* rp = rrow + job.right_col[jj];
      T* column = cols + static_cast<size_t>(jj) * nd;
      for (int k = 0; k < nd; k += kLanes) {
        V rv;
        LoadPixels<V, Bytes>(rv, rp + k);
        V diff = lvv - rv;
        diff = diff < V{} ? -diff : diff;
        V acc;
        Load(acc, column + k);
        acc += diff;
        Store(column + k, acc);
      }
      tex[jj] += std::abs(lv - job.cap);
    }
  }
}

// One row of pixels, for any nd: the costs go through memory (`sad`), as wide as the vectors.
// `tsum`: the texture of the row's first window minus its last column.
template <typename T, int kBytes, typename P>
[[gnu::always_inline]] inline void MatchRowGeneric(const Job& job, T* sad, T* cols, int* tex,
                                                   int tsum, bool slide, const uint8_t* left_add,
                                                   const uint8_t* left_sub, const P* right_add,
                                                   const P* right_sub, int16_t* out) {
  using V = typename Lanes<T, kBytes>::V;
  constexpr int kLanes = Lanes<T, kBytes>::kCount;
  const int nd = job.nd;
  const int span = 2 * job.half;
  V lane;
  for (int i = 0; i < kLanes; ++i) lane[i] = static_cast<T>(i);
  const V big = V{} + std::numeric_limits<T>::max();
  for (int x = job.x0; x < job.x1; ++x) {
    const int jadd = x - job.x0 + span;
    const int jsub = jadd - span - 1;  // -1 (the zero column) at the first pixel
    T* const add_col = cols + static_cast<ptrdiff_t>(jadd) * nd;
    const T* const sub_col = cols + static_cast<ptrdiff_t>(jsub) * nd;
    if (slide) {
      SlideColumn<T, kBytes, P>(job, jadd, left_add, left_sub, right_add, right_sub, add_col,
                                tex + jadd);
    }
    tsum += tex[jadd] - tex[jsub];

    // SADs, and per lane the minimum and the first block reaching it.
    V vmin = big;
    V vblock = V{};
    for (int k = 0; k < nd; k += kLanes) {
      V s, a, b;
      Load(s, sad + k);
      Load(a, add_col + k);
      Load(b, sub_col + k);
      s += a - b;
      Store(sad + k, s);
      const V lower = s < vmin;
      vmin = lower ? s : vmin;
      vblock = lower ? V{} + static_cast<T>(k) : vblock;
    }
    if (tsum < job.texture_threshold) {
      out[x] = job.filtered;
      continue;
    }
    const int min_sad = HorizontalMin(vmin);
    const V candidates = vmin == V{} + static_cast<T>(min_sad) ? vblock + lane : big;
    const int best = HorizontalMin(candidates);

    if (job.uniqueness_ratio > 0) {
      const int thresh = std::min(min_sad + min_sad * job.uniqueness_ratio / 100,
                                  static_cast<int>(std::numeric_limits<T>::max()));
      const V tv = V{} + static_cast<T>(thresh);
      const V first_exempt = V{} + static_cast<T>(best - 1);
      const V last_exempt = V{} + static_cast<T>(best + 1);
      V index = lane;
      V rival = V{};
      for (int k = 0; k < nd; k += kLanes) {
        V s;
        Load(s, sad + k);
        rival |= (s <= tv) & ((index < first_exempt) | (index > last_exempt));
        index += static_cast<T>(kLanes);
      }
      if (Any(rival)) {
        out[x] = job.filtered;
        continue;
      }
    }
    out[x] = Interpolated(sad, best, nd, job.max_disp);
  }
}

// Column sums updated row by row, running sums along x: the cost of a pixel is O(nd), whatever
// the block size. T holds every block sum exactly (16 bits when block^2 * 2 * cap < 32767).
//
// kVectors > 0 (AVX2, 16-bit costs only): the rows go through MatchRowInRegisters.
template <typename T, int kBytes, typename P, int kVectors = 0>
[[gnu::always_inline]] inline void MatchKernel(const Job& job) {
  using V = typename Lanes<T, kBytes>::V;
  constexpr int kLanes = Lanes<T, kBytes>::kCount;
  const int nd = job.nd;
  const int half = job.half;
  const int span = 2 * half;
  const int ncols = job.x1 - job.x0 + span;
  const P* const right = static_cast<const P*>(job.right);
  T* const sad = static_cast<T*>(job.cost);
  T* const cols = sad + 2 * nd;  // window column jj at cols + jj * nd; cols - nd: zeros
  int* const tex = job.texture_col + 1;

  InitWindow<T, kBytes, P>(job, cols, tex, ncols);

  for (int y = job.y0; y < job.y1; ++y) {
    const bool slide = y > job.y0;
    // Rows entering and leaving the window when moving down from y - 1 (used when `slide`).
    const uint8_t* left_add = job.left + (y + half) * job.left_step;
    const P* right_add = right + (y + half) * job.right_step;
    const int sub_row = slide ? y - half - 1 : y;
    const uint8_t* left_sub = job.left + sub_row * job.left_step;
    const P* right_sub = right + sub_row * job.right_step;
    if (slide) {
      for (int jj = 0; jj < span; ++jj) {
        SlideColumn<T, kBytes, P>(job, jj, left_add, left_sub, right_add, right_sub,
                                  cols + static_cast<size_t>(jj) * nd, tex + jj);
      }
    }
    // SADs of the window minus its last column, which the first pixel adds.
    std::fill(sad, sad + nd, T{0});
    int tsum = 0;
    for (int jj = 0; jj < span; ++jj) {
      const T* column = cols + static_cast<size_t>(jj) * nd;
      for (int k = 0; k < nd; k += kLanes) {
        V s, c;
        Load(s, sad + k);
        Load(c, column + k);
        s += c;
        Store(sad + k, s);
      }
      tsum += tex[jj];
    }

    int16_t* out = job.disp + y * job.disp_step;
#if defined(__x86_64__) || defined(__i386__)
    if constexpr (kVectors > 0) {
      static_assert(std::is_same_v<T, int16_t> && std::is_same_v<P, int16_t> && kBytes == 32);
      MatchRowInRegisters<kVectors>(job, cols, tex, tsum, slide, left_add, left_sub, right_add,
                                    right_sub, out);
      continue;
    }
#endif
    MatchRowGeneric<T, kBytes, P>(job, sad, cols, tex, tsum, slide, left_add, left_sub, right_add,
                                  right_sub, out);
  }
}

// 16-bit costs read a pre-widened right image (GCC 12 widens bytes to a 32-byte vector in four
// instructions); 32-bit costs read bytes.
void MatchPortable16(const Job& job) { MatchKernel<int16_t, 16, int16_t>(job); }
void MatchPortable32(const Job& job) { MatchKernel<int32_t, 16, uint8_t>(job); }
#if defined(__x86_64__) || defined(__i386__)
__attribute__((target("avx2"))) void MatchAvx2_16(const Job& job) {
  MatchKernel<int16_t, 32, int16_t>(job);
}
// 32, 64 and 128 disparities (the usual search ranges) in registers.
__attribute__((target("avx2"))) void MatchAvx2_16x32(const Job& job) {
  MatchKernel<int16_t, 32, int16_t, 2>(job);
}
__attribute__((target("avx2"))) void MatchAvx2_16x64(const Job& job) {
  MatchKernel<int16_t, 32, int16_t, 4>(job);
}
__attribute__((target("avx2"))) void MatchAvx2_16x128(const Job& job) {
  MatchKernel<int16_t, 32, int16_t, 8>(job);
}
__attribute__((target("avx2"))) void MatchAvx2_32(const Job& job) {
  MatchKernel<int32_t, 32, uint8_t>(job);
}
#endif

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
  const int cap = p_.prefilter_cap;
  const int max_disp = p_.min_disparity + nd - 1;
  const int16_t filtered = static_cast<int16_t>((p_.min_disparity - 1) * 16);
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
  Job job{};
  job.left = left_filtered_.ptr<uint8_t>();
  job.left_step = left_filtered_.step[0];
  job.disp = disparity.ptr<int16_t>();
  job.disp_step = disparity.step1();
  job.y0 = y0;
  job.y1 = y1;
  job.x0 = x0;
  job.x1 = x1;
  job.half = half;
  job.nd = nd;
  job.max_disp = max_disp;
  job.cap = cap;
  job.texture_threshold = p_.texture_threshold;
  job.uniqueness_ratio = p_.uniqueness_ratio;
  job.filtered = filtered;
  job.left_col = left_col_.data();
  job.right_col = right_col_.data();
  job.texture_col = texture_col_.data();
  const size_t cost_size = static_cast<size_t>(ncols + 2) * nd;
  const bool avx2 = UsesAvx2();
  void (*kernel)(const Job&) = nullptr;
  const bool costs16 =
      p_.block_size * p_.block_size * 2 * cap < std::numeric_limits<int16_t>::max();
  if (costs16) {
    if (cost16_.size() < cost_size * stripes) cost16_.resize(cost_size * stripes);
    right_filtered_.convertTo(right_wide_, CV_16SC1);
    job.right = right_wide_.ptr<int16_t>();
    job.right_step = right_wide_.step1();
    kernel = MatchPortable16;
#if defined(__x86_64__) || defined(__i386__)
    if (avx2) {
      switch (nd) {
        case 32: kernel = MatchAvx2_16x32; break;
        case 64: kernel = MatchAvx2_16x64; break;
        case 128: kernel = MatchAvx2_16x128; break;
        default: kernel = MatchAvx2_16; break;
      }
    }
#endif
  } else {
    if (cost32_.size() < cost_size * stripes) cost32_.resize(cost_size * stripes);
    job.right = right_filtered_.ptr<uint8_t>();
    job.right_step = right_filtered_.step1();
    kernel = MatchPortable32;
#if defined(__x86_64__) || defined(__i386__)
    if (avx2) kernel = MatchAvx2_32;
#endif
  }
  // Each stripe starts its window afresh (its own cost and texture buffers): the sums are exact
  // integers, so the output is the same as one pass over all rows.
  std::vector<Job> jobs(static_cast<size_t>(stripes), job);
  for (int s = 0; s < stripes; ++s) {
    Job& stripe = jobs[static_cast<size_t>(s)];
    stripe.y0 = y0 + (y1 - y0) * s / stripes;
    stripe.y1 = y0 + (y1 - y0) * (s + 1) / stripes;
    stripe.texture_col = texture_col_.data() + texture_size * s;
    stripe.cost = costs16 ? static_cast<void*>(cost16_.data() + cost_size * s)
                          : static_cast<void*>(cost32_.data() + cost_size * s);
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
