// DenseMatcher's matching (dense_matcher.h): the census, the 8-bit path costs of the semi-global
// aggregation in vectors (portable, AVX2, AVX-512), the winner with its sub-pixel refinement and
// the left-right check with hole filling, row by row. dense_confidence.cc holds the confidence.
#include "core/stereo/dense_matcher.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

#include <opencv2/imgproc.hpp>

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#endif

#include "core/common/error.h"
#include "core/stereo/dense_matcher_internal.h"
#include "core/stereo/vector_memory.h"

namespace stevi::stereo {

using internal::kMarginBins;
using internal::kZRange;
using internal::kZSteps;

std::vector<std::string> DenseMatcherOptions::Validate() const {
  std::vector<std::string> problems = fields::Check(*this);
  if (p2 <= p1) {
    problems.push_back("p2: must be greater than p1 (got p1=" + std::to_string(p1) +
                       ", p2=" + std::to_string(p2) + ")");
  }
  if (p1 + p2 > kDenseMaxPenaltySum) {
    problems.push_back("p2: p1 + p2 must be at most " + std::to_string(kDenseMaxPenaltySum) +
                       " (8-bit path costs: got " + std::to_string(p1 + p2) + ")");
  }
  return problems;
}

namespace {

constexpr int kGuard = 64;      // bytes between path entries (the d-1 / d+1 reads)
constexpr int kMaxVector = 64;  // bytes of the widest vector path (AVX-512)
constexpr int kCensusRadius = kDenseCensusWindow / 2;

template <int kBytes>
struct Vec {
  typedef uint8_t U8 __attribute__((vector_size(kBytes)));
  typedef uint16_t U16 __attribute__((vector_size(kBytes)));
  typedef uint8_t Half __attribute__((vector_size(kBytes / 2)));
  static constexpr int k8 = kBytes;
  static constexpr int k16 = kBytes / 2;
};
typedef uint8_t U8x16 __attribute__((vector_size(16)));
typedef uint8_t U8x32 __attribute__((vector_size(32)));
typedef uint16_t U16x8 __attribute__((vector_size(16)));
typedef uint16_t U16x16 __attribute__((vector_size(32)));
typedef uint8_t U8x64 __attribute__((vector_size(64)));
typedef uint16_t U16x32 __attribute__((vector_size(64)));

using simd::Load;
using simd::Store;
// a = min(a, b), lane by lane (in place: no vector return values).
template <typename V>
[[gnu::always_inline]] inline void MinInto(V& a, const V& b) {
  a = b < a ? b : a;
}
template <typename V>
[[gnu::always_inline]] inline V Min(const V& a, const V& b) {
  static_assert(sizeof(V) == 16);
  return a < b ? a : b;
}

[[gnu::always_inline]] inline int HorizontalMin(const U8x16& v) {
  U8x16 a = v;
  a = Min(a, __builtin_shufflevector(a, a, 8, 9, 10, 11, 12, 13, 14, 15, 0, 1, 2, 3, 4, 5, 6, 7));
  a = Min(a, __builtin_shufflevector(a, a, 4, 5, 6, 7, 0, 1, 2, 3, 4, 5, 6, 7, 0, 1, 2, 3));
  a = Min(a, __builtin_shufflevector(a, a, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3, 0, 1));
  a = Min(a, __builtin_shufflevector(a, a, 1, 0, 1, 0, 1, 0, 1, 0, 1, 0, 1, 0, 1, 0, 1, 0));
  return a[0];
}
[[gnu::always_inline]] inline int HorizontalMin(const U16x8& v) {
  U16x8 a = v;
  a = Min(a, __builtin_shufflevector(a, a, 4, 5, 6, 7, 0, 1, 2, 3));
  a = Min(a, __builtin_shufflevector(a, a, 2, 3, 0, 1, 2, 3, 0, 1));
  a = Min(a, __builtin_shufflevector(a, a, 1, 0, 1, 0, 1, 0, 1, 0));
  return a[0];
}

#if defined(__x86_64__) || defined(__i386__)
constexpr bool kX86 = true;
// phminposuw (SSE4.1): the minimum of 8 u16 lanes in one instruction. Not always_inline (its
// target is wider than the templates'): the AVX2 and AVX-512 entry points are `flatten`, which
// inlines it there; the portable path never calls it.
[[gnu::target("sse4.1")]] inline int MinPos(const U16x8& v) {
  return _mm_cvtsi128_si32(_mm_minpos_epu16(std::bit_cast<__m128i>(v))) & 0xffff;
}
#else
constexpr bool kX86 = false;
inline int MinPos(const U16x8& v) { return HorizontalMin(v); }
#endif

// Halves folded by their lane-wise minimum, in place of the narrower vector.
template <typename Narrow, typename Wide>
[[gnu::always_inline]] inline void Fold(Narrow& out, const Wide& v) {
  static_assert(2 * sizeof(Narrow) == sizeof(Wide));
  Narrow hi;
  std::memcpy(&out, &v, sizeof out);
  std::memcpy(&hi, reinterpret_cast<const char*>(&v) + sizeof out, sizeof hi);
  MinInto(out, hi);
}

// The minimum of all lanes of an 8-bit vector: the generic shuffles on the portable path; on the
// wide x86 paths folds to 16 bytes, the pairs of bytes to 16-bit lanes, then phminposuw.
template <int kBytes>
[[gnu::always_inline]] inline int LaneMin8(const typename Vec<kBytes>::U8& v) {
  if constexpr (kX86 && kBytes >= 32) {
    U8x16 a;
    if constexpr (kBytes == 64) {
      U8x32 b;
      Fold(b, v);
      Fold(a, b);
    } else {
      Fold(a, v);
    }
    U16x8 w;
    std::memcpy(&w, &a, sizeof w);
    const U16x8 high = w >> 8;
    U8x16 h;
    std::memcpy(&h, &high, sizeof h);
    MinInto(a, h);  // low byte: min of the pair; high byte: min(high, 0) = 0
    std::memcpy(&w, &a, sizeof w);
    return MinPos(w);
  } else {
    return HorizontalMin(v);
  }
}
// The same for a 16-bit vector.
template <int kBytes>
[[gnu::always_inline]] inline int LaneMin16(const typename Vec<kBytes>::U16& v) {
  if constexpr (kX86 && kBytes >= 32) {
    U16x8 a;
    if constexpr (kBytes == 64) {
      U16x16 b;
      Fold(b, v);
      Fold(a, b);
    } else {
      Fold(a, v);
    }
    return MinPos(a);
  } else {
    return HorizontalMin(v);
  }
}
}  // namespace

// Everything one frame needs, reused across frames of the same size.
struct DenseMatcher::Buffers {
  int width = 0, height = 0, dp = 0, stride = 0, wr = 0, rev_len = 0, nd = 0, min_d = 0;
  cv::Mat padded_l, padded_r;
  std::vector<uint8_t> census_l, census_r;  // 3 planes of height x wr each
  std::vector<uint8_t> right_rev;           // 3 planes of rev_len: one row, reversed
  std::vector<uint8_t> cost;                // width x dp, one row
  // Path entries of `stride` bytes, each after kGuard guard bytes (the d-1 read of entry x and the
  // d+1 read of entry x - 1 share them). `zero` is one all-zero entry: a path starting there
  // gives L = C, as a fresh path does.
  std::vector<uint8_t> zero, lr, rl, top[2], tl[2], tr[2];  // lr, rl: 2 entries; others: width
  std::vector<uint8_t> top_min[2], tl_min[2], tr_min[2];
  std::vector<uint16_t> sum;    // width x dp: the forward paths' sum of one row
  std::vector<uint16_t> total;  // dp: all paths of one pixel
  // One row's winners.
  std::vector<int> best_d;
  std::vector<uint16_t> best_cost, margin;
  std::vector<int16_t> fixed;
  std::vector<uint16_t> own_cost;
  std::vector<int> own_d;
  std::vector<uint8_t> fail;

