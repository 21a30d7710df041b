#include "core/geometry/range.h"

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "core/geometry/calibration_io.h"

namespace stevi::geometry {
namespace {

using ::testing::ElementsAre;
using ::testing::HasSubstr;
using ::testing::IsEmpty;

TEST(DepthFromDisparity, MatchesFocalTimesBaselineOverDisparity) {
  // f = 700 px, B = 0.5 m: f B = 350 px m.
  EXPECT_DOUBLE_EQ(DepthFromDisparity(35.0, 700.0, 0.5), 10.0);
  EXPECT_DOUBLE_EQ(DepthFromDisparity(3.5, 700.0, 0.5), 100.0);
  EXPECT_DOUBLE_EQ(DepthFromDisparity(0.25, 615.0, 0.1), 246.0);
}

TEST(DisparityFromDepth, InvertsDepthFromDisparity) {
  EXPECT_DOUBLE_EQ(DisparityFromDepth(10.0, 700.0, 0.5), 35.0);
  for (double d : {0.5, 1.0, 7.25, 63.0, 200.0}) {
    EXPECT_NEAR(DisparityFromDepth(DepthFromDisparity(d, 615.0, 0.1), 615.0, 0.1), d, 1e-12);
  }
}

TEST(DepthSigma, IsDepthSquaredOverFocalBaselineTimesDisparitySigma) {
  // Thesis example: 0.7 m baseline. At Z = 300 m with f = 1000 px: Z^2 / (f B) = 128.57 m/px.
  EXPECT_NEAR(DepthSigma(300.0, 1000.0, 0.7, 1.0), 90000.0 / 700.0, 1e-9);
  EXPECT_NEAR(DepthSigma(300.0, 1000.0, 0.7, 0.25), 90000.0 / 700.0 / 4.0, 1e-9);
  EXPECT_DOUBLE_EQ(DepthSigma(10.0, 700.0, 0.5, 0.0), 0.0);
  // Matches the derivative of Z(d): |dZ/dd| = f B / d^2 = Z^2 / (f B).
  const double d = 12.0, h = 1e-4;
  const double numeric =
      (DepthFromDisparity(d - h, 700, 0.5) - DepthFromDisparity(d + h, 700, 0.5)) / (2 * h);
  EXPECT_NEAR(DepthSigma(DepthFromDisparity(d, 700, 0.5), 700, 0.5, 1.0), numeric, 1e-6);
}

TEST(PointFromDisparity, IdealQMatchesPinholeBackProjection) {
  const double f = 615.0, baseline = 0.1, cx = 319.5, cy = 241.25;
  const cv::Matx44d Q = *IdealCalibration(cv::Size(640, 480), f, baseline, cx, cy).Q;
  for (double u : {0.0, 100.5, 319.5, 639.0}) {
    for (double v : {0.0, 241.25, 479.0}) {
      for (double d : {0.5, 5.0, 61.5}) {
        const std::optional<cv::Vec3d> p = PointFromDisparity(u, v, d, Q);
        ASSERT_TRUE(p.has_value());
        const double z = f * baseline / d;
        EXPECT_NEAR((*p)[0], (u - cx) * z / f, 1e-9) << "u=" << u << " v=" << v << " d=" << d;
        EXPECT_NEAR((*p)[1], (v - cy) * z / f, 1e-9) << "u=" << u << " v=" << v << " d=" << d;
        EXPECT_NEAR((*p)[2], z, 1e-9) << "u=" << u << " v=" << v << " d=" << d;
      }
    }
  }
}

TEST(PointFromDisparity, ZeroDisparityIsAtInfinity) {
  const cv::Matx44d Q = *IdealCalibration(cv::Size(640, 480), 615.0, 0.1, 320, 240).Q;
  EXPECT_FALSE(PointFromDisparity(10, 10, 0.0, Q).has_value());
}

TEST(RangeFromPoint, IsEuclideanNorm) {
  EXPECT_DOUBLE_EQ(RangeFromPoint(cv::Vec3d(3, 4, 12)), 13.0);
  EXPECT_DOUBLE_EQ(RangeFromPoint(cv::Vec3d(0, 0, 0)), 0.0);
}

TEST(IsTrustedDisparity, FloorIsInclusive) {
  RangeOptions options;
  options.min_disparity_px = 5.0;
  EXPECT_TRUE(IsTrustedDisparity(5.0, 700, 0.5, options));
  EXPECT_FALSE(IsTrustedDisparity(std::nextafter(5.0, 0.0), 700, 0.5, options));
  EXPECT_FALSE(IsTrustedDisparity(0.0, 700, 0.5, options));
  EXPECT_FALSE(IsTrustedDisparity(-1.0, 700, 0.5, options));
  EXPECT_FALSE(IsTrustedDisparity(std::numeric_limits<double>::quiet_NaN(), 700, 0.5, options));
  EXPECT_TRUE(IsTrustedDisparity(200.0, 700, 0.5, options));
}

TEST(IsTrustedDisparity, MaxRangeIsInclusiveAndZeroMeansNoLimit) {
  RangeOptions options;
  options.min_disparity_px = 1.0;
  options.max_range_m = 50.0;
  // f B = 350: d = 7 gives Z = 50 m exactly.
  EXPECT_TRUE(IsTrustedDisparity(7.0, 700, 0.5, options));
  EXPECT_FALSE(IsTrustedDisparity(6.99, 700, 0.5, options));
  EXPECT_TRUE(IsTrustedDisparity(7.01, 700, 0.5, options));
  options.max_range_m = 0.0;
  EXPECT_TRUE(IsTrustedDisparity(1.0, 700, 0.5, options));  // 350 m, no limit
}

TEST(RangeOptionsValidate, DefaultsAreValid) { EXPECT_THAT(RangeOptions().Validate(), IsEmpty()); }

TEST(RangeOptionsValidate, ListsEveryProblem) {
  RangeOptions options;
  options.min_disparity_px = -1;
  options.max_range_m = -5;
  options.disparity_sigma_px = 0;
  const std::vector<std::string> problems = options.Validate();
  EXPECT_THAT(problems, ElementsAre(HasSubstr("min_disparity_px: must be > 0 pixels (got -1)"),
                                    HasSubstr("max_range_m: must be >= 0"),
                                    HasSubstr("disparity_sigma_px: must be > 0")));
}

TEST(RangeOptionsValidate, RejectsNonFiniteValues) {
  RangeOptions options;
  options.min_disparity_px = std::numeric_limits<double>::quiet_NaN();
  options.disparity_sigma_px = std::numeric_limits<double>::infinity();
  EXPECT_THAT(options.Validate(),
              ElementsAre(HasSubstr("min_disparity_px"), HasSubstr("disparity_sigma_px")));
}

}  // namespace
}  // namespace stevi::geometry
