// SadBlockMatcher's vector kernels (block_matcher_internal.h): column sums updated row by row and
// running sums along x, with the best index, the texture and uniqueness tests and OpenCV's
// sub-pixel interpolation; portable 16-byte vectors (SSE2, NEON) and AVX2, 16- or 32-bit costs.
// block_matcher.cc's top comment says what they compute.
#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <type_traits>

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#endif

#include "core/stereo/block_matcher_internal.h"
#include "core/stereo/vector_memory.h"

namespace stevi::stereo::internal {
namespace {

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

// MatchRowInRegisters' step to the next pixel when the window moved down a row: window column
// jadd (`add_col`) moved down (adds the rows left_add / right_add, drops left_sub / right_sub) and
// its texture with it, and the costs `s` moved right: plus the new column, minus `sub_col`.
template <int kVectors>
__attribute__((target("avx2"), always_inline)) inline void SlideAndAddColumn(
    const Job& job, int jadd, const uint8_t* left_add, const uint8_t* left_sub,
    const int16_t* right_add, const int16_t* right_sub, int16_t* add_col, const int16_t* sub_col,
    int* tex, __m256i (&s)[kVectors]) {
  constexpr int kLanes = 16;
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
}

// The same step on the first row of a stripe, whose columns are already summed: the costs `s`
// plus `add_col`, minus `sub_col`.
template <int kVectors>
__attribute__((target("avx2"), always_inline)) inline void AddColumn(const int16_t* add_col,
                                                                     const int16_t* sub_col,
                                                                     __m256i (&s)[kVectors]) {
  constexpr int kLanes = 16;
#pragma GCC unroll 8
  for (int v = 0; v < kVectors; ++v) {
    s[v] = _mm256_add_epi16(s[v],
                            _mm256_sub_epi16(At(add_col + v * kLanes), At(sub_col + v * kLanes)));
  }
}

// The minimum of the costs `s` (costs are >= 0: the unsigned horizontal minimum applies) into
// `min_sad`, and the first index holding it.
template <int kVectors>
__attribute__((target("avx2"), always_inline)) inline int FirstMinimum(const __m256i (&s)[kVectors],
                                                                       int& min_sad) {
  constexpr int kWords = (kVectors * 16 + 63) / 64;
  __m256i vmin = s[0];
#pragma GCC unroll 8
  for (int v = 1; v < kVectors; ++v) vmin = _mm256_min_epi16(vmin, s[v]);
  const __m128i half_min =
      _mm_min_epi16(_mm256_castsi256_si128(vmin), _mm256_extracti128_si256(vmin, 1));
  min_sad = _mm_extract_epi16(_mm_minpos_epu16(half_min), 0);
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
  return best;
}

// The uniqueness test: whether any cost outside [best - 1, best + 1] is at most
// min_sad + min_sad * uniqueness_ratio / 100 (a rival: the pixel is filtered).
template <int kVectors>
__attribute__((target("avx2"), always_inline)) inline bool HasRival(const __m256i (&s)[kVectors],
                                                                    int best, int min_sad,
                                                                    int uniqueness_ratio) {
  constexpr int nd = kVectors * 16;
  constexpr int kWords = (nd + 63) / 64;
  const int thresh = std::min(min_sad + min_sad * uniqueness_ratio / 100,
                              static_cast<int>(std::numeric_limits<int16_t>::max()));
  const __m256i above = _mm256_set1_epi16(static_cast<int16_t>(thresh));
  __m256i masks[kVectors];
  uint64_t words[kWords];
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
  return rival != 0;
}

template <int kVectors>
__attribute__((target("avx2"), always_inline)) inline void StoreCosts(const __m256i (&s)[kVectors],
                                                                      int16_t* sad_buffer) {
  constexpr int kLanes = 16;
#pragma GCC unroll 8
  for (int v = 0; v < kVectors; ++v)
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(sad_buffer + v * kLanes), s[v]);
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
      SlideAndAddColumn<kVectors>(job, jadd, left_add, left_sub, right_add, right_sub, add_col,
                                  sub_col, tex, s);
    } else {
      AddColumn<kVectors>(add_col, sub_col, s);
    }
    tsum += tex[jadd] - tex[jsub];
    if (tsum < job.texture_threshold) {
      out[x] = job.filtered;
      continue;
    }
    int min_sad = 0;
    const int best = FirstMinimum<kVectors>(s, min_sad);
    if (job.uniqueness_ratio > 0 && HasRival<kVectors>(s, best, min_sad, job.uniqueness_ratio)) {
      out[x] = job.filtered;
      continue;
    }
    StoreCosts<kVectors>(s, sad_buffer);
    out[x] = Interpolated(sad_buffer, best, nd, job.max_disp);
  }
  StoreCosts<kVectors>(s, sad_buffer);
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

Kernel SelectKernel(bool costs16, int nd, bool avx2) {
  if (costs16) {
#if defined(__x86_64__) || defined(__i386__)
    if (avx2) {
      switch (nd) {
        case 32: return MatchAvx2_16x32;
        case 64: return MatchAvx2_16x64;
        case 128: return MatchAvx2_16x128;
        default: return MatchAvx2_16;
      }
    }
#endif
    return MatchPortable16;
  }
#if defined(__x86_64__) || defined(__i386__)
  if (avx2) return MatchAvx2_32;
#endif
  return MatchPortable32;
}

}  // namespace stevi::stereo::internal