  void Resize(int w, int h, int num_disparities, int min_disparity, int p1) {
    if (w == width && h == height && num_disparities == nd && min_disparity == min_d) return;
    width = w;
    height = h;
    nd = num_disparities;
    min_d = min_disparity;
    dp = (nd + kMaxVector - 1) / kMaxVector * kMaxVector;
    stride = dp + kGuard;
    wr = (w + kMaxVector - 1) / kMaxVector * kMaxVector;
    rev_len = w + min_d + dp;
    census_l.assign(3 * static_cast<size_t>(h) * wr, 0);
    census_r.assign(3 * static_cast<size_t>(h) * wr, 0);
    right_rev.assign(3 * static_cast<size_t>(rev_len), 0);
    cost.assign(static_cast<size_t>(w) * dp, 0);
    const uint8_t guard = static_cast<uint8_t>(255 - p1);
    auto path = [&](std::vector<uint8_t>& b, int entries) {
      b.assign(static_cast<size_t>(entries) * stride + kGuard, guard);
    };
    zero.assign(static_cast<size_t>(stride) + kGuard, 0);
    path(lr, 2);
    path(rl, 2);
    for (int i = 0; i < 2; ++i) {
      path(top[i], w);
      path(tl[i], w);
      path(tr[i], w);
      top_min[i].assign(w, 0);
      tl_min[i].assign(w, 0);
      tr_min[i].assign(w, 0);
    }
    sum.assign(static_cast<size_t>(w) * dp, 0);
    total.assign(dp, 0);
    best_d.assign(w, 0);
    best_cost.assign(w, 0);
    margin.assign(w, 0);
    fixed.assign(w, 0);
    own_cost.assign(w, 0);
    own_d.assign(w, 0);
    fail.assign(w, 0);
  }
};

namespace {

// Per-frame constants of the kernels.
struct Job {
  DenseMatcher::Buffers* b = nullptr;
  int p1 = 0, p2 = 0, num_paths = 5;
};

// 5x5 census of a padded image (2 px of border all round and kMaxVector more columns on the right)
// into 3 bit planes: bit i of plane i / 8 is set when neighbour i (row-major, the centre skipped)
// is darker than the centre.
template <int kBytes>
[[gnu::always_inline]] inline void Census(const cv::Mat& padded, int width, int height, int wr,
                                          uint8_t* planes) {
  using U8 = typename Vec<kBytes>::U8;
  const size_t plane_size = static_cast<size_t>(height) * wr;
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; x += kBytes) {
      U8 centre, p[3] = {};
      Load(centre, padded.ptr<uint8_t>(y + kCensusRadius) + x + kCensusRadius);
      int i = 0;
      for (int dy = 0; dy < kDenseCensusWindow; ++dy) {
        const uint8_t* row = padded.ptr<uint8_t>(y + dy) + x;
        for (int dx = 0; dx < kDenseCensusWindow; ++dx) {
          if (dy == kCensusRadius && dx == kCensusRadius) continue;
          U8 n;
          Load(n, row + dx);
          const auto darker = n < centre;
          U8 mask;
          std::memcpy(&mask, &darker, sizeof mask);
          // A named uint8_t: under -fsanitize=shift, g++ sees the shift's int in a cast inline.
          const uint8_t bit = static_cast<uint8_t>(1u << (i % 8));
          p[i / 8] |= mask & bit;
          ++i;
        }
      }
      for (int k = 0; k < 3; ++k) Store(planes + k * plane_size + y * wr + x, p[k]);
    }
  }
}

