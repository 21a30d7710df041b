#include "core/extraction/saliency.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

namespace stevi::extraction {
namespace {

using ::testing::HasSubstr;
using ::testing::IsEmpty;
using ::testing::UnorderedElementsAre;

// ---- A naive reference: direct sums in double, no integral images and no OpenCV filters. ----

using Map = cv::Mat1d;

// Reflect-101 index (…, 2, 1 | 0, 1, 2, …, n-1 | n-2, …).
int Reflect101(int i, int n) {
  if (n == 1) return 0;
  while (i < 0 || i >= n) i = i < 0 ? -i : 2 * n - 2 - i;
  return i;
}

Map NaiveDown(const Map& level) {
  const double k[3] = {0.25, 0.5, 0.25};
  Map blurred(level.size());
  for (int y = 0; y < level.rows; ++y) {
    for (int x = 0; x < level.cols; ++x) {
      double sum = 0;
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          sum += k[dy + 1] * k[dx + 1] *
                 level(Reflect101(y + dy, level.rows), Reflect101(x + dx, level.cols));
        }
      }
      blurred(y, x) = sum;
    }
  }
  Map out(std::max(1, level.rows / 2), std::max(1, level.cols / 2));
  for (int y = 0; y < out.rows; ++y) {
    for (int x = 0; x < out.cols; ++x) {
      double sum = 0;
      for (int dy = 0; dy <= 1; ++dy) {
        for (int dx = 0; dx <= 1; ++dx) {
          sum +=
              blurred(std::min(2 * y + dy, level.rows - 1), std::min(2 * x + dx, level.cols - 1));
        }
      }
      out(y, x) = sum / 4;
    }
  }
  return out;
}

std::vector<Map> NaivePyramid(const cv::Mat1b& grey, int top) {
  std::vector<Map> pyramid(1);
  grey.convertTo(pyramid[0], CV_64F);
  for (int k = 1; k <= top; ++k) pyramid.push_back(NaiveDown(pyramid.back()));
  return pyramid;
}

// on = max(c - surround, 0), off = max(surround - c, 0); surround = mean of the clipped box
// without the centre, summed pixel by pixel.
void NaiveCentreSurround(const Map& level, int r, Map& on, Map& off) {
  on = Map(level.size(), 0.0);
  off = Map(level.size(), 0.0);
  for (int y = 0; y < level.rows; ++y) {
    for (int x = 0; x < level.cols; ++x) {
      double sum = 0;
      int n = 0;
      for (int v = std::max(0, y - r); v <= std::min(level.rows - 1, y + r); ++v) {
        for (int u = std::max(0, x - r); u <= std::min(level.cols - 1, x + r); ++u) {
          if (u == x && v == y) continue;
          sum += level(v, u);
          ++n;
        }
      }
      const double d = n == 0 ? 0.0 : level(y, x) - sum / n;
      on(y, x) = std::max(d, 0.0);
      off(y, x) = std::max(-d, 0.0);
    }
  }
}

// Bilinear up-sampling by 2^octaves with centre-aligned pixels and clamped coordinates.
Map NaiveUpsample(const Map& map, int octaves, cv::Size size) {
  const double scale = std::pow(2.0, octaves);
  Map out(size);
  const auto coord = [](double u, int n, int& i0, int& i1, double& f) {
    u = std::clamp(u, 0.0, n - 1.0);
    i0 = static_cast<int>(std::floor(u));
    i1 = std::min(i0 + 1, n - 1);
    f = u - i0;
  };
  for (int y = 0; y < size.height; ++y) {
    int y0, y1;
    double fy;
    coord((y + 0.5) / scale - 0.5, map.rows, y0, y1, fy);
    for (int x = 0; x < size.width; ++x) {
      int x0, x1;
      double fx;
      coord((x + 0.5) / scale - 0.5, map.cols, x0, x1, fx);
      out(y, x) = (1 - fy) * ((1 - fx) * map(y0, x0) + fx * map(y0, x1)) +
                  fy * ((1 - fx) * map(y1, x0) + fx * map(y1, x1));
    }
  }
  return out;
}

// Local maxima (>= every in-image 8-neighbour) at or above fraction * max, counted per pixel: the
// random maps below have no plateaus above the threshold.
int NaivePeaks(const Map& map, double fraction) {
  double max_value = 0;
  cv::minMaxLoc(map, nullptr, &max_value);
  if (max_value <= 0) return 0;
  int peaks = 0;
  for (int y = 0; y < map.rows; ++y) {
    for (int x = 0; x < map.cols; ++x) {
      if (map(y, x) < fraction * max_value) continue;
      bool is_max = true;
      for (int v = std::max(0, y - 1); v <= std::min(map.rows - 1, y + 1); ++v) {
        for (int u = std::max(0, x - 1); u <= std::min(map.cols - 1, x + 1); ++u) {
          if (map(v, u) > map(y, x)) is_max = false;
        }
      }
      peaks += is_max;
    }
  }
  return peaks;
}

