#include "core/stereo/dense_matcher.h"

#include <algorithm>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "core/stereo/disparity.h"
#include "core/stereo/matcher.h"
#include "drivers/synthetic/synthetic_source.h"
#include "tests/core/stereo/synthetic_sky.h"

namespace stevi::stereo {
namespace {

using ::testing::HasSubstr;

// Random texture: cells of 2x2 px with uniform grey levels, seeded.
cv::Mat1b Texture(cv::Size size, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> grey(0, 255);
  cv::Mat1b cells((size.height + 1) / 2, (size.width + 1) / 2);
  for (uchar& v : cells) v = static_cast<uchar>(grey(rng));
  cv::Mat1b out;
  cv::resize(cells, out, cv::Size(cells.cols * 2, cells.rows * 2), 0, 0, cv::INTER_NEAREST);
  return out(cv::Rect(cv::Point(0, 0), size)).clone();
}

// The right image of `left` for a disparity d(x, y) (linear interpolation along the row).
cv::Mat1b RightFor(const cv::Mat1b& left, const cv::Mat1f& disparity) {
  cv::Mat1f map_x(left.size()), map_y(left.size());
  // x_right = x_left - d: sample the left image at x_right + d of the right pixel (the surface is
  // slanted slowly enough that d at the right pixel is the left pixel's).
  for (int y = 0; y < left.rows; ++y) {
    for (int x = 0; x < left.cols; ++x) {
      map_x(y, x) = static_cast<float>(x) + disparity(y, x);
      map_y(y, x) = static_cast<float>(y);
    }
  }
  cv::Mat1b right;
  cv::remap(left, right, map_x, map_y, cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  return right;
}

struct Accuracy {
  double matched = 0, within_half = 0, within_one = 0;
};
// Over the pixels at least `margin` px from every border and right of the search range.
Accuracy Measure(const DisparityMap& map, const cv::Mat1f& truth, int margin) {
  long n = 0, matched = 0, half = 0, one = 0;
  for (int y = margin; y < truth.rows - margin; ++y) {
    for (int x = map.min_disparity + map.num_disparities + margin; x < truth.cols - margin; ++x) {
      ++n;
      const std::optional<float> d = map.At(x, y);
      if (!d) continue;
      ++matched;
      half += std::abs(*d - truth(y, x)) <= 0.5f;
      one += std::abs(*d - truth(y, x)) <= 1.0f;
    }
  }
  return {static_cast<double>(matched) / n, static_cast<double>(half) / std::max(1L, matched),
          static_cast<double>(one) / std::max(1L, matched)};
}

TEST(DenseMatcherOptions, DefaultsAreValid) {
  EXPECT_THAT(DenseMatcherOptions{}.Validate(), ::testing::IsEmpty());
}

TEST(DenseMatcherOptions, ValidateListsEveryProblem) {
  DenseMatcherOptions o;
  o.num_disparities = 40;
  o.min_disparity = -1;
  o.p1 = 0;
  o.p2 = 300;
  o.num_paths = 8;
  o.lr_max_diff = -2;
  const std::vector<std::string> problems = o.Validate();
  const std::string all = ::testing::PrintToString(problems);
  for (const char* field :
       {"num_disparities", "min_disparity", "p1", "p2", "num_paths", "lr_max_diff"}) {
    EXPECT_THAT(all, HasSubstr(field)) << all;
  }
  DenseMatcherOptions penalties;
  penalties.p1 = 40;
  penalties.p2 = 30;
  EXPECT_THAT(penalties.Validate(), ::testing::ElementsAre(HasSubstr("p2: must be greater")));
  penalties.p1 = 100;
  penalties.p2 = 200;
  EXPECT_THAT(penalties.Validate(), ::testing::ElementsAre(HasSubstr("p1 + p2 must be at most")));
}

TEST(DenseMatcherOptions, MatcherOptionsPrefixAndRange) {
  MatcherOptions options;
  options.kind = MatcherKind::kDense;
  options.dense.num_disparities = 17;
  EXPECT_THAT(options.Validate(), ::testing::ElementsAre(HasSubstr("dense.num_disparities")));
  options.dense.num_disparities = 96;
  options.dense.min_disparity = 4;
  EXPECT_EQ(options.num_disparities(), 96);
  EXPECT_EQ(options.min_disparity(), 4);
  EXPECT_EQ(MatcherKindName(MatcherKind::kDense), "dense");
  // The default kind stays block matching.
  EXPECT_EQ(MatcherOptions{}.kind, MatcherKind::kBlockMatching);
}

// A constant disparity on random texture: every path (AVX-512, AVX2, portable) gives the same map,
// and nearly every pixel is exact, confidently.
TEST(DenseMatcher, ConstantDisparityOnTextureEveryPath) {
  const cv::Mat1b left = Texture({301, 203}, 7);
  const cv::Mat1f truth(left.size(), 9.0f);
  const cv::Mat1b right = RightFor(left, truth);
  DenseMatcherOptions options;
  options.num_disparities = 32;
  DenseMatcher best(options), avx2(options), portable(options);
  avx2.set_simd_path(DenseMatcher::SimdPath::kAvx2);
  portable.set_simd_path(DenseMatcher::SimdPath::kPortable);
  const DisparityMap a = best.Compute(left, right);
  const DisparityMap b = avx2.Compute(left, right);
  const DisparityMap c = portable.Compute(left, right);
  EXPECT_EQ(cv::norm(a.fixed, b.fixed, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(a.fixed, c.fixed, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(a.confidence, c.confidence, cv::NORM_INF), 0.0);
  const Accuracy acc = Measure(a, truth, 3);
  EXPECT_GT(acc.matched, 0.99);
  EXPECT_GT(acc.within_half, 0.99);
  cv::Mat1b inner = a.confidence(cv::Rect(40, 3, 250, 190));
  EXPECT_GT(cv::mean(inner)[0], 200.0);
  EXPECT_EQ(a.min_disparity, 0);
  EXPECT_EQ(a.num_disparities, 32);
  EXPECT_EQ(a.block_size, kDenseCensusWindow);
}

// DenseCues::agreement against a naive count over the 5x5 window, on a map with holes, steps and
// every border (the vector code covers eight pixels at a time, the borders one by one).
TEST(DenseMatcher, AgreementCountsTheWindowsNeighboursWithinOnePixel) {
  const cv::Mat1b left = Texture({67, 23}, 3);
  cv::Mat1f truth(left.size());
  for (int y = 0; y < truth.rows; ++y) {
    for (int x = 0; x < truth.cols; ++x) truth(y, x) = x < 30 ? 6.0f : 6.0f + 0.2f * (x % 9);
  }
  DenseMatcherOptions options;
  options.num_disparities = 16;
  options.fill_holes = false;  // keep the left-right failures as holes
  DenseMatcher matcher(options);
  DisparityMap map = matcher.Compute(left, RightFor(left, truth));
  const cv::Mat1s& d = map.fixed;
  const cv::Mat1b& agreement = matcher.last_cues().agreement;
  ASSERT_EQ(agreement.size(), d.size());
  int checked = 0;
  for (int y = 0; y < d.rows; ++y) {
    for (int x = 0; x < d.cols; ++x) {
      int n = 0;
      for (int yy = y - 2; yy <= y + 2; ++yy) {
        for (int xx = x - 2; xx <= x + 2; ++xx) {
          if ((yy == y && xx == x) || yy < 0 || xx < 0 || yy >= d.rows || xx >= d.cols) continue;
          n += d(yy, xx) >= 0 && std::abs(d(yy, xx) - d(y, x)) <= DisparityMap::kScale;
        }
      }
      EXPECT_EQ(agreement(y, x), d(y, x) < 0 ? 0 : n) << "at " << x << "," << y;
      ++checked;
    }
  }
  EXPECT_EQ(checked, 67 * 23);
  EXPECT_GT(cv::countNonZero(d < 0), 0);  // some holes were counted around
}

// A slanted plane (d from 6 to 20 px across the image): sub-pixel refinement follows it.
TEST(DenseMatcher, SlantedPlaneSubPixel) {
  const cv::Mat1b left = Texture({320, 160}, 11);
  cv::Mat1f truth(left.size());
  for (int y = 0; y < truth.rows; ++y) {
    for (int x = 0; x < truth.cols; ++x) truth(y, x) = 6.0f + 14.0f * x / truth.cols;
  }
  const cv::Mat1b right = RightFor(left, truth);
  DenseMatcherOptions options;
  options.num_disparities = 32;
  const DisparityMap map = DenseMatcher(options).Compute(left, right);
  const Accuracy acc = Measure(map, truth, 3);
  std::printf("slanted plane: matched %.3f, within 0.5 px %.3f, within 1 px %.3f\n", acc.matched,
              acc.within_half, acc.within_one);
  EXPECT_GT(acc.matched, 0.99);
  // Census costs lock the parabola towards whole pixels: sub-pixel values are only roughly right.
  EXPECT_GT(acc.within_half, 0.3);
  EXPECT_GT(acc.within_one, 0.9);
}

// A near square in front of a far background: the background strip it hides in the right image
// fails the left-right check (unmatched without filling; filled with the background disparity and
// a low confidence with it).
TEST(DenseMatcher, LeftRightCheckInvalidatesTheOccludedStrip) {
  const cv::Mat1b background = Texture({320, 200}, 3);
  const cv::Mat1b front = Texture({320, 200}, 4);
  constexpr int kFar = 4, kNear = 20, kX0 = 140, kX1 = 220;
  // Right image: background shifted by kFar, square (columns kX0..kX1 of the left) by kNear.
  cv::Mat1b left = background.clone(), right(background.size());
  front(cv::Rect(kX0, 50, kX1 - kX0, 100)).copyTo(left(cv::Rect(kX0, 50, kX1 - kX0, 100)));
  for (int y = 0; y < right.rows; ++y) {
    for (int x = 0; x < right.cols; ++x) {
      const bool in_square = y >= 50 && y < 150 && x + kNear >= kX0 && x + kNear < kX1;
      right(y, x) = in_square ? left(y, x + kNear) : background(y, std::min(x + kFar, 319));
    }
  }
  DenseMatcherOptions options;
  options.num_disparities = 32;
  options.fill_holes = false;
  const DisparityMap unfilled = DenseMatcher(options).Compute(left, right);
  options.fill_holes = true;
  DenseMatcher filling(options);
  const DisparityMap filled = filling.Compute(left, right);
  // The occluded strip: left columns kX0 - (kNear - kFar) .. kX0 - 1, rows of the square.
  long strip = 0, strip_unmatched = 0, strip_background = 0, strip_low = 0;
  for (int y = 60; y < 140; ++y) {
    for (int x = kX0 - (kNear - kFar) + 2; x < kX0 - 2; ++x) {
      ++strip;
      strip_unmatched += !unfilled.At(x, y).has_value();
      const std::optional<float> d = filled.At(x, y);
      strip_background += d && std::abs(*d - kFar) <= 1.0f;
      strip_low += filled.confidence(y, x) < 128;
    }
  }
  std::printf("occluded strip: %ld px, %ld unmatched, filled with background %ld, low conf %ld\n",
              strip, strip_unmatched, strip_background, strip_low);
  EXPECT_GT(strip_unmatched, strip * 8 / 10);
  EXPECT_GT(strip_background, strip * 6 / 10);
  EXPECT_GT(strip_low, strip * 8 / 10);
  // Filled pixels are marked, and the square and background away from the strip are exact.
  EXPECT_GT(cv::countNonZero(filling.last_cues().filled), strip * 8 / 10);
  EXPECT_NEAR(*filled.At(180, 100), kNear, 0.5);
  EXPECT_NEAR(*filled.At(260, 100), kFar, 0.5);
}

// Flat noise (sigma 2) on the left half, texture on the right: the flat half gets no confident
// disparity.
TEST(DenseMatcher, FlatNoiseIsNotConfident) {
  std::mt19937 rng(5);
  std::normal_distribution<float> noise(0.0f, 2.0f);
  const cv::Mat1b texture = Texture({320, 160}, 21);
  cv::Mat1b left(texture.size()), right(texture.size());
  for (int y = 0; y < left.rows; ++y) {
    for (int x = 0; x < left.cols; ++x) {
      const int base_l = x < 160 ? 120 : texture(y, x);
      const int base_r = x < 160 ? 120 : texture(y, std::min(x + 8, 319));
      left(y, x) = cv::saturate_cast<uchar>(base_l + noise(rng));
      right(y, x) = cv::saturate_cast<uchar>(base_r + noise(rng));
    }
  }
  DenseMatcherOptions options;
  options.num_disparities = 32;
  const DisparityMap map = DenseMatcher(options).Compute(left, right);
  const cv::Rect flat(40, 5, 100, 150), textured(200, 5, 110, 150);
  const cv::Mat1b flat_conf = map.confidence(flat);
  const double flat_confident = cv::countNonZero(flat_conf >= 64) / double(flat.area());
  const double textured_mean = cv::mean(map.confidence(textured))[0];
  std::printf("flat noise: %.4f of pixels with confidence >= 64 (mean %.1f); textured mean %.1f\n",
              flat_confident, cv::mean(flat_conf)[0], textured_mean);
  EXPECT_LT(flat_confident, 0.02);
  EXPECT_GT(textured_mean, 200.0);
}

// The synthetic rig's sky (noise sigma 2): unmatched or low confidence, while the obstacles keep
// confident, correct disparities.
TEST(DenseMatcher, SyntheticSkyIsNotConfident) {
  const auto [frame, truth, open_sky, obstacles] = fixtures::DefaultSkyScene();
  ASSERT_GT(cv::countNonZero(open_sky), 50000);
  DenseMatcher matcher(DenseMatcherOptions{});
  const DisparityMap map = matcher.Compute(frame.left, frame.right);
  long sky = 0, sky_confident = 0, obstacle = 0, obstacle_confident_correct = 0;
  for (int y = 0; y < map.fixed.rows; ++y) {
    for (int x = 0; x < map.fixed.cols; ++x) {
      const std::optional<float> d = map.At(x, y);
      if (open_sky(y, x)) {
        ++sky;
        sky_confident += d && map.confidence(y, x) >= 64;
      } else if (obstacles(y, x)) {
        ++obstacle;
        obstacle_confident_correct +=
            d && map.confidence(y, x) >= 128 && std::abs(*d - truth.disparity_px(y, x)) <= 1.0f;
      }
    }
  }
  std::printf("synthetic sky: %.4f confident (>= 64); obstacles confident and within 1 px: %.3f\n",
              double(sky_confident) / sky, double(obstacle_confident_correct) / obstacle);
  EXPECT_LT(double(sky_confident) / sky, 0.01);
  EXPECT_GT(double(obstacle_confident_correct) / obstacle, 0.7);
}

TEST(DenseMatcher, OddAndTinySizes) {
  DenseMatcherOptions options;
  options.num_disparities = 16;
  DenseMatcher matcher(options);
  for (const cv::Size size : {cv::Size(4, 30), cv::Size(30, 4), cv::Size(1, 1), cv::Size(5, 5),
                              cv::Size(7, 13), cv::Size(97, 33)}) {
    const cv::Mat1b left = Texture(size, 1);
    const DisparityMap map = matcher.Compute(left, left);
    ASSERT_EQ(map.fixed.size(), size);
    ASSERT_EQ(map.confidence.size(), size);
    if (size.width < kDenseCensusWindow || size.height < kDenseCensusWindow) {
      EXPECT_EQ(cv::countNonZero(map.fixed != DisparityMap::kInvalid), 0);
      EXPECT_EQ(cv::countNonZero(map.confidence), 0);
    }
  }
  // Identical images at an odd size: disparity 0 nearly everywhere.
  const cv::Mat1b odd = Texture({97, 33}, 2);
  const DisparityMap map = matcher.Compute(odd, odd);
  EXPECT_GT(cv::countNonZero(map.fixed == 0), 97 * 33 * 9 / 10);
  // Unmatched pixels have confidence 0.
  EXPECT_EQ(cv::countNonZero(map.confidence & (map.fixed < 0)), 0);
}

TEST(DenseMatcher, DeterministicAndThroughMakeMatcher) {
  const cv::Mat1b left = Texture({200, 120}, 8);
  const cv::Mat1f truth(left.size(), 5.5f);
  const cv::Mat1b right = RightFor(left, truth);
  MatcherOptions options;
  options.kind = MatcherKind::kDense;
  options.dense.num_disparities = 16;
  options.dense.min_disparity = 2;
  const std::unique_ptr<DisparityMatcher> matcher = MakeMatcher(options);
  const DisparityMap a = matcher->Compute(left, right);
  const DisparityMap b = matcher->Compute(left, right);
  EXPECT_EQ(cv::norm(a.fixed, b.fixed, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(a.confidence, b.confidence, cv::NORM_INF), 0.0);
  EXPECT_EQ(a.min_disparity, 2);
  EXPECT_EQ(a.num_disparities, 16);
  const Accuracy acc = Measure(a, truth, 3);
  EXPECT_GT(acc.within_one, 0.98);
}

}  // namespace
}  // namespace stevi::stereo