// Hamming costs of one left pixel's census against the right census for dp disparities.
template <int kBytes>
[[gnu::always_inline]] inline void Costs(const uint8_t (&left)[3], const uint8_t* rev, int rev_len,
                                         int dp, uint8_t* out) {
  using U8 = typename Vec<kBytes>::U8;
  for (int k = 0; k < dp; k += kBytes) {
    U8 nibbles = {};
    for (int plane = 0; plane < 3; ++plane) {
      U8 r;
      Load(r, rev + plane * rev_len + k);
      U8 x = r ^ left[plane];
      x = x - ((x >> 1) & static_cast<uint8_t>(0x55));
      x = (x & static_cast<uint8_t>(0x33)) + ((x >> 2) & static_cast<uint8_t>(0x33));
      nibbles += x;  // each nibble <= 12
    }
    const U8 c = (nibbles & static_cast<uint8_t>(0x0f)) + (nibbles >> 4);
    Store(out + k, c);
  }
}

// kN path steps at one pixel: for each path p, L(d) = C(d) + min(Lp(d), Lp(d -+ 1) + p1,
// min Lp + p2) - min Lp over its previous entry prev[p] (min Lp = prev_min[p]), stored to out[p],
// its minimum to mins[p]; and the 16-bit sum of the kN paths (plus `base` when kBase) to `sum`.
// 8-bit throughout: L <= 24 + p2, guards 255 - p1.
template <int kBytes, int kN, bool kBase>
[[gnu::always_inline]] inline void PathSteps(const uint8_t* cost, const uint8_t* const (&prev)[kN],
                                             const int (&prev_min)[kN], uint8_t* const (&out)[kN],
                                             const uint16_t* base, uint16_t* sum, int dp, int p1,
                                             int p2, int (&mins)[kN]) {
  using U8 = typename Vec<kBytes>::U8;
  using U16 = typename Vec<kBytes>::U16;
  using Half = typename Vec<kBytes>::Half;
  constexpr int kL = Vec<kBytes>::k16;
  U8 acc[kN] = {}, pm[kN] = {}, cap[kN] = {}, pen = {};
#pragma GCC unroll 8
  for (int p = 0; p < kN; ++p) {
    acc[p] += static_cast<uint8_t>(255);
    pm[p] += static_cast<uint8_t>(prev_min[p]);
    cap[p] += static_cast<uint8_t>(prev_min[p] + p2);
  }
  pen += static_cast<uint8_t>(p1);
  for (int k = 0; k < dp; k += kBytes) {
    U8 c;
    Load(c, cost + k);
    U16 lo = {}, hi = {};
    if constexpr (kBase) {
      Load(lo, base + k);
      Load(hi, base + k + kL);
    }
#pragma GCC unroll 8
    for (int p = 0; p < kN; ++p) {
      U8 a, m, q;
      Load(a, prev[p] + k);
      Load(m, prev[p] + k - 1);
      Load(q, prev[p] + k + 1);
      U8 t = m;
      MinInto(t, q);
      t += pen;
      MinInto(t, a);
      MinInto(t, cap[p]);
      const U8 l = c + (t - pm[p]);
      Store(out[p] + k, l);
      MinInto(acc[p], l);
      Half h;
      std::memcpy(&h, &l, sizeof h);
      lo += __builtin_convertvector(h, U16);
      std::memcpy(&h, reinterpret_cast<const char*>(&l) + sizeof h, sizeof h);
      hi += __builtin_convertvector(h, U16);
    }
    Store(sum + k, lo);
    Store(sum + k + kL, hi);
  }
#pragma GCC unroll 8
  for (int p = 0; p < kN; ++p) mins[p] = LaneMin8<kBytes>(acc[p]);
}

