// Where the vehicle pose comes from (server/runtime/pose_source.h): validation, the order of
// precedence (published, recorded, synthetic path, fixed, none). The synthetic rig's own pose and
// motion: tests/drivers/synthetic/scene_registry_test.cc.
#include "server/runtime/pose_source.h"
#include "tests/testing/status_matchers.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

using stevi::testing::IsError;

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
  EXPECT_THAT(bad, IsError(ErrorCode::kInvalidArgument, HasSubstr("geo.max_age_s")));
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

}  // namespace
}  // namespace stevi::server