struct NaiveSaliency {
  Map on, off, saliency;
  int on_peaks = 0, off_peaks = 0;
};

// Brings a map of level s to level c: bilinear up-sampling, or pyramid steps down.
Map NaiveToLevel(const Map& map, int s, int c, cv::Size size) {
  if (s >= c) return NaiveUpsample(map, s - c, size);
  Map out = map;
  for (int k = s; k < c; ++k) out = NaiveDown(out);
  return out;
}

NaiveSaliency NaiveCompute(const cv::Mat1b& grey, const SaliencyOptions& o) {
  const int top = std::max(o.centre_level, *std::max_element(o.scales.begin(), o.scales.end()));
  const std::vector<Map> pyramid = NaivePyramid(grey, top);
  const cv::Size size = pyramid[o.centre_level].size();
  NaiveSaliency n{Map(size, 0.0), Map(size, 0.0), Map(), 0, 0};
  for (const int s : o.scales) {
    for (const int r : o.surround_radii) {
      Map on, off;
      NaiveCentreSurround(pyramid[s], r, on, off);
      n.on += NaiveToLevel(on, s, o.centre_level, size);
      n.off += NaiveToLevel(off, s, o.centre_level, size);
    }
  }
  const double count = static_cast<double>(o.scales.size() * o.surround_radii.size());
  n.on /= count;
  n.off /= count;
  n.on_peaks = NaivePeaks(n.on, o.peak_fraction);
  n.off_peaks = NaivePeaks(n.off, o.peak_fraction);
  n.saliency =
      n.on / std::sqrt(std::max(1, n.on_peaks)) + n.off / std::sqrt(std::max(1, n.off_peaks));
  double max_value = 0;
  cv::minMaxLoc(n.saliency, nullptr, &max_value);
  n.saliency /= std::max(max_value, o.min_contrast);
  return n;
}

// ---- Helpers. ----

cv::Mat1b RandomImage(cv::Size size, uint64_t seed) {
  cv::Mat1b image(size);
  cv::RNG rng(seed);
  rng.fill(image, cv::RNG::UNIFORM, 0, 256);
  return image;
}

// Largest |a - b| over the pixels, with its location in the message.
::testing::AssertionResult MapsNear(const cv::Mat& a, const cv::Mat& b, double tol) {
  if (a.size() != b.size()) {
    return ::testing::AssertionFailure() << "sizes differ: " << a.size() << " vs " << b.size();
  }
  cv::Mat1d da, db;
  a.convertTo(da, CV_64F);
  b.convertTo(db, CV_64F);
  double max_diff = 0;
  cv::Point where;
  cv::minMaxLoc(cv::abs(da - db), nullptr, &max_diff, nullptr, &where);
  if (max_diff <= tol) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << "max |diff| " << max_diff << " > " << tol << " at "
                                       << where << ": " << da(where) << " vs " << db(where);
}

cv::Point MaxLocation(const cv::Mat1f& map) {
  cv::Point where;
  cv::minMaxLoc(map, nullptr, nullptr, nullptr, &where);
  return where;
}

// ---- Agreement with the naive reference at awkward sizes. ----

TEST(BuildGreyPyramid, MatchesNaiveBlurAndDecimation) {
  const cv::Mat1b grey = RandomImage({331, 247}, 1);
  const std::vector<cv::Mat1f> fast = BuildGreyPyramid(grey, 4);
  const std::vector<Map> naive = NaivePyramid(grey, 4);
  ASSERT_EQ(fast.size(), 5u);
  EXPECT_EQ(fast[2].size(), cv::Size(82, 61));
  EXPECT_EQ(fast[4].size(), cv::Size(20, 15));
  // Float rounding only: grey levels up to 255 carry about 2e-5 of it per step.
  for (int k = 0; k <= 4; ++k) EXPECT_TRUE(MapsNear(fast[k], naive[k], 2e-4)) << "level " << k;
}

TEST(CentreSurround, MatchesDirectSummationAtEveryLevelAndRadius) {
  const cv::Mat1b grey = RandomImage({331, 247}, 2);
  const std::vector<cv::Mat1f> pyramid = BuildGreyPyramid(grey, 4);
  for (int k = 0; k <= 4; ++k) {
    Map level;
    pyramid[k].convertTo(level, CV_64F);
    for (const int r : {1, 3, 7, 40}) {  // 40 is wider than levels 3 and 4: every box is clipped
      if (r == 40 && k < 2) continue;    // (and slow to sum directly at levels 0 and 1)
      cv::Mat1f on, off;
      CentreSurround(pyramid[k], r, on, off);
      Map want_on, want_off;
      NaiveCentreSurround(level, r, want_on, want_off);
      EXPECT_TRUE(MapsNear(on, want_on, 1e-4)) << "level " << k << " radius " << r;
      EXPECT_TRUE(MapsNear(off, want_off, 1e-4)) << "level " << k << " radius " << r;
    }
  }
}