// Row y of the right census, reversed (j = w - 1 - x, column 0's census left of the image).
inline void ReverseRightRow(DenseMatcher::Buffers& b, int y) {
  const int w = b.width;
  const size_t plane_size = static_cast<size_t>(b.height) * b.wr;
  for (int k = 0; k < 3; ++k) {
    const uint8_t* src = b.census_r.data() + k * plane_size + static_cast<size_t>(y) * b.wr;
    uint8_t* dst = b.right_rev.data() + k * b.rev_len;
    std::reverse_copy(src, src + w, dst);
    std::memset(dst + w, src[0], b.rev_len - w);
  }
}

// The forward pass of row y: costs, then the left-to-right, top, top-left and top-right paths and
// their sum.
template <int kBytes>
[[gnu::always_inline]] inline void ForwardRow(const Job& job, int y) {
  DenseMatcher::Buffers& b = *job.b;
  const int w = b.width, dp = b.dp, st = b.stride;
  const int cur = y & 1, prv = cur ^ 1;
  const size_t plane_size = static_cast<size_t>(b.height) * b.wr;
  ReverseRightRow(b, y);
  const uint8_t* zero = b.zero.data() + kGuard;
  uint8_t* lr = b.lr.data() + kGuard;
  const uint8_t *top_p = b.top[prv].data() + kGuard, *tl_p = b.tl[prv].data() + kGuard,
                *tr_p = b.tr[prv].data() + kGuard;
  uint8_t *top_c = b.top[cur].data() + kGuard, *tl_c = b.tl[cur].data() + kGuard,
          *tr_c = b.tr[cur].data() + kGuard;
  const uint8_t *top_min = b.top_min[prv].data(), *tl_min = b.tl_min[prv].data(),
                *tr_min = b.tr_min[prv].data();
  const int j_base = w - 1 + b.min_d;
  int lr_min = 0;
  for (int x = 0; x < w; ++x) {
    uint8_t left[3];
    for (int k = 0; k < 3; ++k) left[k] = b.census_l[k * plane_size + y * b.wr + x];
    uint8_t* c = b.cost.data() + static_cast<size_t>(x) * dp;
    Costs<kBytes>(left, b.right_rev.data() + (j_base - x), b.rev_len, dp, c);
    if (b.nd < dp) std::memset(c + b.nd, kDenseMaxCost, dp - b.nd);
    const size_t at = static_cast<size_t>(x) * st;
    const bool up = y > 0, tl = up && x > 0, tr = up && x + 1 < w;
    const uint8_t* const prev[4] = {x > 0 ? lr + ((x - 1) & 1) * st : zero, up ? top_p + at : zero,
                                    tl ? tl_p + at - st : zero, tr ? tr_p + at + st : zero};
    const int prev_min[4] = {x > 0 ? lr_min : 0, up ? top_min[x] : 0, tl ? tl_min[x - 1] : 0,
                             tr ? tr_min[x + 1] : 0};
    uint8_t* const out[4] = {lr + (x & 1) * st, top_c + at, tl_c + at, tr_c + at};
    int mins[4];
    PathSteps<kBytes, 4, false>(c, prev, prev_min, out, nullptr,
                                b.sum.data() + static_cast<size_t>(x) * dp, dp, job.p1, job.p2,
                                mins);
    lr_min = mins[0];
    b.top_min[cur][x] = static_cast<uint8_t>(mins[1]);
    b.tl_min[cur][x] = static_cast<uint8_t>(mins[2]);
    b.tr_min[cur][x] = static_cast<uint8_t>(mins[3]);
  }
}

