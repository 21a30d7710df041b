#include "core/geo/vehicle_state.h"

#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/core/geo/geo_reference.h"

namespace stevi::geo {
namespace {

using ::testing::AllOf;
using ::testing::Contains;
using ::testing::HasSubstr;
using ::testing::IsEmpty;
using ::testing::SizeIs;

using ref::ReferenceDcm;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

TEST(NedFromBody, MatchesTheWrittenOutDirectionCosineMatrix) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> roll(-180, 180), pitch(-89, 89), yaw(-360, 360);
  for (int i = 0; i < 200; ++i) {
    const double r = roll(rng), p = pitch(rng), y = yaw(rng);
    const Eigen::Matrix3d got = NedFromBody(r, p, y).toRotationMatrix();
    EXPECT_LT((got - ReferenceDcm(r, p, y)).cwiseAbs().maxCoeff(), 1e-14)
        << "roll " << r << " pitch " << p << " yaw " << y;
  }
}

TEST(NedFromBody, SignConventions) {
  const Eigen::Vector3d forward = Eigen::Vector3d::UnitX(), right = Eigen::Vector3d::UnitY();
  // Yaw 90: the nose points east (heading clockwise from north).
  EXPECT_LT((NedFromBody(0, 0, 90) * forward - Eigen::Vector3d(0, 1, 0)).norm(), 1e-15);
  // Pitch 30 nose up: the nose has a negative down component.
  const Eigen::Vector3d nose = NedFromBody(0, 30, 0) * forward;
  EXPECT_NEAR(nose.z(), -0.5, 1e-15);
  EXPECT_NEAR(nose.x(), std::sqrt(3.0) / 2, 1e-15);
  // Roll 30 right wing down: the right wing has a positive down component.
  const Eigen::Vector3d wing = NedFromBody(30, 0, 0) * right;
  EXPECT_NEAR(wing.z(), 0.5, 1e-15);
}

TEST(EulerFromNedFromBody, RoundTripsAndWrapsYaw) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> roll(-179, 179), pitch(-89, 89), yaw(-179, 179);
  for (int i = 0; i < 200; ++i) {
    const double r = roll(rng), p = pitch(rng), y = yaw(rng);
    const EulerDeg e = EulerFromNedFromBody(NedFromBody(r, p, y));
    EXPECT_NEAR(e.roll_deg, r, 1e-9);
    EXPECT_NEAR(e.pitch_deg, p, 1e-9);
    EXPECT_NEAR(e.yaw_deg, y, 1e-9);
  }
  EXPECT_NEAR(EulerFromNedFromBody(NedFromBody(0, 0, 350)).yaw_deg, -10, 1e-9);
  EXPECT_NEAR(EulerFromNedFromBody(NedFromBody(0, 0, -180)).yaw_deg, 180, 1e-9);
  // Gimbal lock: the rotation is still reproduced.
  const Eigen::Quaterniond locked = NedFromBody(0, 90, 40);
  const EulerDeg e = EulerFromNedFromBody(locked);
  EXPECT_NEAR(e.pitch_deg, 90, 1e-6);
  EXPECT_LT(NedFromBody(e.roll_deg, e.pitch_deg, e.yaw_deg).angularDistance(locked), 1e-7);
}

TEST(VehicleStateValidate, DefaultAndTypicalStatesAreValid) {
  EXPECT_THAT(VehicleState{}.Validate(), IsEmpty());
  VehicleState s{.t_ns = 5,
                 .lat_deg = 43.68,
                 .lon_deg = 10.39,
                 .alt_m = 52.0,
                 .roll_deg = -3,
                 .pitch_deg = 2,
                 .yaw_deg = 350,
                 .velocity_ned_mps = {30, 1, -0.5},
                 .sigma = {.horizontal_m = 1.5, .vertical_m = 3, .tilt_deg = 0.2, .yaw_deg = 1}};
  EXPECT_THAT(s.Validate(), IsEmpty());
}

TEST(VehicleStateValidate, NamesEveryBadField) {
  VehicleState s;
  s.lat_deg = 91;
  s.lon_deg = -180.5;
  s.alt_m = 120000;  // e.g. millimetres
  s.roll_deg = kNaN;
  s.pitch_deg = 95;
  s.yaw_deg = 400;
  s.velocity_ned_mps = {0, std::numeric_limits<double>::infinity(), 0};
  s.sigma = {.horizontal_m = -1, .vertical_m = kNaN, .tilt_deg = -0.1, .yaw_deg = -2};
  const std::vector<std::string> problems = s.Validate();
  EXPECT_THAT(problems, SizeIs(11));
  EXPECT_THAT(problems,
              Contains(AllOf(HasSubstr("lat_deg: must be in [-90, 90]"), HasSubstr("(got 91)"))));
  EXPECT_THAT(problems, Contains(AllOf(HasSubstr("lon_deg:"), HasSubstr("(got -180.5)"))));
  EXPECT_THAT(problems, Contains(AllOf(HasSubstr("alt_m:"), HasSubstr("ellipsoid"),
                                       HasSubstr("(got 120000)"))));
  EXPECT_THAT(problems, Contains(AllOf(HasSubstr("roll_deg:"), HasSubstr("(got nan)"))));
  EXPECT_THAT(problems, Contains(AllOf(HasSubstr("pitch_deg:"), HasSubstr("(got 95)"))));
  EXPECT_THAT(problems, Contains(AllOf(HasSubstr("yaw_deg: must be in [-360, 360]"),
                                       HasSubstr("(got 400)"))));
  EXPECT_THAT(problems, Contains(AllOf(HasSubstr("velocity_ned_mps.e: must be finite"),
                                       HasSubstr("(got inf)"))));
  EXPECT_THAT(problems, Contains(AllOf(HasSubstr("sigma.horizontal_m: must be >= 0"),
                                       HasSubstr("(got -1)"))));
  EXPECT_THAT(problems, Contains(HasSubstr("sigma.vertical_m:")));
  EXPECT_THAT(problems, Contains(HasSubstr("sigma.tilt_deg:")));
  EXPECT_THAT(problems, Contains(HasSubstr("sigma.yaw_deg:")));
}

TEST(VehicleStateValidate, BoundsAreInclusive) {
  VehicleState s{.lat_deg = -90,
                 .lon_deg = 180,
                 .alt_m = -1000,
                 .roll_deg = 180,
                 .pitch_deg = -90,
                 .yaw_deg = -360};
  EXPECT_THAT(s.Validate(), IsEmpty());
}

}  // namespace
}  // namespace stevi::geo