TEST(UpsampleOctaves, MatchesNaiveBilinear) {
  cv::Mat1f map(15, 20);
  cv::RNG(3).fill(map, cv::RNG::UNIFORM, 0.0, 100.0);
  Map naive_in;
  map.convertTo(naive_in, CV_64F);
  for (const cv::Size size : {cv::Size(80, 60), cv::Size(83, 61), cv::Size(20, 15)}) {
    for (const int octaves : {0, 1, 2}) {
      if (octaves == 0 && size != map.size()) continue;
      EXPECT_TRUE(MapsNear(UpsampleOctaves(map, octaves, size),
                           NaiveUpsample(naive_in, octaves, size), 1e-4))
          << size << " octaves " << octaves;
    }
  }
}

TEST(ComputeSaliency, MatchesTheNaiveReferenceAtAnAwkwardSize) {
  // A random image smoothed a little, so that the maps have structure, plus a bright patch.
  cv::Mat1b grey = RandomImage({331, 247}, 4);
  cv::GaussianBlur(grey, grey, cv::Size(9, 9), 3);
  grey(cv::Rect(200, 60, 30, 25)).setTo(250);
  const SaliencyOptions options;
  const SaliencyMaps fast = ComputeSaliencyMaps(grey, options);
  const NaiveSaliency naive = NaiveCompute(grey, options);
  ASSERT_EQ(fast.saliency.size(), cv::Size(82, 61));
  EXPECT_TRUE(MapsNear(fast.on, naive.on, 1e-4));
  EXPECT_TRUE(MapsNear(fast.off, naive.off, 1e-4));
  EXPECT_EQ(fast.on_peaks, naive.on_peaks);
  EXPECT_EQ(fast.off_peaks, naive.off_peaks);
  EXPECT_GT(naive.on_peaks + naive.off_peaks, 2);  // the weights are really exercised
  EXPECT_TRUE(MapsNear(fast.saliency, naive.saliency, 1e-4));
  EXPECT_TRUE(MapsNear(ComputeSaliency(grey, options), naive.saliency, 1e-4));
  EXPECT_TRUE(MapsNear(FuseSaliency(fast.on, fast.off, options), naive.saliency, 1e-4));
}

TEST(ComputeSaliency, MatchesTheNaiveReferenceWithOtherOptions) {
  const cv::Mat1b grey = RandomImage({203, 157}, 5);
  SaliencyOptions options;
  options.centre_level = 1;
  options.scales = {0, 1, 3};  // level 0 is brought down to level 1
  options.surround_radii = {2, 5, 9};
  options.uniqueness_weight = true;
  options.peak_fraction = 0.8;
  const SaliencyMaps fast = ComputeSaliencyMaps(grey, options);
  const NaiveSaliency naive = NaiveCompute(grey, options);
  EXPECT_TRUE(MapsNear(fast.on, naive.on, 1e-4));
  EXPECT_TRUE(MapsNear(fast.off, naive.off, 1e-4));
  EXPECT_TRUE(MapsNear(fast.saliency, naive.saliency, 1e-4));
}

// ---- Behaviour. ----

TEST(SaliencyAtFullSize, BrightSquareOnFlatBackgroundIsTheMaximum) {
  cv::Mat1b grey(480, 640, uchar{80});
  const cv::Rect square(400, 120, 40, 40);
  grey(square).setTo(200);
  const cv::Mat1f saliency = SaliencyAtFullSize(grey, SaliencyOptions{});
  ASSERT_EQ(saliency.size(), grey.size());
  const cv::Point peak = MaxLocation(saliency);
  EXPECT_TRUE(square.contains(peak)) << peak;
  // Bilinear up-sampling never lands exactly on a level-2 pixel centre: the peak is just below 1.
  EXPECT_GT(saliency(peak), 0.95f);
  EXPECT_LE(saliency(peak), 1.0f);
  // Far from the square the map is empty.
  EXPECT_EQ(cv::countNonZero(saliency(cv::Rect(0, 340, 300, 140))), 0);
}

TEST(SaliencyAtFullSize, DarkSquareIsSalientThroughOffCentre) {
  cv::Mat1b grey(480, 640, uchar{180});
  const cv::Rect square(100, 300, 40, 40);
  grey(square).setTo(60);
  const SaliencyMaps maps = ComputeSaliencyMaps(grey, SaliencyOptions{});
  double on_max = 0, off_max = 0;
  cv::minMaxLoc(maps.on, nullptr, &on_max);
  cv::minMaxLoc(maps.off, nullptr, &off_max);
  EXPECT_GT(off_max, on_max);  // the off-centre response carries the square
  const cv::Point peak = MaxLocation(SaliencyAtFullSize(grey, SaliencyOptions{}));
  EXPECT_TRUE(square.contains(peak)) << peak;
}