// Winner takes all over the aggregated costs `sum` (nd of them, rounded up to the vector: the
// caller sets the lanes past nd to 0xffff): the best disparity index, its cost, and the margin of
// the second best at least 2 disparities away.
template <int kBytes>
[[gnu::always_inline]] inline int Winner(const uint16_t* sum, int nd, int& best_cost,
                                         int& second_cost) {
  using U16 = typename Vec<kBytes>::U16;
  constexpr int kL = Vec<kBytes>::k16;
  U16 big = {}, idx = {};
  big += static_cast<uint16_t>(0xffff);
  for (int i = 0; i < kL; ++i) idx[i] = static_cast<uint16_t>(i);
  U16 mn = big;
  for (int k = 0; k < nd; k += kL) {
    U16 s;
    Load(s, sum + k);
    MinInto(mn, s);
  }
  best_cost = LaneMin16<kBytes>(mn);
  U16 bv = {}, im = big;
  bv += static_cast<uint16_t>(best_cost);
  for (int k = 0; k < nd; k += kL) {
    U16 s;
    Load(s, sum + k);
    const U16 lane = idx + static_cast<uint16_t>(k);
    const U16 cand = s == bv ? lane : big;
    MinInto(im, cand);
  }
  const int best = LaneMin16<kBytes>(im);
  const uint16_t lo = static_cast<uint16_t>(best - 1);
  U16 m2 = big;
  for (int k = 0; k < nd; k += kL) {
    U16 s;
    Load(s, sum + k);
    const U16 dist = (idx + static_cast<uint16_t>(k)) - lo;
    const U16 cand = dist <= static_cast<uint16_t>(2) ? big : s;
    MinInto(m2, cand);
  }
  second_cost = LaneMin16<kBytes>(m2);
  return best;
}

