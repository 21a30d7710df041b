#include "core/detection/ground.h"
#include "core/detection/regions.h"
#include "core/detection/stereo_blobs.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <opencv2/core.hpp>

namespace stevi::detection {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;

constexpr double kF = 700, kB = 0.6;

// A 640x480 map with nothing matched.
stereo::DisparityMap EmptyMap() {
  stereo::DisparityMap map;
  map.num_disparities = 64;
  map.fixed = cv::Mat1s(480, 640, stereo::DisparityMap::kInvalid);
  return map;
}

// A level camera `height_m` above flat ground (rows below cy = 240), noisy like a matcher, with a
// fronto-parallel obstacle standing on it and an empty sky.
stereo::DisparityMap GroundScene(double height_m, double obstacle_depth_m, uint64_t seed) {
  stereo::DisparityMap map = EmptyMap();
  cv::RNG rng(seed);
  for (int v = 241; v < 480; ++v) {
    const double d = kB / height_m * (v - 240);
    for (int u = 0; u < 640; ++u) {
      if (rng.uniform(0.0, 1.0) < 0.15) continue;  // unmatched pixels
      map.fixed(v, u) = static_cast<int16_t>(std::lround((d + rng.gaussian(0.15)) * 16));
    }
  }
  // The obstacle: its base row is where the ground has its disparity.
  const double d_obstacle = kF * kB / obstacle_depth_m;
  const int base_row = 240 + static_cast<int>(d_obstacle * height_m / kB);
  const cv::Rect box = cv::Rect(300, base_row - 120, 40, 120) & cv::Rect(0, 0, 640, 480);
  map.fixed(box).setTo(static_cast<int16_t>(std::lround(d_obstacle * 16)));
  return map;
}

TEST(FitGround, RecoversTheLineAndTheCameraHeight) {
  for (const double height : {3.0, 5.0, 12.0}) {
    const stereo::DisparityMap map = GroundScene(height, 30, 7);
    const std::optional<GroundModel> ground = FitGround(map, GroundOptions());
    ASSERT_TRUE(ground.has_value()) << "height " << height;
    EXPECT_NEAR(ground->slope, kB / height, 0.01 * kB / height) << "height " << height;
    EXPECT_NEAR(ground->horizon_row, 240, 1.5) << "height " << height;
    EXPECT_NEAR(ground->CameraHeight(kB), height, 0.02 * height);
    EXPECT_GE(ground->support_rows, 100);
  }
}

TEST(FitGround, NoGroundInAClearSky) {
  stereo::DisparityMap map = EmptyMap();
  map.fixed(cv::Rect(100, 100, 80, 30)).setTo(14 * 16);  // an aircraft
  EXPECT_FALSE(FitGround(map, GroundOptions()).has_value());
}

TEST(FitGround, AWallFillingManyRowsIsNotGround) {
  // A building at one disparity filling the lower half: constant modes, no ground line.
  stereo::DisparityMap map = EmptyMap();
  cv::RNG rng(3);
  for (int v = 280; v < 480; ++v) {
    for (int u = 100; u < 500; ++u)
      map.fixed(v, u) = static_cast<int16_t>(std::lround((8.75 + rng.gaussian(0.1)) * 16));
  }
  EXPECT_FALSE(FitGround(map, GroundOptions()).has_value());
}

// Where the ground went unmatched (smooth, noisy grass), a stepped building (a farther upper
// storey above a nearer front) fills rows at disparities that grow downwards, as the ground's do:
// a slanted line fits them. A constant fits them as well, and they fill part of the view only:
// a wall, and taking it for ground would drop the building as terrain.
TEST(FitGround, ASteppedBuildingWhereTheGroundWentUnmatchedIsNotGround) {
  stereo::DisparityMap map = EmptyMap();
  cv::RNG rng(5);
  for (int v = 100; v < 160; ++v) {
    if (v >= 125 && v < 135) continue;  // the ledge, unmatched
    const double d = v < 125 ? 8.5 : 9.5;
    for (int u = 300; u < 590; ++u) {  // 45 % of the width
      if (rng.uniform(0.0, 1.0) < 0.5) continue;
      map.fixed(v, u) = static_cast<int16_t>(std::lround((d + rng.gaussian(0.1)) * 16));
    }
  }
  EXPECT_FALSE(FitGround(map, GroundOptions()).has_value());
}

// Far ground, seen from 40 m up, spans under 4 px of disparity from the horizon to the bottom
// row, so a constant explains most of its rows too; but it fills them from edge to edge.
TEST(FitGround, FarGroundThatFillsItsRowsIsStillGround) {
  const stereo::DisparityMap map = GroundScene(40.0, 300, 9);
  const std::optional<GroundModel> ground = FitGround(map, GroundOptions());
  ASSERT_TRUE(ground.has_value());
  EXPECT_NEAR(ground->CameraHeight(kB), 40.0, 4.0);
}

TEST(StandsOutFromGround, ObstaclePixelsDoGroundPixelsDoNot) {
  const double height = 3;
  const stereo::DisparityMap map = GroundScene(height, 30, 11);
  const std::optional<GroundModel> ground = FitGround(map, GroundOptions());
  ASSERT_TRUE(ground.has_value());
  const GroundOptions options;
  int ground_out = 0, ground_total = 0;
  for (int v = 300; v < 480; v += 3) {
    for (int u = 0; u < 280; u += 3) {
      if (map.fixed(v, u) < 0) continue;
      ++ground_total;
      ground_out += StandsOutFromGround(ground, v, map.fixed(v, u) / 16.0, options) ? 1 : 0;
    }
  }
  EXPECT_LT(ground_out, 0.01 * ground_total) << ground_out << " of " << ground_total;
  // The obstacle's upper pixels stand out; its base row meets the ground.
  const double d_obstacle = kF * kB / 30;
  const int base_row = 240 + static_cast<int>(d_obstacle * height / kB);
  for (int v = base_row - 120; v < base_row - 20; v += 10) {
    EXPECT_TRUE(StandsOutFromGround(ground, v, d_obstacle, options)) << "row " << v;
  }
  EXPECT_TRUE(StandsOutFromGround(std::nullopt, 470, 0.5, options)) << "no model: all stand out";
}

TEST(GroundOptions, ValidateNamesEveryProblem) {
  GroundOptions o;
  o.min_row_fraction = 0;
  o.min_support_rows = 1;
  o.margin_fraction = 2;
  const std::vector<std::string> problems = o.Validate();
  ASSERT_EQ(problems.size(), 3u);
  EXPECT_THAT(::testing::PrintToString(problems),
              AllOf(HasSubstr("min_row_fraction"), HasSubstr("min_support_rows"),
                    HasSubstr("margin_fraction")));
}

// RangeRegions' test of short hypotheses against their surroundings (regions.h), on an analytic
// map: a camera 3 m over flat ground, a hillside band at 9 px (46.7 m) standing out from the ground
// rows 250..300, and candidate patches the same size cut out of it or standing free.
class ShortBlobSurroundings : public ::testing::Test {
 protected:
  static constexpr double kHeight = 3.0;
  const geometry::StereoRig rig = geometry::StereoRig::Ideal(cv::Size(640, 480), kF, kB, 320, 240);
  stereo::DisparityMap map;
  cv::Mat1b candidates = cv::Mat1b(480, 640, uchar{0});
  GroundModel ground{kB / kHeight, 240.0, 100};
  const cv::Rect hill_patch{80, 262, 20, 15};  // inside the hillside: same range all around
  const cv::Rect aircraft{400, 262, 20, 15};   // 12 px (35 m) against the ground (4..7 px)
  const cv::Rect sky_patch{80, 100, 20, 15};   // above the horizon: never judged

