// Where the vehicle pose comes from (server/runtime/pose_source.h): validation, the order of
// precedence (published, recorded, synthetic path, fixed, none), and the synthetic rig's motion
// against GeographicLib's geodesic as an independent reference.
#include "server/runtime/pose_source.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <GeographicLib/Geodesic.hpp>

namespace stevi::server {
namespace {

using ::testing::HasSubstr;

constexpr int64_t kSecond = 1'000'000'000;

geo::VehicleState At(double lat, double lon, double alt, int64_t t_ns = 0) {
  geo::VehicleState s;
  s.lat_deg = lat;
  s.lon_deg = lon;
  s.alt_m = alt;
  s.t_ns = t_ns;
  return s;
}

TEST(PoseSource, CreateNamesEveryBadFieldAsTheConfigDoes) {
  geo::PoseBufferOptions options;
  options.max_age_s = -1;
  const Result<std::unique_ptr<PoseSource>> bad = PoseSource::Create(options, At(91, 0, 0));
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.error().code, ErrorCode::kInvalidArgument);
  EXPECT_THAT(bad.error().message, HasSubstr("geo.max_age_s"));
  EXPECT_THAT(bad.error().message, HasSubstr("geo.fixed_pose.lat_deg"));
  EXPECT_TRUE(PoseSource::Create({}, std::nullopt).ok());
}

TEST(PoseSource, WithoutAnySourceThereIsNoPose) {
  const std::unique_ptr<PoseSource> poses = PoseSource::Create({}, std::nullopt).value();
  EXPECT_EQ(poses->At(0, 5 * kSecond).status, geo::GeoStatus::kNoPose);
}

TEST(PoseSource, TheFixedPoseTakesTheFramesTime) {
  const std::unique_ptr<PoseSource> poses = PoseSource::Create({}, At(43.7, 10.4, 50)).value();
  const geo::PoseLookup lookup = poses->At(7, 5 * kSecond);
  ASSERT_TRUE(lookup.ok());
  EXPECT_EQ(lookup.pose->state.t_ns, 5 * kSecond);
  EXPECT_DOUBLE_EQ(lookup.pose->state.lat_deg, 43.7);
  EXPECT_EQ(lookup.message, "fixed pose");
}

TEST(PoseSource, PublishedStatesWinOverEverythingElseOnceAnyArrived) {
  std::unique_ptr<PoseSource> poses = PoseSource::Create({}, At(43.7, 10.4, 50)).value();
  poses->SetSyntheticPath([](int64_t) { return At(1, 2, 3); });
  // Before any state: the synthetic path (scene clock t_ns), with the frame's Unix time.
  geo::PoseLookup lookup = poses->At(3 * kSecond, 10 * kSecond);
  ASSERT_TRUE(lookup.ok());
  EXPECT_DOUBLE_EQ(lookup.pose->state.lat_deg, 1);
  EXPECT_EQ(lookup.pose->state.t_ns, 10 * kSecond);
  // Two published states: the frame between them is interpolated from them alone.
  ASSERT_TRUE(poses->Publish(At(40, 10, 100, 10 * kSecond)).ok());
  ASSERT_TRUE(poses->Publish(At(40.002, 10, 100, 10 * kSecond + kSecond / 5)).ok());
  lookup = poses->At(3 * kSecond, 10 * kSecond + kSecond / 10);
  ASSERT_TRUE(lookup.ok()) << lookup.message;
  EXPECT_NEAR(lookup.pose->state.lat_deg, 40.001, 1e-9);
  // Out of order: refused, and the buffer is what it was.
  const Status refused = poses->Publish(At(41, 10, 100, 10 * kSecond));
  EXPECT_FALSE(refused.ok());
  lookup = poses->At(3 * kSecond, 10 * kSecond + kSecond / 10);
  EXPECT_NEAR(lookup.pose->state.lat_deg, 40.001, 1e-9);
}

TEST(PoseSource, RecordedStatesAreFoundByTheFramesExactTime) {
  std::unique_ptr<PoseSource> poses = PoseSource::Create({}, At(43.7, 10.4, 50)).value();
  poses->SetRecordedStates({At(45, 9, 200, 100), At(45.5, 9, 200, 200)});
  geo::PoseLookup lookup = poses->At(0, 200);
  ASSERT_TRUE(lookup.ok());
  EXPECT_DOUBLE_EQ(lookup.pose->state.lat_deg, 45.5);
  EXPECT_EQ(lookup.message, "recorded pose");
  // A frame whose pose was not recorded has none: never the fixed pose instead.
  lookup = poses->At(0, 150);
  EXPECT_EQ(lookup.status, geo::GeoStatus::kNoPose);
  EXPECT_THAT(lookup.message, HasSubstr("no pose was recorded"));
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
}  // namespace stevi::server