// The backward pass of row y: the right-to-left path added to the forward sum, and the winner
// with its sub-pixel refinement.
template <int kBytes>
[[gnu::always_inline]] inline void BackwardRow(const Job& job) {
  DenseMatcher::Buffers& b = *job.b;
  const int w = b.width, dp = b.dp, st = b.stride, nd = b.nd;
  const uint8_t* zero = b.zero.data() + kGuard;
  uint8_t* rl = b.rl.data() + kGuard;
  int rl_min = 0;
  for (int x = w - 1; x >= 0; --x) {
    uint16_t* sum = b.sum.data() + static_cast<size_t>(x) * dp;
    if (job.num_paths == 5) {
      const uint8_t* const prev[1] = {x + 1 < w ? rl + ((x + 1) & 1) * st : zero};
      const int prev_min[1] = {x + 1 < w ? rl_min : 0};
      uint8_t* const out[1] = {rl + (x & 1) * st};
      int mins[1];
      PathSteps<kBytes, 1, true>(b.cost.data() + static_cast<size_t>(x) * dp, prev, prev_min, out,
                                 sum, b.total.data(), dp, job.p1, job.p2, mins);
      rl_min = mins[0];
      sum = b.total.data();
    }
    // Lanes past nd (the last vector of a wide path) never win.
    if (nd % Vec<kBytes>::k16 != 0) {
      std::fill(sum + nd, sum + dp, static_cast<uint16_t>(0xffff));
    }
    int best_cost = 0, second_cost = 0;
    const int best = Winner<kBytes>(sum, nd, best_cost, second_cost);
    int fixed = (b.min_d + best) * DisparityMap::kScale;
    if (best > 0 && best + 1 < nd) {
      const int a = sum[best - 1], c = sum[best + 1];
      const int den = a + c - 2 * best_cost;
      if (den > 0) {
        // Parabola through the three costs, rounded half away from zero to 1/16 px.
        const int num = DisparityMap::kScale * (a - c);
        fixed += (num >= 0 ? num + den : num - den) / (2 * den);
      }
    }
    b.best_d[x] = best;
    b.best_cost[x] = static_cast<uint16_t>(best_cost);
    b.margin[x] = static_cast<uint16_t>(std::min(second_cost - best_cost, 0xffff));
    b.fixed[x] = static_cast<int16_t>(fixed);
  }
}
template <int kBytes>
[[gnu::always_inline]] inline void Aggregate(const Job& job, const cv::Mat& left,
                                             const cv::Mat& right,
                                             void (*row_done)(const Job&, int, void*), void* ctx) {
  DenseMatcher::Buffers& b = *job.b;
  const int pad = kCensusRadius;
  cv::copyMakeBorder(left, b.padded_l, pad, pad, pad, pad + kMaxVector, cv::BORDER_REPLICATE);
  cv::copyMakeBorder(right, b.padded_r, pad, pad, pad, pad + kMaxVector, cv::BORDER_REPLICATE);
  Census<kBytes>(b.padded_l, b.width, b.height, b.wr, b.census_l.data());
  Census<kBytes>(b.padded_r, b.width, b.height, b.wr, b.census_r.data());
  for (int y = 0; y < b.height; ++y) {
    ForwardRow<kBytes>(job, y);
    BackwardRow<kBytes>(job);
    row_done(job, y, ctx);
  }
}

