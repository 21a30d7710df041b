#include "core/stereo/matcher.h"

#include <algorithm>
#include <climits>
#include <cstdio>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "core/stereo/disparity.h"
#include "drivers/synthetic/synthetic_source.h"
#include "tests/core/stereo/synthetic_sky.h"

namespace stevi::stereo {
namespace {

using ::testing::AllOf;
using ::testing::Contains;
using ::testing::Each;
using ::testing::HasSubstr;
using ::testing::IsEmpty;
using ::testing::SizeIs;
using ::testing::StartsWith;

// A rectified pair of a seeded, slightly blurred random texture with a constant integer disparity:
// left(x) = texture(x), right(x') = texture(x' + d), so left(x) = right(x - d). The leftmost d
// columns of the left image are not seen by the right camera.
struct Pair {
  cv::Mat1b left, right;
};

Pair ConstantDisparityPair(cv::Size size, int disparity, uint64_t seed) {
  cv::RNG rng(seed);
  cv::Mat1b texture(size.height, size.width + disparity);
  rng.fill(texture, cv::RNG::UNIFORM, 0, 256);
  cv::GaussianBlur(texture, texture, cv::Size(3, 3), 0.7);
  Pair pair;
  pair.left = texture(cv::Rect(0, 0, size.width, size.height)).clone();
  pair.right = texture(cv::Rect(disparity, 0, size.width, size.height)).clone();
  return pair;
}

MatcherOptions BlockMatching() {
  MatcherOptions options;
  options.kind = MatcherKind::kBlockMatching;
  options.block_matching.block_size = 9;
  return options;
}

MatcherOptions SemiGlobal() {
  MatcherOptions options;
  options.kind = MatcherKind::kSemiGlobal;
  return options;
}

// Fraction of pixels of `region` that are matched, and of those, the fraction within `tolerance`
// of `expected` (pixels).
struct RegionStats {
  double matched = 0;
  double correct = 0;
};

RegionStats Stats(const DisparityMap& map, const cv::Rect& region, double expected,
                  double tolerance) {
  int total = 0, matched = 0, correct = 0;
  for (int y = region.y; y < region.y + region.height; ++y) {
    for (int x = region.x; x < region.x + region.width; ++x) {
      ++total;
      const std::optional<float> d = map.At(x, y);
      if (!d) continue;
      ++matched;
      if (std::abs(*d - expected) <= tolerance) ++correct;
    }
  }
  return {total > 0 ? static_cast<double>(matched) / total : 0.0,
          matched > 0 ? static_cast<double>(correct) / matched : 0.0};
}

TEST(BlockMatchingOptionsValidate, DefaultsAreValid) {
  EXPECT_THAT(BlockMatchingOptions().Validate(), IsEmpty());
}

TEST(BlockMatchingOptionsValidate, ListsEveryProblem) {
  BlockMatchingOptions o;
  o.prefilter_size = 4;
  o.prefilter_cap = 0;
  o.block_size = 8;
  o.num_disparities = 50;
  o.min_disparity = -2;
  o.texture_threshold = -1;
  o.uniqueness_ratio = 101;
  o.speckle_window_size = -5;
  o.speckle_range = -1;
  const std::vector<std::string> problems = o.Validate();
  EXPECT_THAT(problems, Contains("prefilter_size: must be in [5, 255] pixels and odd (got 4)"));
  EXPECT_THAT(problems, Contains("prefilter_cap: must be in [1, 63] (got 0)"));
  EXPECT_THAT(problems, Contains("block_size: must be in [5, 255] pixels and odd (got 8)"));
  EXPECT_THAT(problems,
              Contains("num_disparities: must be <= 512 pixels and a positive multiple of 16 "
                       "(got 50)"));
  EXPECT_THAT(problems, Contains("min_disparity: must be in [0, 512] pixels (got -2)"));
  EXPECT_THAT(problems, Contains("texture_threshold: must be >= 0 (got -1)"));
  EXPECT_THAT(problems, Contains("uniqueness_ratio: must be in [0, 100] percent (got 101)"));
  EXPECT_THAT(problems, Contains("speckle_window_size: must be >= 0 pixels (got -5)"));
  EXPECT_THAT(problems, Contains(HasSubstr("speckle_range: must be in [0, ")));
  EXPECT_THAT(problems, SizeIs(9));
}

TEST(BlockMatchingOptionsValidate, BlockSizeRangeAndDisparityCap) {
  BlockMatchingOptions o;
  o.block_size = 3;
  o.num_disparities = 1024;
  EXPECT_THAT(
      o.Validate(),
      testing::ElementsAre(
          "block_size: must be in [5, 255] pixels and odd (got 3)",
          "num_disparities: must be <= 512 pixels and a positive multiple of 16 (got 1024)"));
  o.block_size = 5;
  o.num_disparities = 0;
  EXPECT_THAT(o.Validate(),
              testing::ElementsAre(
                  "num_disparities: must be <= 512 pixels and a positive multiple of 16 (got 0)"));
}

TEST(SemiGlobalOptionsValidate, DefaultsAreValid) {
  EXPECT_THAT(SemiGlobalOptions().Validate(), IsEmpty());
}

TEST(SemiGlobalOptionsValidate, ListsEveryProblem) {
  SemiGlobalOptions o;
  o.block_size = 12;
  o.num_disparities = -16;
  o.p1 = 100;
  o.p2 = 50;
  o.disp12_max_diff = -2;
  o.prefilter_cap = 64;
  o.uniqueness_ratio = -1;
  o.speckle_window_size = -1;
  o.speckle_range = -3;
  o.texture_threshold = -4;
  const std::vector<std::string> problems = o.Validate();
  EXPECT_THAT(problems, Contains("block_size: must be in [1, 11] pixels and odd (got 12)"));
  EXPECT_THAT(problems, Contains("num_disparities: must be <= 512 pixels and a positive multiple "
                                 "of 16 (got -16)"));
  EXPECT_THAT(problems, Contains("p2: must be greater than p1 (got p1=100, p2=50)"));
  EXPECT_THAT(problems, Contains("disp12_max_diff: must be >= -1 pixels (got -2)"));
  EXPECT_THAT(problems, Contains("prefilter_cap: must be in [1, 63] (got 64)"));
  EXPECT_THAT(problems, Contains("uniqueness_ratio: must be in [0, 100] percent (got -1)"));
  EXPECT_THAT(problems, Contains("speckle_window_size: must be >= 0 pixels (got -1)"));
  EXPECT_THAT(problems, Contains(HasSubstr("speckle_range: must be in [0, ")));
  EXPECT_THAT(problems, Contains("texture_threshold: must be >= 0 (got -4)"));
  EXPECT_THAT(problems, SizeIs(9));
}

TEST(SemiGlobalOptionsValidate, NamesTextureThresholdWhenNegative) {
  SemiGlobalOptions o;
  o.texture_threshold = -1;
  EXPECT_THAT(o.Validate(), testing::ElementsAre("texture_threshold: must be >= 0 (got -1)"));
  o.texture_threshold = 0;  // disables the gate
  EXPECT_THAT(o.Validate(), IsEmpty());
  MatcherOptions options = SemiGlobal();
  options.semi_global.texture_threshold = -7;
  EXPECT_THAT(options.Validate(),
              testing::ElementsAre("semi_global.texture_threshold: must be >= 0 (got -7)"));
}

TEST(SemiGlobalOptionsValidate, PenaltiesAgainstAutomaticValues) {
  SemiGlobalOptions o;  // block 5: automatic p1 = 200, p2 = 800
  o.p1 = 900;
  EXPECT_THAT(o.Validate(),
              testing::ElementsAre(HasSubstr("p1: must be less than the automatic p2")));
  o.p1 = 0;
  o.p2 = 150;
  EXPECT_THAT(o.Validate(),
              testing::ElementsAre(HasSubstr("p2: must be greater than the automatic p1")));
  o.p2 = 300;
  EXPECT_THAT(o.Validate(), IsEmpty());
  o.p1 = -1;
  o.p2 = 0;
  EXPECT_THAT(o.Validate(), testing::ElementsAre("p1: must be >= 0 (got -1)"));
}

TEST(MatcherOptionsValidate, PrefixesTheSelectedKindOnly) {
  MatcherOptions options;
  options.block_matching.block_size = 8;
  options.semi_global.block_size = 4;
  options.kind = MatcherKind::kBlockMatching;
  EXPECT_THAT(options.Validate(),
              testing::ElementsAre(
                  "block_matching.block_size: must be in [5, 255] pixels and odd (got 8)"));
  options.kind = MatcherKind::kSemiGlobal;
  EXPECT_THAT(
      options.Validate(),
      testing::ElementsAre("semi_global.block_size: must be in [1, 11] pixels and odd (got 4)"));
  EXPECT_EQ(MatcherKindName(MatcherKind::kSemiGlobal), "semi_global");
  EXPECT_EQ(MatcherKindName(MatcherKind::kBlockMatching), "block_matching");
}

TEST(MatcherOptions, ReportsTheSelectedSearchRange) {
  MatcherOptions options;
  options.block_matching.num_disparities = 32;
  options.block_matching.min_disparity = 2;
  options.semi_global.num_disparities = 96;
  options.semi_global.min_disparity = 4;
  options.kind = MatcherKind::kBlockMatching;
  EXPECT_EQ(options.num_disparities(), 32);
  EXPECT_EQ(options.min_disparity(), 2);
  options.kind = MatcherKind::kSemiGlobal;
  EXPECT_EQ(options.num_disparities(), 96);
  EXPECT_EQ(options.min_disparity(), 4);
}

class ConstantDisparity : public ::testing::TestWithParam<MatcherKind> {
 protected:
  MatcherOptions Options(bool pad_left) const {
    MatcherOptions options =
        GetParam() == MatcherKind::kBlockMatching ? BlockMatching() : SemiGlobal();
    options.block_matching.pad_left = pad_left;
    options.semi_global.pad_left = pad_left;
    return options;
  }
};

TEST_P(ConstantDisparity, RecoversTheDisparity) {
  constexpr int kDisparity = 20;
  const Pair pair = ConstantDisparityPair(cv::Size(320, 240), kDisparity, 7);
  std::unique_ptr<DisparityMatcher> matcher = MakeMatcher(Options(true));
  const DisparityMap map = matcher->Compute(pair.left, pair.right);
  ASSERT_EQ(map.fixed.size(), pair.left.size());
  ASSERT_EQ(map.fixed.type(), CV_16SC1);
  EXPECT_EQ(map.num_disparities, 64);
  EXPECT_EQ(map.min_disparity, 0);

  cv::Mat1i labels(map.fixed.size(), 1);
  int valid = 0;
  const std::optional<double> median =
      MedianDisparityInMask(map, labels, 1, cv::Rect(0, 0, 320, 240), 1.0, &valid);
  ASSERT_TRUE(median.has_value());
  EXPECT_NEAR(*median, kDisparity, 0.1);
  // The seen part of the image (x >= d) is matched and right.
  const RegionStats seen =
      Stats(map, cv::Rect(kDisparity + 8, 8, 320 - kDisparity - 16, 224), kDisparity, 0.5);
  EXPECT_GE(seen.matched, 0.95);
  EXPECT_GE(seen.correct, 0.98);
  // Unmatched pixels are exactly kInvalid.
  double lowest = 0;
  cv::minMaxLoc(map.fixed, &lowest, nullptr);
  EXPECT_GE(lowest, DisparityMap::kInvalid);
}

TEST_P(ConstantDisparity, LeftPaddingMatchesTheLeftmostColumns) {
  constexpr int kDisparity = 20;
  const Pair pair = ConstantDisparityPair(cv::Size(320, 240), kDisparity, 11);
  // Columns d + margin .. num_disparities have a true match in the right image, but OpenCV only
  // searches x >= num_disparities unless the images are padded. (x < d are not seen by the right
  // camera at all and are left out.)
  const cv::Rect leftmost(kDisparity + 5, 8, 64 - kDisparity - 5, 224);
  const DisparityMap padded = MakeMatcher(Options(true))->Compute(pair.left, pair.right);
  const DisparityMap unpadded = MakeMatcher(Options(false))->Compute(pair.left, pair.right);
  const RegionStats with_pad = Stats(padded, leftmost, kDisparity, 0.5);
  const RegionStats without_pad = Stats(unpadded, leftmost, kDisparity, 0.5);
  EXPECT_GE(with_pad.matched, 0.9);
  EXPECT_GE(with_pad.correct, 0.95);
  EXPECT_LE(without_pad.matched, 0.05);
  // Away from the left border both agree.
  const RegionStats middle = Stats(unpadded, cv::Rect(80, 8, 220, 224), kDisparity, 0.5);
  EXPECT_GE(middle.matched, 0.95);
}

TEST_P(ConstantDisparity, MinimumDisparityIsRespected) {
  const Pair pair = ConstantDisparityPair(cv::Size(200, 120), 21, 5);
  MatcherOptions options = Options(true);
  options.block_matching.min_disparity = 16;
  options.block_matching.num_disparities = 32;
  options.semi_global.min_disparity = 16;
  options.semi_global.num_disparities = 32;
  const DisparityMap map = MakeMatcher(options)->Compute(pair.left, pair.right);
  EXPECT_EQ(map.min_disparity, 16);
  EXPECT_EQ(map.num_disparities, 32);
  int below_range = 0;
  for (int y = 0; y < map.fixed.rows; ++y) {
    for (int x = 0; x < map.fixed.cols; ++x) {
      const int16_t v = map.fixed(y, x);
      if (v != DisparityMap::kInvalid && v < 16 * DisparityMap::kScale) ++below_range;
    }
  }
  EXPECT_EQ(below_range, 0);
  EXPECT_GE(Stats(map, cv::Rect(40, 8, 150, 104), 21, 0.5).correct, 0.95);
}

TEST_P(ConstantDisparity, RepeatedAndResizedCallsAreConsistent) {
  std::unique_ptr<DisparityMatcher> matcher = MakeMatcher(Options(true));
  const Pair big = ConstantDisparityPair(cv::Size(160, 96), 12, 3);
  const Pair small = ConstantDisparityPair(cv::Size(97, 61), 9, 4);
  const DisparityMap first = matcher->Compute(big.left, big.right);
  const DisparityMap other = matcher->Compute(small.left, small.right);
  const DisparityMap again = matcher->Compute(big.left, big.right);
  EXPECT_EQ(other.fixed.size(), small.left.size());
  EXPECT_EQ(cv::norm(first.fixed, again.fixed, cv::NORM_INF), 0.0);
  EXPECT_NE(first.fixed.data, again.fixed.data);  // each map owns its pixels
  EXPECT_EQ(cv::norm(first.fixed, MakeMatcher(Options(true))->Compute(big.left, big.right).fixed,
                     cv::NORM_INF),
            0.0);
}

TEST_P(ConstantDisparity, ImageSmallerThanTheBlockIsAllUnmatched) {
  const cv::Mat1b tiny(4, 40, uchar{9});
  const DisparityMap map = MakeMatcher(Options(false))->Compute(tiny, tiny);
  ASSERT_EQ(map.fixed.size(), tiny.size());
  EXPECT_EQ(cv::countNonZero(map.fixed != DisparityMap::kInvalid), 0);
  EXPECT_TRUE(MakeMatcher(Options(true))->Compute(cv::Mat1b(), cv::Mat1b()).empty());
}

INSTANTIATE_TEST_SUITE_P(BothKinds, ConstantDisparity,
                         ::testing::Values(MatcherKind::kBlockMatching, MatcherKind::kSemiGlobal),
                         [](const ::testing::TestParamInfo<MatcherKind>& param_info) {
                           return std::string(param_info.param == MatcherKind::kBlockMatching
                                                  ? "BlockMatching"
                                                  : "SemiGlobal");
                         });

// Block matching is local, so away from the left border the padded result must equal the
// unpadded one pixel for pixel: this pins the crop of the padding to the right column.
TEST(MakeMatcher, BlockMatchingPaddingIsCroppedExactly) {
  const Pair pair = ConstantDisparityPair(cv::Size(211, 90), 17, 8);
  cv::Mat1b left = pair.left.clone();
  // Make the disparity vary along x so that a column shift would show.
  for (int y = 0; y < left.rows; ++y) {
    for (int x = 120; x < left.cols; ++x) left(y, x) = pair.right(y, std::max(0, x - 9));
  }
  MatcherOptions options = BlockMatching();
  options.block_matching.pad_left = true;
  const DisparityMap padded = MakeMatcher(options)->Compute(left, pair.right);
  options.block_matching.pad_left = false;
  const DisparityMap unpadded = MakeMatcher(options)->Compute(left, pair.right);
  const cv::Rect inner(64 + 9, 0, 211 - 64 - 9, 90);
  EXPECT_EQ(cv::norm(padded.fixed(inner), unpadded.fixed(inner), cv::NORM_INF), 0.0);
  EXPECT_GE(Stats(padded, cv::Rect(130, 8, 70, 74), 9, 0.5).correct, 0.95);
}

TEST(MakeMatcher, EverySemiGlobalModeRecoversTheDisparity) {
  const Pair pair = ConstantDisparityPair(cv::Size(160, 100), 13, 21);
  for (SemiGlobalOptions::Mode mode :
       {SemiGlobalOptions::Mode::kSgbm5Path, SemiGlobalOptions::Mode::kFull8Path,
        SemiGlobalOptions::Mode::kThreeWay, SemiGlobalOptions::Mode::kHH4}) {
    MatcherOptions options = SemiGlobal();
    options.semi_global.mode = mode;
    options.semi_global.num_disparities = 32;
    const DisparityMap map = MakeMatcher(options)->Compute(pair.left, pair.right);
    const RegionStats stats = Stats(map, cv::Rect(20, 5, 130, 90), 13, 0.5);
    EXPECT_GE(stats.matched, 0.95) << static_cast<int>(mode);
    EXPECT_GE(stats.correct, 0.98) << static_cast<int>(mode);
  }
}

// A fronto-parallel plane at a constant disparity whose left half is flat grey and whose right
// half carries a texture like the synthetic obstacles' (contrast +-0.35 of 255, random cells of
// kCell pixels, bilinear), seen by two cameras with independent Gaussian pixel noise of sigma 2
// grey levels (seeded), as in the synthetic rig.
struct HalfFlatPair {
  cv::Mat1b left, right;
  int disparity = 0;
  int flat_end = 0;  // columns [0, flat_end) of the left image see the flat half
};

HalfFlatPair HalfFlatNoisyPair(cv::Size size, int disparity, uint64_t seed) {
  constexpr int kCell = 4;
  cv::RNG rng(seed);
  const int scene_width = size.width + disparity;
  cv::Mat1f cells(size.height / kCell + 2, scene_width / kCell + 2);
  rng.fill(cells, cv::RNG::UNIFORM, 128.0 - 89.0, 128.0 + 89.0);
  cv::Mat1f scene;
  cv::resize(cells, scene, cv::Size(cells.cols * kCell, cells.rows * kCell), 0, 0,
             cv::INTER_LINEAR);
  scene = scene(cv::Rect(0, 0, scene_width, size.height)).clone();
  HalfFlatPair pair;
  pair.disparity = disparity;
  pair.flat_end = size.width / 2;
  scene(cv::Rect(0, 0, pair.flat_end, size.height)).setTo(140.0f);
  // left(x) = scene(x), right(x) = scene(x + d): left(x) = right(x - d).
  auto view = [&](int x0) {
    cv::Mat1f noise(size);
    rng.fill(noise, cv::RNG::NORMAL, 0.0, 2.0);
    cv::Mat1b out;
    cv::Mat1f(scene(cv::Rect(x0, 0, size.width, size.height)) + noise).convertTo(out, CV_8U);
    return out;
  };
  pair.left = view(0);
  pair.right = view(disparity);
  return pair;
}

// Matched fraction and median absolute error (pixels) against `expected` over `region`.
struct RegionError {
  double matched = 0;
  double median_error = 1e9;
};

RegionError MedianError(const DisparityMap& map, const cv::Rect& region, double expected) {
  std::vector<float> errors;
  for (int y = region.y; y < region.y + region.height; ++y) {
    for (int x = region.x; x < region.x + region.width; ++x) {
      if (const std::optional<float> d = map.At(x, y)) {
        errors.push_back(std::abs(*d - static_cast<float>(expected)));
      }
    }
  }
  RegionError out;
  out.matched = static_cast<double>(errors.size()) / region.area();
  if (!errors.empty()) {
    std::nth_element(errors.begin(), errors.begin() + errors.size() / 2, errors.end());
    out.median_error = errors[errors.size() / 2];
  }
  return out;
}

// cv::StereoSGBM matches pixel noise on a flat surface to random disparities; the texture gate
// removes those and keeps the textured surface.
TEST(MakeMatcher, SemiGlobalTextureGateRemovesMatchesOnFlatNoise) {
  const HalfFlatPair pair = HalfFlatNoisyPair(cv::Size(320, 240), 12, 42);
  // Away from the image border and from the flat/textured boundary (the 5x5 texture window and
  // SGBM's own smoothing reach a few pixels across it).
  const cv::Rect flat(8, 8, pair.flat_end - 24, 224);
  const cv::Rect textured(pair.flat_end + 16, 8, 320 - pair.flat_end - 24, 224);

  MatcherOptions options = SemiGlobal();
  ASSERT_GT(options.semi_global.texture_threshold, 0) << "the gate is on by default";
  const DisparityMap gated = MakeMatcher(options)->Compute(pair.left, pair.right);
  options.semi_global.texture_threshold = 0;
  const DisparityMap ungated = MakeMatcher(options)->Compute(pair.left, pair.right);

  const RegionError flat_gated = MedianError(gated, flat, pair.disparity);
  const RegionError flat_ungated = MedianError(ungated, flat, pair.disparity);
  const RegionError textured_gated = MedianError(gated, textured, pair.disparity);
  const RegionError textured_ungated = MedianError(ungated, textured, pair.disparity);
  std::printf(
      "flat half matched: %.2f %% gated, %.2f %% ungated; textured half matched %.2f %% "
      "(median error %.3f px) gated, %.2f %% ungated\n",
      100 * flat_gated.matched, 100 * flat_ungated.matched, 100 * textured_gated.matched,
      textured_gated.median_error, 100 * textured_ungated.matched);
  EXPECT_LT(flat_gated.matched, 0.02);
  EXPECT_GT(textured_gated.matched, 0.90);
  EXPECT_LT(textured_gated.median_error, 0.25);
  // Without the gate SGBM matches a good part of the flat half, to noise (28-41 % at median
  // errors of 41-48 px over seeds 1..29): the gate is what removes it.
  EXPECT_GT(flat_ungated.matched, 0.2);
  EXPECT_GT(flat_ungated.median_error, 5.0);
  // The gate only removes matches: every gated disparity is the ungated one.
  const cv::Mat1b kept = gated.fixed != DisparityMap::kInvalid;
  EXPECT_EQ(cv::norm(gated.fixed, ungated.fixed, cv::NORM_INF, kept), 0.0);
  EXPECT_GE(textured_ungated.matched, textured_gated.matched);
}

// The synthetic rig's default scene (flat sky gradient with pixel noise of sigma 2, textured
// obstacles): without the gate SGBM matches a quarter of the open sky to noise, which the
// detector turns into ~100 spurious blobs per frame; with the default gate none is left, and the
// obstacles keep their matches.
TEST(MakeMatcher, SemiGlobalTextureGateClearsTheSyntheticSky) {
  // Open sky: sky pixels more than 8 px from anything else (next to an obstacle's silhouette,
  // SGBM and any window-based gate give the sky the obstacle's disparity).
  const auto [frame, truth, open_sky, obstacles] = fixtures::DefaultSkyScene();
  ASSERT_GT(cv::countNonZero(open_sky), 50000);
  ASSERT_GT(cv::countNonZero(obstacles), 20000);

  struct SceneStats {
    double open_sky_matched = 0, obstacle_matched = 0, obstacle_correct = 0;
  };
  auto measure = [&](int texture_threshold) {
    MatcherOptions options = SemiGlobal();
    options.semi_global.texture_threshold = texture_threshold;
    const DisparityMap map = MakeMatcher(options)->Compute(frame.left, frame.right);
    long sky = 0, sky_matched = 0, obstacle = 0, obstacle_matched = 0, obstacle_correct = 0;
    for (int y = 0; y < map.fixed.rows; ++y) {
      for (int x = 0; x < map.fixed.cols; ++x) {
        const std::optional<float> d = map.At(x, y);
        if (open_sky(y, x)) {
          ++sky;
          sky_matched += d.has_value();
        } else if (obstacles(y, x)) {
          ++obstacle;
          if (!d) continue;
          ++obstacle_matched;
          if (std::abs(*d - truth.disparity_px(y, x)) <= 1.0f) ++obstacle_correct;
        }
      }
    }
    return SceneStats{static_cast<double>(sky_matched) / sky,
                      static_cast<double>(obstacle_matched) / obstacle,
                      static_cast<double>(obstacle_correct) / std::max(1L, obstacle_matched)};
  };
  const SceneStats gated = measure(SemiGlobalOptions().texture_threshold);
  const SceneStats ungated = measure(0);
  std::printf(
      "open sky matched: %.3f %% gated, %.2f %% ungated; obstacles matched %.2f %% / "
      "%.2f %%, within 1 px %.2f %% / %.2f %%\n",
      100 * gated.open_sky_matched, 100 * ungated.open_sky_matched, 100 * gated.obstacle_matched,
      100 * ungated.obstacle_matched, 100 * gated.obstacle_correct, 100 * ungated.obstacle_correct);
  EXPECT_LT(gated.open_sky_matched, 0.001);
  EXPECT_GT(ungated.open_sky_matched, 0.1);
  EXPECT_GT(gated.obstacle_matched, 0.95);
  EXPECT_GT(gated.obstacle_correct, 0.98);
  EXPECT_GE(gated.obstacle_correct, ungated.obstacle_correct - 0.005);
}

// Block matching has its own texture threshold: SemiGlobalOptions::texture_threshold does not
// touch it.
TEST(MakeMatcher, SemiGlobalTextureThresholdDoesNotAffectBlockMatching) {
  const HalfFlatPair pair = HalfFlatNoisyPair(cv::Size(200, 120), 9, 43);
  MatcherOptions options = BlockMatching();
  options.semi_global.texture_threshold = 0;
  const DisparityMap a = MakeMatcher(options)->Compute(pair.left, pair.right);
  options.semi_global.texture_threshold = 200;
  const DisparityMap b = MakeMatcher(options)->Compute(pair.left, pair.right);
  EXPECT_EQ(cv::norm(a.fixed, b.fixed, cv::NORM_INF), 0.0);
  EXPECT_GT(cv::countNonZero(a.fixed != DisparityMap::kInvalid), 200 * 120 / 4);
}

// cv::StereoBM's x-Sobel pre-filter: the horizontal Sobel response, clamped to +-cap and offset
// by cap. Rows reflect at the border (BORDER_REFLECT_101) and the first and last columns are cap.
cv::Mat1b XSobelPrefilter(const cv::Mat1b& image, int cap) {
  cv::Mat1b out(image.size());
  for (int y = 0; y < image.rows; ++y) {
    const int y0 = cv::borderInterpolate(y - 1, image.rows, cv::BORDER_REFLECT_101);
    const int y2 = cv::borderInterpolate(y + 1, image.rows, cv::BORDER_REFLECT_101);
    for (int x = 0; x < image.cols; ++x) {
      if (x == 0 || x == image.cols - 1) {
        out(y, x) = static_cast<uchar>(cap);
        continue;
      }
      const int d = (image(y0, x + 1) - image(y0, x - 1)) +
                    2 * (image(y, x + 1) - image(y, x - 1)) + (image(y2, x + 1) - image(y2, x - 1));
      out(y, x) = static_cast<uchar>(std::clamp(d, -cap, cap) + cap);
    }
  }
  return out;
}

// Naive winner-take-all SAD over a block, integer disparities in [0, num_disparities), on the
// pixels where every candidate block lies inside both images; -1 elsewhere.
cv::Mat1i NaiveSad(const cv::Mat1b& left, const cv::Mat1b& right, int block, int num_disparities) {
  const int r = block / 2;
  cv::Mat1i out(left.size(), -1);
  for (int y = r; y < left.rows - r; ++y) {
    for (int x = r + num_disparities - 1; x < left.cols - r; ++x) {
      int best = INT_MAX, best_d = -1;
      for (int d = 0; d < num_disparities; ++d) {
        int sad = 0;
        for (int dy = -r; dy <= r; ++dy) {
          for (int dx = -r; dx <= r; ++dx)
            sad += std::abs(left(y + dy, x + dx) - right(y + dy, x + dx - d));
        }
        if (sad < best) {
          best = sad;
          best_d = d;
        }
      }
      out(y, x) = best_d;
    }
  }
  return out;
}

// StereoBM against a naive SAD at an awkward size. StereoBM always pre-filters, so the naive SAD
// runs on the same x-Sobel pre-filtered images; texture, uniqueness and speckle filters are off.
// StereoBM's sub-pixel refinement is rounded back to an integer; ties and half-pixel refinements
// can move a few pixels by one, hence 95 % rather than 100 %.
TEST(MakeMatcher, BlockMatchingAgreesWithNaiveSad) {
  constexpr int kWidth = 67, kHeight = 41, kBlock = 5, kNum = 16, kCap = 31;
  cv::RNG rng(2024);
  cv::Mat1b left(kHeight, kWidth), right(kHeight, kWidth);
  rng.fill(left, cv::RNG::UNIFORM, 0, 256);
  cv::GaussianBlur(left, left, cv::Size(3, 3), 0.8);
  // Piecewise disparity (4 px in the top half, 11 px below) plus noise, so the search has work.
  for (int y = 0; y < kHeight; ++y) {
    const int d = y < kHeight / 2 ? 4 : 11;
    for (int x = 0; x < kWidth; ++x) {
      const int source = std::min(kWidth - 1, x + d);
      right(y, x) = cv::saturate_cast<uchar>(left(y, source) + rng.uniform(-6, 7));
    }
  }
  MatcherOptions options = BlockMatching();
  BlockMatchingOptions& bm = options.block_matching;
  bm.block_size = kBlock;
  bm.num_disparities = kNum;
  bm.prefilter_cap = kCap;
  bm.texture_threshold = 0;
  bm.uniqueness_ratio = 0;
  bm.speckle_window_size = 0;
  bm.pad_left = false;
  ASSERT_THAT(options.Validate(), IsEmpty());
  const DisparityMap map = MakeMatcher(options)->Compute(left, right);
  const cv::Mat1i naive =
      NaiveSad(XSobelPrefilter(left, kCap), XSobelPrefilter(right, kCap), kBlock, kNum);

  int compared = 0, agree = 0, naive_valid = 0;
  for (int y = 0; y < kHeight; ++y) {
    for (int x = 0; x < kWidth; ++x) {
      if (naive(y, x) < 0) continue;
      ++naive_valid;
      const std::optional<float> d = map.At(x, y);
      if (!d) continue;
      ++compared;
      if (cvRound(*d) == naive(y, x)) ++agree;
    }
  }
  std::printf("naive SAD: %d pixels, StereoBM matched %d, agree %d (%.1f %%)\n", naive_valid,
              compared, agree, compared > 0 ? 100.0 * agree / compared : 0.0);
  ASSERT_GT(naive_valid, 1000);
  EXPECT_GE(compared, naive_valid * 95 / 100) << "StereoBM left too many pixels unmatched";
  EXPECT_GE(agree, compared * 95 / 100) << agree << " of " << compared << " agree";
}

TEST(ToFixedPoint16U, MapsInvalidToZero) {
  DisparityMap map;
  map.fixed = (cv::Mat1s(1, 4) << -1, 0, 16, 1000);
  const cv::Mat1w out = ToFixedPoint16U(map);
  EXPECT_EQ(out(0, 0), 0);
  EXPECT_EQ(out(0, 1), 0);
  EXPECT_EQ(out(0, 2), 16);
  EXPECT_EQ(out(0, 3), 1000);
}

TEST(ToColour, BlackWhereUnmatchedAndWarmWhereNear) {
  DisparityMap map;
  map.num_disparities = 64;
  map.fixed = (cv::Mat1s(1, 3) << -1, 16 * 2, 16 * 60);
  const cv::Mat3b colour = ToColour(map);
  ASSERT_EQ(colour.size(), map.fixed.size());
  EXPECT_EQ(colour(0, 0), cv::Vec3b(0, 0, 0));
  // BGR: far is blue-ish, near is red-ish.
  EXPECT_GT(colour(0, 1)[0], colour(0, 1)[2]);
  EXPECT_GT(colour(0, 2)[2], colour(0, 2)[0]);
}

TEST(MedianDisparityInMask, ExactMedianOfTheLabelAboveTheFloor) {
  DisparityMap map;
  map.fixed = cv::Mat1s(4, 6, int16_t{-1});
  cv::Mat1i labels(4, 6, 0);
  // Label 3: values 2, 4, 5, 9 px plus one below the floor (1 px) and one unmatched.
  const std::vector<std::pair<cv::Point, int16_t>> pixels = {
      {{1, 1}, 32}, {{2, 1}, 64}, {{3, 1}, 80}, {{4, 2}, 144}, {{1, 2}, 16}, {{2, 2}, -1}};
  for (const auto& [p, v] : pixels) {
    map.fixed(p) = v;
    labels(p) = 3;
  }
  map.fixed(0, 0) = 500;  // another label
  int valid = -1;
  std::optional<double> median =
      MedianDisparityInMask(map, labels, 3, cv::Rect(0, 0, 6, 4), 1.5, &valid);
  ASSERT_TRUE(median.has_value());
  EXPECT_EQ(valid, 4);
  EXPECT_DOUBLE_EQ(*median, 4.5);  // even count: mean of 4 and 5
  median = MedianDisparityInMask(map, labels, 3, cv::Rect(0, 0, 6, 4), 4.5, &valid);
  EXPECT_EQ(valid, 2);
  EXPECT_DOUBLE_EQ(*median, 7.0);
  map.fixed(cv::Point(3, 2)) = 16 * 7;
  labels(cv::Point(3, 2)) = 3;
  median = MedianDisparityInMask(map, labels, 3, cv::Rect(0, 0, 6, 4), 1.5, &valid);
  EXPECT_EQ(valid, 5);
  EXPECT_DOUBLE_EQ(*median, 5.0);  // odd count
  // The box limits the search; a box past the image is clipped.
  median = MedianDisparityInMask(map, labels, 3, cv::Rect(3, 0, 10, 10), 1.5, &valid);
  EXPECT_EQ(valid, 3);  // 5, 7 and 9 px
  EXPECT_DOUBLE_EQ(*median, 7.0);
  EXPECT_FALSE(
      MedianDisparityInMask(map, labels, 8, cv::Rect(0, 0, 6, 4), 1.5, &valid).has_value());
  EXPECT_EQ(valid, 0);
}

TEST(MedianDisparityInMask, AgreesWithSortingOnRandomMaps) {
  cv::RNG rng(99);
  for (int trial = 0; trial < 20; ++trial) {
    DisparityMap map;
    map.fixed.create(37, 53);
    rng.fill(map.fixed, cv::RNG::UNIFORM, -40, 1200);
    cv::Mat1i labels(map.fixed.size());
    rng.fill(labels, cv::RNG::UNIFORM, 0, 3);
    const cv::Rect box(rng.uniform(0, 20), rng.uniform(0, 15), rng.uniform(1, 40),
                       rng.uniform(1, 30));
    const double floor_px = rng.uniform(0.0, 10.0);
    std::vector<int> values;
    for (int y = box.y; y < std::min(box.y + box.height, 37); ++y) {
      for (int x = box.x; x < std::min(box.x + box.width, 53); ++x) {
        if (labels(y, x) == 1 && map.fixed(y, x) >= 0 && map.fixed(y, x) >= floor_px * 16) {
          values.push_back(map.fixed(y, x));
        }
      }
    }
    int valid = -1;
    const std::optional<double> median =
        MedianDisparityInMask(map, labels, 1, box, floor_px, &valid);
    ASSERT_EQ(valid, static_cast<int>(values.size())) << "trial " << trial;
    if (values.empty()) {
      EXPECT_FALSE(median.has_value());
      continue;
    }
    std::sort(values.begin(), values.end());
    const double expected =
        0.5 * (values[(values.size() - 1) / 2] + values[values.size() / 2]) / 16.0;
    ASSERT_TRUE(median.has_value());
    EXPECT_DOUBLE_EQ(*median, expected) << "trial " << trial;
  }
}

}  // namespace
}  // namespace stevi::stereo