  void SetUp() override {
    map.num_disparities = 64;
    map.fixed = cv::Mat1s(480, 640, stereo::DisparityMap::kInvalid);
    for (int v = 241; v < 480; ++v) {
      map.fixed.row(v).setTo(std::lround(ground.DisparityAt(v) * 16));
    }
    map.fixed(cv::Rect(0, 250, 200, 50)).setTo(9 * 16);
    map.fixed(cv::Rect(40, 80, 120, 60)).setTo(9 * 16);  // a wall in the sky at the same range
    map.fixed(aircraft).setTo(12 * 16);
    for (const cv::Rect& r : {hill_patch, aircraft, sky_patch}) candidates(r).setTo(255);
  }

  std::vector<Detection> Hypotheses(const StereoBlobOptions& options,
                                    const std::optional<GroundModel>& model) const {
    const geometry::RangeOptions range;
    const cv::Mat1b classes = ClassifyPixels(map, rig, range, model, GroundOptions{});
    return RangeRegions(candidates, classes, map, rig, range, options, "test", model, nullptr);
  }

  bool Found(const std::vector<Detection>& detections, const cv::Rect& r) {
    for (const Detection& d : detections) {
      if (d.bbox == r) return true;
    }
    return false;
  }
};

TEST_F(ShortBlobSurroundings, APatchOfAContinuousSurfaceBelowTheHorizonIsTerrain) {
  const StereoBlobOptions options;
  const std::vector<Detection> found = Hypotheses(options, ground);
  EXPECT_FALSE(Found(found, hill_patch)) << "the hillside continues at its range all around it";
  EXPECT_TRUE(Found(found, aircraft)) << "it stands out in depth from the ground around it";
  EXPECT_TRUE(Found(found, sky_patch)) << "above the horizon there is no terrain to be part of";
  EXPECT_EQ(found.size(), 2u);
}

TEST_F(ShortBlobSurroundings,
       DisabledEveryPatchStaysWithoutAGroundModelThePrincipalRowIsTheHorizon) {
  StereoBlobOptions off;
  off.max_attached_fraction = 1.0;
  EXPECT_EQ(Hypotheses(off, ground).size(), 3u);
  // Without a ground model, the principal point's row (a level camera's horizon) says where
  // terrain can be: the hillside patch below it is still terrain, the sky patch above it stays.
  const std::vector<Detection> found = Hypotheses(StereoBlobOptions{}, std::nullopt);
  EXPECT_FALSE(Found(found, hill_patch));
  EXPECT_TRUE(Found(found, aircraft));
  EXPECT_TRUE(Found(found, sky_patch));
}

TEST(StereoBlobOptions, ValidateNamesTheAttachedFraction) {
  StereoBlobOptions options;
  options.max_attached_fraction = 1.5;
  EXPECT_THAT(options.Validate(),
              ::testing::ElementsAre(AllOf(HasSubstr("max_attached_fraction"), HasSubstr("[0, 1]"),
                                           HasSubstr("1.5"))));
}

}  // namespace
}  // namespace stevi::detection
