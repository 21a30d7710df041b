// The synthetic source's scene registry and its rig's place on Earth.
#include "drivers/synthetic/scenarios.h"

#include <cmath>
#include <set>

#include <GeographicLib/Geodesic.hpp>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace stevi::drivers {
namespace {

TEST(SceneNames, EveryNameIsKnownAndOpensOrIsTheBoard) {
  const std::vector<std::string> names = SceneNames();
  EXPECT_EQ(std::set<std::string>(names.begin(), names.end()).size(), names.size());
  EXPECT_GE(names.size(), 3u + EvaluationScenarios().size() + TrackingScenarios().size());
  for (const std::string& name : names) {
    EXPECT_TRUE(IsKnownScene(name)) << name;
    if (name == kChessboardScene) {
      EXPECT_FALSE(FindScenario(name)) << "the board has no scenario";
      EXPECT_FALSE(SceneRigPose(name)) << "the board has no vehicle";
      continue;
    }
    const std::optional<Scenario> scenario = FindScenario(name);
    ASSERT_TRUE(scenario) << name;
    EXPECT_EQ(scenario->name, name);
    EXPECT_THAT(scenario->options.Validate(), ::testing::IsEmpty()) << name;
    ASSERT_TRUE(SceneRigPose(name)) << name;
  }
  EXPECT_TRUE(IsKnownScene(""));  // the default
  EXPECT_FALSE(IsKnownScene("airfeld"));
  EXPECT_FALSE(FindScenario("airfeld"));
}

TEST(FindScenario, AirfieldIsTheDefaultSceneOnTheDefaultRig) {
  const std::optional<Scenario> airfield = FindScenario(kAirfieldScene);
  ASSERT_TRUE(airfield);
  const SyntheticOptions defaults;
  EXPECT_EQ(airfield->options.width, defaults.width);
  EXPECT_EQ(airfield->options.f_px, defaults.f_px);
  EXPECT_EQ(airfield->options.scene.obstacles.size(), DefaultScene().obstacles.size());
  EXPECT_EQ(FindScenario("")->name, kAirfieldScene);
}

// Only a rig that moves has a path; "flight" flies forward at its velocity along the heading.
TEST(SceneRigPath, FollowsTheFlightAndNothingElse) {
  const geo::VehicleState start = *SceneRigPose(kAirfieldScene);
  EXPECT_FALSE(SceneRigPath(kAirfieldScene, start));
  const Scenario flight = FlightScenario();
  const auto path = SceneRigPath(flight.name, start);
  ASSERT_TRUE(path);
  const geo::VehicleState at1 = path(1'000'000'000);
  const cv::Vec3d offset = flight.options.scene.RigOffsetAt(1.0);
  double distance = 0, azimuth = 0, azimuth_end = 0;
  GeographicLib::Geodesic::WGS84().Inverse(start.lat_deg, start.lon_deg, at1.lat_deg, at1.lon_deg,
                                           distance, azimuth, azimuth_end);
  EXPECT_NEAR(distance, std::hypot(offset[0], offset[2]), 1e-3);
  EXPECT_GT(distance, 0.5);
}

TEST(SyntheticRigPose, HoversOverPisaRunway04RAtTheCameraHeight) {
  const geo::VehicleState s = SyntheticRigPose(12);
  EXPECT_DOUBLE_EQ(s.lat_deg, 43.6839);
  EXPECT_DOUBLE_EQ(s.lon_deg, 10.3925);
  EXPECT_DOUBLE_EQ(s.alt_m, 49.5 + 12);
  EXPECT_DOUBLE_EQ(s.yaw_deg, 43);
  EXPECT_TRUE(s.Validate().empty());
}

// 1 km forward and 200 m right at heading 43: the geodesic from the start must be as long as the
// offset and point along heading + atan(200 / 1000); the velocity turns by the heading too.
TEST(MovedRigPose, MovesAlongTheHeadingAsTheGeodesicSays) {
  const geo::VehicleState start = SyntheticRigPose(10);
  const geo::VehicleState moved = MovedRigPose(start, cv::Vec3d(200, 0, 1000), cv::Vec3d(0, 0, 50));
  double distance = 0, azimuth = 0, azimuth_end = 0;
  GeographicLib::Geodesic::WGS84().Inverse(start.lat_deg, start.lon_deg, moved.lat_deg,
                                           moved.lon_deg, distance, azimuth, azimuth_end);
  const double expected_distance = std::hypot(200.0, 1000.0);
  // The local tangent plane curves away from the ellipsoid: at 1 km, by well under a millimetre
  // horizontally, and the height rises by d^2 / (2 R) = 8 cm.
  EXPECT_NEAR(distance, expected_distance, 0.01);
  EXPECT_NEAR(azimuth, 43 + std::atan2(200.0, 1000.0) * 180 / M_PI, 1e-3);
  EXPECT_NEAR(moved.alt_m - start.alt_m, expected_distance * expected_distance / (2 * 6.371e6),
              0.01);
  EXPECT_NEAR(moved.velocity_ned_mps.x(), 50 * std::cos(43 * M_PI / 180), 1e-9);
  EXPECT_NEAR(moved.velocity_ned_mps.y(), 50 * std::sin(43 * M_PI / 180), 1e-9);
  EXPECT_NEAR(moved.velocity_ned_mps.z(), 0, 1e-12);
}

}  // namespace
}  // namespace stevi::drivers
