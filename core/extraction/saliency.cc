#include "core/extraction/saliency.h"

#include "core/common/error.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <set>
#include <string>
#include <vector>

#include <opencv2/imgproc.hpp>

namespace stevi::extraction {
namespace {

// Problems of a list's repeated entries, each named by its index ("scales[1]").
void CheckDistinct(const char* name, const std::vector<int>& values,
                   std::vector<std::string>& problems) {
  std::set<int> seen;
  for (size_t i = 0; i < values.size(); ++i) {
    if (!seen.insert(values[i]).second) {
      problems.push_back(std::string(name) + "[" + std::to_string(i) +
                         "]: repeats an earlier value" + Got(values[i]));
    }
  }
}

// Index for BORDER_REFLECT_101 (..., 2, 1 | 0, 1, ..., n-1 | n-2, ...), for i in [-1, n].
inline int Reflect(int i, int n) {
  if (n == 1) return 0;
  if (i < 0) return -i;
  if (i >= n) return 2 * n - 2 - i;
  return i;
}

// The horizontal pass of Down on one row: the 3x3 Gaussian's horizontal [1 2 1] / 4, then the
// average of columns 2x and 2x + 1 (clamped for a one-column image).
void DownRow(const float* src, int w, float* dst, int w_out) {
  const int last = w - 1;
  const auto blurred = [&](int b) {
    return 0.25f * (src[Reflect(b - 1, w)] + src[Reflect(b + 1, w)]) + 0.5f * src[b];
  };
  const auto general = [&](int x) {
    return 0.5f * (blurred(2 * x) + blurred(std::min(2 * x + 1, last)));
  };
  // Interior: columns 2x - 1 .. 2x + 2 are all inside, and the taps are [1 3 3 1] / 8.
  const int x_end = std::min(w_out, (w - 2) / 2);  // 2x + 2 <= w - 1
  dst[0] = general(0);
  int x = 1;
  for (; x < x_end; ++x) {
    const float* p = src + 2 * x - 1;
    dst[x] = 0.125f * (p[0] + p[3]) + 0.375f * (p[1] + p[2]);
  }
  for (; x < w_out; ++x) dst[x] = general(x);
}

// One pyramid step (see the header): 3x3 Gaussian with BORDER_REFLECT_101, then 2x2 block
// average, fused into one separable pass that only filters the rows and columns it keeps and
// allocates no full-size temporary. Works on 8-bit level 0 directly. Per output row: the
// vertical pass over the (at most 4) source rows it needs, contiguous, then the horizontal pass.
template <typename T>
cv::Mat1f Down(const cv::Mat_<T>& level) {
  CV_Assert(!level.empty());
  const int w = level.cols, h = level.rows;
  const int w_out = std::max(1, w / 2), h_out = std::max(1, h / 2);
  cv::Mat1f out(h_out, w_out);
  std::vector<float> column_pass(static_cast<size_t>(w));
  float* tmp = column_pass.data();
  const int last = h - 1;
  for (int y = 0; y < h_out; ++y) {
    // Vertical [1 2 1] / 4 around rows a1 = 2y and a2 = 2y + 1 (clamped), averaged: weights
    // [1 3 3 1] / 8 on rows 2y - 1 .. 2y + 2 inside the image, merged where rows reflect.
    const int a1 = 2 * y, a2 = std::min(2 * y + 1, last);
    const int taps[6] = {Reflect(a1 - 1, h), a1, Reflect(a1 + 1, h),
                         Reflect(a2 - 1, h), a2, Reflect(a2 + 1, h)};
    constexpr float kTapWeights[6] = {0.125f, 0.25f, 0.125f, 0.125f, 0.25f, 0.125f};
    int rows[6];
    float weights[6];
    int n = 0;
    for (int t = 0; t < 6; ++t) {
      int i = 0;
      while (i < n && rows[i] != taps[t]) ++i;
      if (i == n) {
        rows[n] = taps[t];
        weights[n++] = 0.0f;
      }
      weights[i] += kTapWeights[t];
    }
    const T* src = level[rows[0]];
    for (int x = 0; x < w; ++x) tmp[x] = weights[0] * static_cast<float>(src[x]);
    for (int i = 1; i < n; ++i) {
      src = level[rows[i]];
      const float k = weights[i];
      for (int x = 0; x < w; ++x) tmp[x] += k * static_cast<float>(src[x]);
    }
    DownRow(tmp, w, out[y], w_out);
  }
  return out;
}

// Levels 0..top of the pyramid; level 0 (a float copy of the input) stays empty unless asked
// for, since level 1 is computed from the 8-bit input directly.
std::vector<cv::Mat1f> Pyramid(const cv::Mat1b& grey, int top, bool with_level0) {
  CV_Assert(top >= 0);
  std::vector<cv::Mat1f> pyramid(static_cast<size_t>(top) + 1);
  if (grey.empty()) return {};
  if (with_level0 || top == 0) grey.convertTo(pyramid[0], CV_32F);
  if (top >= 1) pyramid[1] = Down(grey);
  for (int k = 2; k <= top; ++k) pyramid[k] = Down(pyramid[k - 1]);
  return pyramid;
}

// Centre-surround of `level` for one radius, from its integral image (double, (h+1) x (w+1)).
void CentreSurroundFromIntegral(const cv::Mat1f& level, const cv::Mat1d& integral, int radius,
                                cv::Mat1f& on, cv::Mat1f& off) {
  const int w = level.cols, h = level.rows;
  on.create(h, w);
  off.create(h, w);
  for (int y = 0; y < h; ++y) {
    const int y0 = std::max(0, y - radius), y1 = std::min(h - 1, y + radius);
    const double* top = integral[y0];
    const double* bottom = integral[y1 + 1];
    const int box_h = y1 - y0 + 1;
    const float* c = level[y];
    float* on_row = on[y];
    float* off_row = off[y];
    for (int x = 0; x < w; ++x) {
      const int x0 = std::max(0, x - radius), x1 = std::min(w - 1, x + radius);
      const int n = box_h * (x1 - x0 + 1);
      const double sum = bottom[x1 + 1] - bottom[x0] - top[x1 + 1] + top[x0];
      // The surround excludes the centre; a 1x1 level has no surround and no contrast.
      const double surround = n > 1 ? (sum - c[x]) / (n - 1) : c[x];
      const double d = c[x] - surround;
      on_row[x] = d > 0 ? static_cast<float>(d) : 0.0f;
      off_row[x] = d < 0 ? static_cast<float>(-d) : 0.0f;
    }
  }
}

// `map` from level s brought to `size` at level c (step 3).
cv::Mat1f ToCentreLevel(const cv::Mat1f& map, int s, int c, cv::Size size) {
  if (s >= c) return UpsampleOctaves(map, s - c, size);
  cv::Mat1f out = map;
  for (int k = s; k < c; ++k) out = Down(out);
  CV_Assert(out.size() == size);
  return out;
}

// Step 4, given the peak counts of ON and OFF.
cv::Mat1f Fuse(const cv::Mat1f& on, const cv::Mat1f& off, int on_peaks, int off_peaks,
               const SaliencyOptions& options) {
  CV_Assert(on.size() == off.size());
  double on_weight = 1, off_weight = 1;
  if (options.uniqueness_weight) {
    on_weight = 1 / std::sqrt(std::max(1, on_peaks));
    off_weight = 1 / std::sqrt(std::max(1, off_peaks));
  }
  cv::Mat1f saliency;
  cv::addWeighted(on, on_weight, off, off_weight, 0, saliency);
  double max_value = 0;
  cv::minMaxLoc(saliency, nullptr, &max_value);
  const double denominator = std::max(max_value, options.min_contrast);
  if (denominator > 0) {
    saliency *= 1 / denominator;
  } else {
    saliency.setTo(0);
  }
  return saliency;
}

}  // namespace

std::vector<std::string> SaliencyOptions::Validate() const {
  std::vector<std::string> problems = fields::Check(*this);
  CheckDistinct("scales", scales, problems);
  CheckDistinct("surround_radii", surround_radii, problems);
  return problems;
}

cv::Mat1f PyramidDown(const cv::Mat1f& level) { return Down(level); }

std::vector<cv::Mat1f> BuildGreyPyramid(const cv::Mat1b& grey, int top_level) {
  return Pyramid(grey, top_level, /*with_level0=*/true);
}

void CentreSurround(const cv::Mat1f& level, int radius, cv::Mat1f& on, cv::Mat1f& off) {
  CV_Assert(radius >= 1 && !level.empty());
  cv::Mat1d integral;
  cv::integral(level, integral, CV_64F);
  CentreSurroundFromIntegral(level, integral, radius, on, off);
}

cv::Mat1f UpsampleOctaves(const cv::Mat1f& map, int octaves, cv::Size size) {
  CV_Assert(octaves >= 0 && octaves < 16 && !map.empty());
  if (octaves == 0 && map.size() == size) return map.clone();
  // cv::resize with an exact integer scale maps fine pixel X to coarse u = (X + 0.5) / scale - 0.5
  // and replicates the edges, which is the pyramid's alignment. The scaled map is then cut or
  // extended (edge replicated, as the bilinear sampling would) to `size`: the pyramid drops odd
  // rows and columns, so `size` may exceed map.size() * scale by up to scale - 1 pixels.
  const int scale = 1 << octaves;
  cv::Mat1f scaled;
  cv::resize(map, scaled, cv::Size(map.cols * scale, map.rows * scale), 0, 0, cv::INTER_LINEAR);
  const int extra_x = std::max(0, size.width - scaled.cols);
  const int extra_y = std::max(0, size.height - scaled.rows);
  if (extra_x > 0 || extra_y > 0) {
    cv::copyMakeBorder(scaled, scaled, 0, extra_y, 0, extra_x, cv::BORDER_REPLICATE);
  }
  if (scaled.size() == size) return scaled;
  // Copying into a fresh full-size buffer costs more than the resize itself: only when cutting.
  return scaled(cv::Rect(0, 0, size.width, size.height)).clone();
}

int CountPeaks(const cv::Mat1f& map, double fraction) {
  if (map.empty()) return 0;
  double max_value = 0;
  cv::minMaxLoc(map, nullptr, &max_value);
  if (!(max_value > 0)) return 0;
  cv::Mat1f neighbourhood_max;
  // The default border value of dilation is -inf: pixels outside never win.
  cv::dilate(map, neighbourhood_max, cv::Mat());  // 3x3
  const cv::Mat1b peaks =
      (map >= neighbourhood_max) & (map >= static_cast<float>(fraction * max_value));
  cv::Mat labels;
  return cv::connectedComponents(peaks, labels, 8, CV_32S) - 1;
}

cv::Mat1f FuseSaliency(const cv::Mat1f& on, const cv::Mat1f& off, const SaliencyOptions& options) {
  return Fuse(on, off, CountPeaks(on, options.peak_fraction),
              CountPeaks(off, options.peak_fraction), options);
}

SaliencyMaps ComputeSaliencyMaps(const cv::Mat1b& grey, const SaliencyOptions& options) {
  SaliencyMaps maps;
  if (grey.empty()) return maps;
  CV_Assert(!options.scales.empty() && !options.surround_radii.empty());
  const int top = std::max(options.centre_level,
                           *std::max_element(options.scales.begin(), options.scales.end()));
  const int bottom = std::min(options.centre_level,
                              *std::min_element(options.scales.begin(), options.scales.end()));
  const std::vector<cv::Mat1f> pyramid = Pyramid(grey, top, /*with_level0=*/bottom == 0);
  const cv::Size size = pyramid[options.centre_level].size();
  maps.on = cv::Mat1f(size, 0.0f);
  maps.off = cv::Mat1f(size, 0.0f);
  cv::Mat1d integral;
  cv::Mat1f on, off;
  for (const int s : options.scales) {
    cv::integral(pyramid[s], integral, CV_64F);
    for (const int r : options.surround_radii) {
      CentreSurroundFromIntegral(pyramid[s], integral, r, on, off);
      maps.on += ToCentreLevel(on, s, options.centre_level, size);
      maps.off += ToCentreLevel(off, s, options.centre_level, size);
    }
  }
  const double n = static_cast<double>(options.scales.size() * options.surround_radii.size());
  maps.on *= 1 / n;
  maps.off *= 1 / n;
  maps.on_peaks = CountPeaks(maps.on, options.peak_fraction);
  maps.off_peaks = CountPeaks(maps.off, options.peak_fraction);
  maps.saliency = Fuse(maps.on, maps.off, maps.on_peaks, maps.off_peaks, options);
  return maps;
}

cv::Mat1f ComputeSaliency(const cv::Mat1b& grey, const SaliencyOptions& options) {
  return ComputeSaliencyMaps(grey, options).saliency;
}

cv::Mat1f SaliencyAtFullSize(const cv::Mat1b& grey, const SaliencyOptions& options) {
  const cv::Mat1f saliency = ComputeSaliency(grey, options);
  if (saliency.empty()) return saliency;
  return UpsampleOctaves(saliency, options.centre_level, grey.size());
}

}  // namespace stevi::extraction
