#include "core/detection/ground.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <opencv2/core.hpp>

namespace stevi::detection {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;

constexpr double kF = 700, kB = 0.6;

// A level camera `height_m` above flat ground (rows below cy = 240), noisy like a matcher, with a
// fronto-parallel obstacle standing on it and an empty sky.
stereo::DisparityMap GroundScene(double height_m, double obstacle_depth_m, uint64_t seed) {
  stereo::DisparityMap map;
  map.num_disparities = 64;
  map.fixed = cv::Mat1s(480, 640, stereo::DisparityMap::kInvalid);
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
  stereo::DisparityMap map;
  map.num_disparities = 64;
  map.fixed = cv::Mat1s(480, 640, stereo::DisparityMap::kInvalid);
  map.fixed(cv::Rect(100, 100, 80, 30)).setTo(14 * 16);  // an aircraft
  EXPECT_FALSE(FitGround(map, GroundOptions()).has_value());
}

TEST(FitGround, AWallFillingManyRowsIsNotGround) {
  // A building at one disparity filling the lower half: constant modes, no ground line.
  stereo::DisparityMap map;
  map.num_disparities = 64;
  map.fixed = cv::Mat1s(480, 640, stereo::DisparityMap::kInvalid);
  cv::RNG rng(3);
  for (int v = 280; v < 480; ++v) {
    for (int u = 100; u < 500; ++u) map.fixed(v, u) = static_cast<int16_t>(std::lround((8.75 + rng.gaussian(0.1)) * 16));
  }
  EXPECT_FALSE(FitGround(map, GroundOptions()).has_value());
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

}  // namespace
}  // namespace stevi::detection