TEST(SaliencyAtFullSize, SmallSquarePeaksAtItsCentre) {
  // Checks the alignment of the pyramid and of the up-sampling: a shift of half a coarse pixel
  // per level would move the peak by several pixels.
  for (const cv::Point centre : {cv::Point(200, 150), cv::Point(421, 303)}) {
    cv::Mat1b grey(480, 640, uchar{100});
    grey(cv::Rect(centre.x - 8, centre.y - 8, 16, 16)).setTo(220);
    const cv::Point peak = MaxLocation(SaliencyAtFullSize(grey, SaliencyOptions{}));
    EXPECT_LE(std::abs(peak.x - centre.x + 0.5), 3.0) << peak << " vs " << centre;
    EXPECT_LE(std::abs(peak.y - centre.y + 0.5), 3.0) << peak << " vs " << centre;
  }
}

TEST(ComputeSaliency, FlatImageIsAllZero) {
  const cv::Mat1f saliency = ComputeSaliency(cv::Mat1b(480, 640, uchar{123}), SaliencyOptions{});
  ASSERT_EQ(saliency.size(), cv::Size(160, 120));
  EXPECT_TRUE(cv::checkRange(saliency));  // no NaN or infinity
  EXPECT_EQ(cv::countNonZero(saliency), 0);
}

TEST(ComputeSaliency, TinyImagesGiveFiniteMaps) {
  for (const cv::Size size : {cv::Size(1, 1), cv::Size(5, 3), cv::Size(17, 2)}) {
    const cv::Mat1b grey = RandomImage(size, 6);
    const cv::Mat1f full = SaliencyAtFullSize(grey, SaliencyOptions{});
    ASSERT_EQ(full.size(), size);
    EXPECT_TRUE(cv::checkRange(full)) << size;
    double lo = 0, hi = 0;
    cv::minMaxLoc(full, &lo, &hi);
    EXPECT_GE(lo, 0.0);
    EXPECT_LE(hi, 1.0);
  }
}

TEST(ComputeSaliency, MinContrastKeepsWeakScenesLow) {
  cv::Mat1b grey(240, 320, uchar{100});
  grey(cv::Rect(100, 100, 20, 20)).setTo(104);  // 4 grey levels of contrast
  SaliencyOptions options;
  double max_value = 0;
  cv::minMaxLoc(ComputeSaliency(grey, options), nullptr, &max_value);
  EXPECT_FLOAT_EQ(max_value, 1.0);
  options.min_contrast = 20;
  cv::minMaxLoc(ComputeSaliency(grey, options), nullptr, &max_value);
  EXPECT_GT(max_value, 0.0);
  EXPECT_LT(max_value, 0.2);
}

TEST(CountPeaks, CountsPlateausOnceAndIgnoresLowMaxima) {
  cv::Mat1f map(20, 20, 0.0f);
  map(5, 5) = 10;
  map(cv::Rect(12, 12, 3, 2)).setTo(8);  // plateau
  map(2, 15) = 3;                        // below half the maximum
  EXPECT_EQ(CountPeaks(map, 0.5), 2);
  EXPECT_EQ(CountPeaks(map, 0.2), 3);
  EXPECT_EQ(CountPeaks(cv::Mat1f(5, 5, 0.0f), 0.5), 0);
}

TEST(SaliencyOptions, ListsEveryProblem) {
  EXPECT_THAT(SaliencyOptions{}.Validate(), IsEmpty());
  SaliencyOptions options;
  options.centre_level = 9;
  options.scales = {2, 2, -1};
  options.surround_radii = {};
  options.peak_fraction = 0;
  options.min_contrast = -1;
  const std::vector<std::string> problems = options.Validate();
  EXPECT_THAT(problems, UnorderedElementsAre("centre_level: must be in [0, 8] (got 9)",
                                             "scales[1]: repeats an earlier value (got 2)",
                                             "scales: must be in [0, 8] (got -1)",
                                             "surround_radii: must not be empty",
                                             "peak_fraction: must be in (0, 1] (got 0)",
                                             "min_contrast: must be >= 0 grey levels (got -1)"));
  options = SaliencyOptions{};
  options.surround_radii = {3, 0, 65};
  EXPECT_THAT(options.Validate(),
              UnorderedElementsAre("surround_radii: must be in [1, 64] pixels (got 0)",
                                   "surround_radii: must be in [1, 64] pixels (got 65)"));
}

}  // namespace
}  // namespace stevi::extraction