using AggregateFn = void (*)(const Job&, const cv::Mat&, const cv::Mat&,
                             void (*)(const Job&, int, void*), void*);

void AggregatePortable(const Job& job, const cv::Mat& l, const cv::Mat& r,
                       void (*done)(const Job&, int, void*), void* ctx) {
  Aggregate<16>(job, l, r, done, ctx);
}
#if defined(__x86_64__) || defined(__i386__)
__attribute__((target("avx2"), flatten)) void AggregateAvx2(const Job& job, const cv::Mat& l,
                                                            const cv::Mat& r,
                                                            void (*done)(const Job&, int, void*),
                                                            void* ctx) {
  Aggregate<32>(job, l, r, done, ctx);
}
__attribute__((target("avx512f,avx512bw,avx512vl"), flatten)) void AggregateAvx512(
    const Job& job, const cv::Mat& l, const cv::Mat& r, void (*done)(const Job&, int, void*),
    void* ctx) {
  Aggregate<64>(job, l, r, done, ctx);
}
#endif

bool HasAvx2() {
#if defined(__x86_64__) || defined(__i386__)
  return __builtin_cpu_supports("avx2");
#else
  return false;
#endif
}
bool HasAvx512() {
#if defined(__x86_64__) || defined(__i386__)
  return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") &&
         __builtin_cpu_supports("avx512vl");
#else
  return false;
#endif
}

// What one row's post-processing writes to.
struct RowSink {
  DisparityMap* out;
  cv::Mat1w* margin;
  cv::Mat1b* filled;
  int lr_max_diff;
  bool fill_holes;
};

// The left-right check on one row: each right-image pixel belongs to the left pixel with the
// lowest aggregated cost among those whose winner lands on it; a left pixel whose right pixel
// belongs to a disparity more than lr_max_diff away fails (occluded, or a mismatch). Failures are
// filled with the smaller of the nearest measured disparities on either side, or left unmatched.
void FinishRow(const Job& job, int y, void* ctx) {
  const RowSink& sink = *static_cast<const RowSink*>(ctx);
  DenseMatcher::Buffers& b = *job.b;
  const int w = b.width;
  int16_t* dst = sink.out->fixed.ptr<int16_t>(y);
  uint16_t* margin = sink.margin->ptr<uint16_t>(y);
  uint8_t* filled = sink.filled->ptr<uint8_t>(y);
  std::fill(b.own_cost.begin(), b.own_cost.end(), 0xffff);
  std::fill(b.fail.begin(), b.fail.end(), 0);
  if (sink.lr_max_diff >= 0) {
    for (int x = 0; x < w; ++x) {
      const int xr = x - b.min_d - b.best_d[x];
      if (xr >= 0 && b.best_cost[x] < b.own_cost[xr]) {
        b.own_cost[xr] = b.best_cost[x];
        b.own_d[xr] = b.best_d[x];
      }
    }
    for (int x = 0; x < w; ++x) {
      const int xr = x - b.min_d - b.best_d[x];
      b.fail[x] = xr >= 0 && std::abs(b.own_d[xr] - b.best_d[x]) > sink.lr_max_diff;
    }
  }
  for (int x = 0; x < w; ++x) {
    dst[x] = b.fail[x] ? DisparityMap::kInvalid : b.fixed[x];
    margin[x] = b.fail[x] ? 0 : b.margin[x];
    filled[x] = 0;
  }
  if (!sink.fill_holes) return;
  // Nearest measured value on the left, then on the right: the smaller (background) wins.
  int16_t last = DisparityMap::kInvalid;
  for (int x = 0; x < w; ++x) {
    if (!b.fail[x]) {
      last = dst[x];
    } else {
      b.fixed[x] = last;  // reused as the left neighbour's value
    }
  }
  last = DisparityMap::kInvalid;
  for (int x = w - 1; x >= 0; --x) {
    if (!b.fail[x]) {
      last = dst[x];
      continue;
    }
    const int16_t from_left = b.fixed[x];
    int16_t v = from_left < 0 ? last : (last < 0 ? from_left : std::min(from_left, last));
    dst[x] = v;
    filled[x] = v >= 0;
  }
}

}  // namespace

