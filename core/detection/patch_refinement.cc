// The patch refinement: the sub-pixel disparity of one region measured on the rectified pair at
// the camera's own resolution (RefineDisparity, declared in regions.h), from small patches fitted
// by Gauss-Newton, and the hypothesis' range from it (RefineOnFullPair, patch_refinement.h).
#include "core/detection/patch_refinement.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <vector>

#include <opencv2/imgproc.hpp>

namespace stevi::detection {
namespace {

// At most this many patches carry the sub-pixel fit (an even subsample), and at least this many.
constexpr int kMaxRefinePatches = 40;
constexpr int kMinRefinePatches = 5;
// What the patches' scatter does not show: the bias of bilinear interpolation and of sampling that
// every patch shares (pixels, added in quadrature; about what regions_test measures on rendered
// boxes, whose errors it leaves at 1 sigma rms).
constexpr double kRefineSystematicPx = 0.03;

// RefineDisparity's patches: 7 x 7, each moving at most kSearchPx from the initial disparity.
constexpr int kHalf = 3;
constexpr double kSearchPx = 2.0;
constexpr int kSide = 2 * kHalf + 1, kCount = kSide * kSide;
constexpr int kOuter = kSide + 2;  // one more pixel around, for the right image's gradients

struct Seed {
  int gx;
  cv::Point at;
};

// The patches' centres: on a grid of cells (5 px, larger for large objects, so that about twice
// kMaxRefinePatches cells cover the box), in each cell's middle row the mask pixel of strongest
// horizontal gradient, so that the patches barely overlap and their errors are nearly
// independent. At most kMaxRefinePatches (an even subsample); fewer than kMinRefinePatches are
// too few to refine with.
std::vector<Seed> PatchSeeds(const cv::Mat1b& left, const cv::Mat1b& mask, const cv::Rect& box,
                             double initial_px) {
  const int cell = std::max(5, static_cast<int>(std::lround(std::sqrt(
                                   static_cast<double>(box.area()) / (2.0 * kMaxRefinePatches)))));
  const int margin = kHalf + 3;
  std::vector<Seed> seeds;
  for (int cy = 0; cy < box.height; cy += cell) {
    const int y = std::min(cy + cell / 2, box.height - 1);
    const int v = box.y + y;
    if (v < margin || v >= left.rows - margin) continue;
    const uchar* m = mask[y];
    const uchar* row = left[v];
    for (int cx = 0; cx < box.width; cx += cell) {
      Seed best{0, {}};
      for (int x = cx; x < std::min(cx + cell, box.width); ++x) {
        const int u = box.x + x;
        if (!m[x] || u < margin || u >= left.cols - margin || u - initial_px - kSearchPx < margin ||
            u - initial_px + kSearchPx >= left.cols - margin) {
          continue;
        }
        const int gx = std::abs(row[u + 1] - row[u - 1]);
        if (gx > best.gx) best = {gx, cv::Point(u, v)};
      }
      if (best.gx >= 2) seeds.push_back(best);
    }
  }
  if (static_cast<int>(seeds.size()) < kMinRefinePatches) return seeds;
  if (static_cast<int>(seeds.size()) > kMaxRefinePatches) {
    // An even subsample: every part of the object counts alike.
    std::vector<Seed> kept;
    kept.reserve(kMaxRefinePatches);
    const double step = static_cast<double>(seeds.size()) / kMaxRefinePatches;
    for (int i = 0; i < kMaxRefinePatches; ++i)
      kept.push_back(seeds[static_cast<size_t>(i * step)]);
    seeds.swap(kept);
  }

  return seeds;
}

using LeftPatch = std::array<float, kCount>;
using RightWindow = std::array<float, kOuter * kOuter>;

// The left image's patch around the seed, less its mean; `energy` gets its sum of squares.
LeftPatch ZeroMeanLeft(const cv::Mat1b& left, const Seed& seed, double& energy) {
  LeftPatch l{};
  double l_mean = 0;
  for (int j = 0, i = 0; j < kSide; ++j) {
    const uchar* row = left[seed.at.y - kHalf + j];
    for (int k = 0; k < kSide; ++k, ++i) {
      l[i] = row[seed.at.x - kHalf + k];
      l_mean += l[i];
    }
  }
  l_mean /= kCount;
  double l_energy = 0;
  for (float& v : l) {
    v = static_cast<float>(v - l_mean);
    l_energy += v * v;
  }
  energy = l_energy;
  return l;
}

// The right image around the patch's match, shifted by (d, e), one pixel wider on every side:
// every sample shares the sub-pixel weights. False when the window leaves the image.
bool SampleRight(const cv::Mat1b& right, const Seed& seed, double d, double e, RightWindow& r) {
  const double x0 = seed.at.x - kHalf - 1 - d, y0 = seed.at.y - kHalf - 1 + e;
  const int ix = static_cast<int>(std::floor(x0)), iy = static_cast<int>(std::floor(y0));
  if (ix < 0 || iy < 0 || ix + kOuter + 1 >= right.cols || iy + kOuter + 1 >= right.rows) {
    return false;
  }
  const float fx = static_cast<float>(x0 - ix), fy = static_cast<float>(y0 - iy);
  const float w00 = (1 - fx) * (1 - fy), w10 = fx * (1 - fy), w01 = (1 - fx) * fy, w11 = fx * fy;
  for (int j = 0; j < kOuter; ++j) {
    const uchar* r0 = right[iy + j] + ix;
    const uchar* r1 = right[iy + j + 1] + ix;
    float* out = &r[j * kOuter];
    for (int k = 0; k < kOuter; ++k) {
      out[k] = w00 * r0[k] + w10 * r0[k + 1] + w01 * r1[k] + w11 * r1[k + 1];
    }
  }
  return true;
}

// The Gauss-Newton step for (d, e) from the zero-mean left patch and the shifted right window;
// nullopt when the fit is ill-conditioned.
std::optional<std::array<double, 2>> GaussNewtonStep(const LeftPatch& l, const RightWindow& r) {
  double r_mean = 0;
  for (int j = 1; j <= kSide; ++j) {
    for (int k = 1; k <= kSide; ++k) r_mean += r[j * kOuter + k];
  }
  r_mean /= kCount;
  // residual = L - R(x - d, y + e): d(res)/dd = Rx, d(res)/de = -Ry.
  double a11 = 0, a12 = 0, a22 = 0, b1 = 0, b2 = 0;
  for (int j = 1, i = 0; j <= kSide; ++j) {
    const float* row = &r[j * kOuter];
    for (int k = 1; k <= kSide; ++k, ++i) {
      const double res = l[i] - (row[k] - r_mean);
      const double jd = 0.5 * (row[k + 1] - row[k - 1]);
      const double je = -0.5 * (row[k + kOuter] - row[k - kOuter]);
      a11 += jd * jd;
      a12 += jd * je;
      a22 += je * je;
      b1 += jd * res;
      b2 += je * res;
    }
  }
  const double det = a11 * a22 - a12 * a12;
  if (a11 < 1.0 || det <= 1e-9 * a11 * a22) return std::nullopt;
  return std::array<double, 2>{-(a22 * b1 - a12 * b2) / det, -(a11 * b2 - a12 * b1) / det};
}

// One patch: zero-mean SSD (a gain and an offset between the views drop out), translation
// (dx, dy) by Gauss-Newton from the initial disparity: the vertical term takes up a residual
// misalignment of the rectification. nullopt for a flat patch, one that leaves the image or the
// search range, or an ill-conditioned fit.
std::optional<double> PatchDisparity(const cv::Mat1b& left, const cv::Mat1b& right,
                                     const Seed& seed, double initial_px) {
  double l_energy = 0;
  const LeftPatch l = ZeroMeanLeft(left, seed, l_energy);
  if (l_energy < 4.0 * kCount) return std::nullopt;  // flat: below a grey level rms
  RightWindow r{};
  double d = initial_px, e = 0;
  bool ok = true;
  for (int iteration = 0; iteration < 5 && ok; ++iteration) {
    if (!SampleRight(right, seed, d, e, r)) {
      ok = false;
      break;
    }
    const std::optional<std::array<double, 2>> step = GaussNewtonStep(l, r);
    if (!step) {
      ok = false;
      break;
    }
    const double step_d = (*step)[0];
    const double step_e = (*step)[1];
    d += std::clamp(step_d, -0.5, 0.5);
    e = std::clamp(e + std::clamp(step_e, -0.5, 0.5), -1.0, 1.0);
    if (std::abs(d - initial_px) > kSearchPx) ok = false;
    if (std::abs(step_d) < 2e-3 && std::abs(step_e) < 2e-3) break;
  }
  if (!ok) return std::nullopt;
  return d;
}

}  // namespace

std::optional<RefinedDisparity> RefineDisparity(const cv::Mat1b& left, const cv::Mat1b& right,
                                                const cv::Mat1b& mask, const cv::Rect& box,
                                                double initial_px) {
  if (left.empty() || right.empty() || left.size() != right.size() || !(initial_px > 0)) {
    return std::nullopt;
  }
  const std::vector<Seed> seeds = PatchSeeds(left, mask, box, initial_px);
  if (static_cast<int>(seeds.size()) < kMinRefinePatches) return std::nullopt;
  std::vector<double> estimates;
  estimates.reserve(seeds.size());
  for (const Seed& seed : seeds) {
    if (const std::optional<double> d = PatchDisparity(left, right, seed, initial_px))
      estimates.push_back(*d);
  }
  const int n = static_cast<int>(estimates.size());
  if (n < kMinRefinePatches) return std::nullopt;
  std::sort(estimates.begin(), estimates.end());
  const double median = n % 2 ? estimates[n / 2] : 0.5 * (estimates[n / 2 - 1] + estimates[n / 2]);
  std::vector<double> deviations(n);
  for (int i = 0; i < n; ++i) deviations[i] = std::abs(estimates[i] - median);
  std::nth_element(deviations.begin(), deviations.begin() + n / 2, deviations.end());
  // The median of n independent patch estimates: 1.2533 * sigma / sqrt(n), with the patches'
  // scatter from their median absolute deviation.
  const double scatter = 1.4826 * deviations[n / 2];
  RefinedDisparity out;
  out.disparity_px = median;
  const double random = 1.2533 * scatter / std::sqrt(static_cast<double>(n));
  out.sigma_px = std::hypot(random, kRefineSystematicPx);
  out.pixels = n;
  return out;
}

std::optional<RefinedDisparity> RefineOnFullPair(const FullResolutionPair& full,
                                                 const cv::Mat1s& fixed, const cv::Mat1b& classes,
                                                 const cv::Rect& box, const cv::Mat1b& mask,
                                                 double median_px) {
  constexpr int kScale = stereo::DisparityMap::kScale;
  const int k = std::max(1, full.binning);
  const cv::Rect full_box = cv::Rect(box.x * k, box.y * k, box.width * k, box.height * k) &
                            cv::Rect(0, 0, full.left.cols, full.left.rows);
  // The fit runs over the pixels at the hypothesis' own range (a box's oblique faces and a
  // halo at other disparities would pull it off its nearest face).
  const int band =
      std::max(kScale * 3 / 8, static_cast<int>(std::lround(0.02 * median_px * kScale)));
  const int median_fixed = static_cast<int>(std::lround(median_px * kScale));
  cv::Mat1b at_range(mask.size());
  for (int y = 0; y < mask.rows; ++y) {
    const int16_t* dd = fixed[box.y + y] + box.x;
    const uchar* c = classes[box.y + y] + box.x;
    const uchar* m = mask[y];
    uchar* o = at_range[y];
    for (int x = 0; x < mask.cols; ++x) {
      const bool near =
          (m[x] != 0) & (c[x] == kCandidate) & (std::abs(dd[x] - median_fixed) <= band);
      o[x] = near ? 255 : 0;
    }
  }
  cv::Mat1b full_mask;
  cv::resize(at_range, full_mask, cv::Size(box.width * k, box.height * k), 0, 0, cv::INTER_NEAREST);
  full_mask = full_mask(cv::Rect(0, 0, full_box.width, full_box.height));
  const std::optional<RefinedDisparity> refined =
      RefineDisparity(full.left, full.right, full_mask, full_box, median_px * k);
  if (!refined || !(std::abs(refined->disparity_px - median_px * k) <=
                    std::max(1.5 * k, 0.2 * median_px * k))) {
    return std::nullopt;
  }
  RefinedDisparity out = *refined;
  out.disparity_px = refined->disparity_px / k;
  out.sigma_px = refined->sigma_px / k;
  return out;
}

}  // namespace stevi::detection