DenseMatcher::DenseMatcher(const DenseMatcherOptions& options)
    : options_(options), buffers_(std::make_unique<Buffers>()) {
  CV_Assert(options.Validate().empty());
  margin_log_.resize(kMarginBins);
  for (int m = 0; m < kMarginBins; ++m) {
    margin_log_[m] = static_cast<float>(std::log1p(static_cast<double>(m) / options_.num_paths));
  }
  logistic_.resize(2 * kZRange * kZSteps + 1);
  for (size_t i = 0; i < logistic_.size(); ++i) {
    const double z = static_cast<double>(i) / kZSteps - kZRange;
    logistic_[i] =
        static_cast<uint8_t>(std::clamp(std::lround(255.0 / (1.0 + std::exp(-z))), 1L, 255L));
  }
}

DenseMatcher::~DenseMatcher() = default;

DisparityMap DenseMatcher::Compute(const cv::Mat& left_rect, const cv::Mat& right_rect) {
  CV_Assert(left_rect.type() == CV_8UC1 && right_rect.type() == CV_8UC1);
  CV_Assert(left_rect.size() == right_rect.size());
  DisparityMap out;
  out.min_disparity = options_.min_disparity;
  out.num_disparities = options_.num_disparities;
  out.block_size = kDenseCensusWindow;
  if (left_rect.empty()) return out;
  out.fixed.create(left_rect.size());
  out.confidence.create(left_rect.size());
  cues_.margin.create(left_rect.size());
  cues_.filled.create(left_rect.size());
  if (left_rect.rows < kDenseCensusWindow || left_rect.cols < kDenseCensusWindow) {
    out.fixed.setTo(DisparityMap::kInvalid);
    out.confidence.setTo(0);
    cues_.margin.setTo(0);
    cues_.filled.setTo(0);
    cues_.texture_ratio = cv::Mat1f(left_rect.size(), 0.0f);
    cues_.structure = cv::Mat1f(left_rect.size(), 0.0f);
    cues_.agreement = cv::Mat1b(left_rect.size(), uint8_t{0});
    return out;
  }
  buffers_->Resize(left_rect.cols, left_rect.rows, options_.num_disparities, options_.min_disparity,
                   options_.p1);
  Job job;
  job.b = buffers_.get();
  job.p1 = options_.p1;
  job.p2 = options_.p2;
  job.num_paths = options_.num_paths;
  RowSink sink{&out, &cues_.margin, &cues_.filled, options_.lr_max_diff, options_.fill_holes};
  AggregateFn aggregate = AggregatePortable;
#if defined(__x86_64__) || defined(__i386__)
  if (path_ != SimdPath::kPortable && HasAvx2()) aggregate = AggregateAvx2;
  if (path_ == SimdPath::kBest && HasAvx512()) aggregate = AggregateAvx512;
#endif
  aggregate(job, left_rect, right_rect, FinishRow, &sink);
  Confidence(left_rect, out);
  return out;
}

}  // namespace stevi::stereo
