#include "core/geo/pose_buffer.h"
#include "tests/testing/status_matchers.h"

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <GeographicLib/Geodesic.hpp>
#include <GeographicLib/GeodesicLine.hpp>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

using stevi::testing::IsError;

namespace stevi::geo {
namespace {

using ::testing::AllOf;
using ::testing::Contains;
using ::testing::HasSubstr;
using ::testing::IsEmpty;
using ::testing::SizeIs;

constexpr int64_t kSecond = 1'000'000'000;
constexpr double kDeg = std::numbers::pi / 180.0;

const GeographicLib::Geodesic& Wgs84() { return GeographicLib::Geodesic::WGS84(); }

// Geodesic distance (m) between two states' positions on the ellipsoid.
double Distance(double lat0, double lon0, double lat1, double lon1) {
  double s12 = 0;
  Wgs84().Inverse(lat0, lon0, lat1, lon1, s12);
  return s12;
}

VehicleState State(int64_t t_ns, double lat, double lon, double alt, double yaw_deg = 0) {
  return VehicleState{
      .t_ns = t_ns, .lat_deg = lat, .lon_deg = lon, .alt_m = alt, .yaw_deg = yaw_deg};
}

// A state `distance_m` from (lat, lon) along the geodesic at azimuth `azi_deg`.
VehicleState StateAlong(int64_t t_ns, double lat, double lon, double azi_deg, double distance_m,
                        double alt) {
  double lat2 = 0, lon2 = 0;
  Wgs84().Direct(lat, lon, azi_deg, distance_m, lat2, lon2);
  return State(t_ns, lat2, lon2, alt);
}

TEST(PoseBuffer, EmptySaysNoPoseYet) {
  const PoseBuffer buffer;
  const PoseLookup lookup = buffer.At(0);
  EXPECT_EQ(lookup.status, GeoStatus::kNoPose);
  EXPECT_EQ(lookup.message, "no pose yet");
  EXPECT_FALSE(lookup.pose.has_value());
  EXPECT_FALSE(lookup.ok());
}

TEST(PoseBuffer, AddRefusesOutOfOrderAndRepeatedTimes) {
  PoseBuffer buffer;
  ASSERT_TRUE(buffer.Add(State(2 * kSecond, 43.68, 10.39, 50)).ok());
  for (int64_t t : {kSecond, 2 * kSecond}) {
    const Status status = buffer.Add(State(t, 43.68, 10.39, 60));
    ASSERT_FALSE(status.ok());
    EXPECT_THAT(status, IsError(ErrorCode::kInvalidArgument, HasSubstr("t_ns: out of order")));
    EXPECT_THAT(status.error().message, HasSubstr("newest state (2000000000 ns)"));
  }
  EXPECT_EQ(buffer.size(), 1u);
  EXPECT_EQ(buffer.Newest()->alt_m, 50);
}

TEST(PoseBuffer, AddRefusesInvalidStatesNamingTheFields) {
  PoseBuffer buffer;
  VehicleState bad = State(0, 95, 10, 50);
  bad.sigma.yaw_deg = -1;
  const Status status = buffer.Add(bad);
  ASSERT_FALSE(status.ok());
  EXPECT_THAT(status.error().message, HasSubstr("lat_deg: must be in [-90, 90] degrees (got 95)"));
  EXPECT_THAT(status.error().message, HasSubstr("sigma.yaw_deg: must be >= 0"));
  EXPECT_EQ(buffer.size(), 0u);
}

TEST(PoseBuffer, ExactTimeReturnsTheStoredState) {
  PoseBuffer buffer;
  VehicleState s = State(kSecond, 43.68, 10.39, 50, 350);
  s.roll_deg = 3;
  s.velocity_ned_mps = {1, 2, 3};
  ASSERT_TRUE(buffer.Add(s).ok());
  const PoseLookup lookup = buffer.At(kSecond);
  ASSERT_TRUE(lookup.ok()) << lookup.message;
  EXPECT_EQ(lookup.pose->state, s);
  EXPECT_FALSE(lookup.pose->extrapolated);
  EXPECT_EQ(lookup.message, "ok");
}

TEST(PoseBufferInterpolation, PositionMatchesTheGeodesicMidpoint) {
  // 30 m in 1 s at azimuth 37 degrees, climbing 4 m.
  PoseBuffer buffer({.max_age_s = 2, .max_gap_s = 2});
  const VehicleState s0 = State(0, 43.68, 10.39, 100);
  const VehicleState s1 = StateAlong(kSecond, s0.lat_deg, s0.lon_deg, 37, 30, 104);
  ASSERT_TRUE(buffer.Add(s0).ok());
  ASSERT_TRUE(buffer.Add(s1).ok());

  const GeographicLib::GeodesicLine line =
      Wgs84().InverseLine(s0.lat_deg, s0.lon_deg, s1.lat_deg, s1.lon_deg);
  for (double w : {0.25, 0.5, 0.9}) {
    const PoseLookup lookup = buffer.At(static_cast<int64_t>(w * kSecond));
    ASSERT_TRUE(lookup.ok()) << lookup.message;
    const VehicleState& s = lookup.pose->state;
    double lat = 0, lon = 0;
    line.Position(w * line.Distance(), lat, lon);
    // The chord in the tangent plane and the geodesic differ by ~s^2/(8R) vertically (18 um).
    EXPECT_LT(Distance(s.lat_deg, s.lon_deg, lat, lon), 1e-3) << "w " << w;
    EXPECT_NEAR(s.alt_m, 100 + 4 * w, 1e-3) << "w " << w;
    EXPECT_NEAR(Distance(s0.lat_deg, s0.lon_deg, s.lat_deg, s.lon_deg), 30 * w, 1e-3);
  }
}

TEST(PoseBufferInterpolation, CrossesTheAntimeridian) {
  // 22 m across longitude 180 at the equator: a naive longitude average would land near 0.
  PoseBuffer buffer;
  ASSERT_TRUE(buffer.Add(State(0, 0.0, 179.9999, 10)).ok());
  ASSERT_TRUE(buffer.Add(State(kSecond / 10, 0.0, -179.9999, 10)).ok());
  const PoseLookup lookup = buffer.At(kSecond / 20);
  ASSERT_TRUE(lookup.ok()) << lookup.message;
  const VehicleState& s = lookup.pose->state;
  EXPECT_GT(std::abs(s.lon_deg), 179.99999);
  EXPECT_LT(Distance(s.lat_deg, s.lon_deg, 0.0, 180.0), 1e-3);
  EXPECT_NEAR(s.alt_m, 10, 1e-3);
}

TEST(PoseBufferInterpolation, YawGoesTheShortWayThroughNorth) {
  PoseBuffer buffer;
  ASSERT_TRUE(buffer.Add(State(0, 43.68, 10.39, 50, 350)).ok());
  ASSERT_TRUE(buffer.Add(State(kSecond / 10, 43.68, 10.39, 50, 10)).ok());
  for (double w : {0.25, 0.5, 0.75}) {
    const PoseLookup lookup = buffer.At(static_cast<int64_t>(w * kSecond / 10));
    ASSERT_TRUE(lookup.ok()) << lookup.message;
    const VehicleState& s = lookup.pose->state;
    EXPECT_NEAR(s.yaw_deg, -10 + 20 * w, 1e-9) << "w " << w;  // never near 180
    EXPECT_NEAR(s.roll_deg, 0, 1e-9);
    EXPECT_NEAR(s.pitch_deg, 0, 1e-9);
  }
  // 20 degrees in 0.1 s about body z, level: 200 deg/s.
  const PoseLookup mid = buffer.At(kSecond / 20);
  EXPECT_LT((mid.pose->angular_rate_body_rps - Eigen::Vector3d(0, 0, 200 * kDeg)).norm(), 1e-9);
}

TEST(PoseBufferInterpolation, AttitudeFollowsTheGreatCircleOfRotations) {
  // Slerp is the constant-rate rotation: the angle from q0 is w * theta and to q1 (1 - w) * theta.
  PoseBuffer buffer;
  VehicleState s0 = State(0, 43.68, 10.39, 50, 30);
  s0.roll_deg = 10;
  s0.pitch_deg = -5;
  VehicleState s1 = State(kSecond / 5, 43.68, 10.39, 50, 80);
  s1.roll_deg = -20;
  s1.pitch_deg = 15;
  ASSERT_TRUE(buffer.Add(s0).ok());
  ASSERT_TRUE(buffer.Add(s1).ok());
  const Eigen::Quaterniond q0 = NedFromBody(s0), q1 = NedFromBody(s1);
  const double theta = q0.angularDistance(q1);
  for (double w : {0.1, 0.5, 0.8}) {
    const PoseLookup lookup = buffer.At(static_cast<int64_t>(w * kSecond / 5));
    ASSERT_TRUE(lookup.ok()) << lookup.message;
    const Eigen::Quaterniond q = NedFromBody(lookup.pose->state);
    EXPECT_NEAR(q0.angularDistance(q), w * theta, 1e-9) << "w " << w;
    EXPECT_NEAR(q.angularDistance(q1), (1 - w) * theta, 1e-9) << "w " << w;
    // The angular rate integrates to the same rotation: q0 * exp(omega * t) = q.
    const Eigen::Vector3d turn = lookup.pose->angular_rate_body_rps * (w * 0.2);
    const Eigen::Quaterniond integrated =
        q0 * Eigen::Quaterniond(Eigen::AngleAxisd(turn.norm(), turn.normalized()));
    EXPECT_LT(integrated.angularDistance(q), 1e-9);
  }
}

TEST(PoseBufferInterpolation, VelocityAndSigmasAreLinear) {
  PoseBuffer buffer;
  VehicleState s0 = State(0, 43.68, 10.39, 50);
  s0.velocity_ned_mps = {10, 0, 0};
  s0.sigma = {.horizontal_m = 1, .vertical_m = 2, .tilt_deg = 0.1, .yaw_deg = 1};
  VehicleState s1 = State(kSecond / 10, 43.68, 10.39, 50);
  s1.velocity_ned_mps = {20, -4, 2};
  s1.sigma = {.horizontal_m = 3, .vertical_m = 2, .tilt_deg = 0.3, .yaw_deg = 2};
  ASSERT_TRUE(buffer.Add(s0).ok());
  ASSERT_TRUE(buffer.Add(s1).ok());
  const PoseLookup lookup = buffer.At(kSecond / 40);  // w = 0.25
  ASSERT_TRUE(lookup.ok());
  const VehicleState& s = lookup.pose->state;
  EXPECT_LT((s.velocity_ned_mps - Eigen::Vector3d(12.5, -1, 0.5)).norm(), 1e-12);
  EXPECT_NEAR(s.sigma.horizontal_m, 1.5, 1e-12);
  EXPECT_NEAR(s.sigma.vertical_m, 2, 1e-12);
  EXPECT_NEAR(s.sigma.tilt_deg, 0.15, 1e-12);
  EXPECT_NEAR(s.sigma.yaw_deg, 1.25, 1e-12);
  EXPECT_EQ(s.t_ns, kSecond / 40);
}

// 1 s of states at 100 Hz, flying at 30 m/s on azimuth 60 and climbing 2 m/s.
void AddFlight(PoseBuffer& buffer) {
  const double azi = 60;
  const Eigen::Vector3d v(30 * std::cos(azi * kDeg), 30 * std::sin(azi * kDeg), -2);
  for (int i = 0; i <= 100; ++i) {
    VehicleState s = StateAlong(i * kSecond / 100, 43.68, 10.39, azi, 0.3 * i, 100 + 0.02 * i);
    s.yaw_deg = azi;
    s.velocity_ned_mps = v;
    EXPECT_TRUE(buffer.Add(s).ok());
  }
}

TEST(PoseBufferAge, RefusesFramesOlderThanMaxAge) {
  PoseBuffer buffer;  // max_age_s 0.5
  AddFlight(buffer);  // newest at 1 s
  const PoseLookup old = buffer.At(kSecond * 4 / 10);
  EXPECT_EQ(old.status, GeoStatus::kFrameTooOld);
  EXPECT_EQ(old.message, "frame too old (0.60 s before the newest pose)");
  EXPECT_FALSE(old.pose.has_value());
  EXPECT_TRUE(buffer.At(kSecond * 6 / 10).ok());
  EXPECT_TRUE(buffer.At(kSecond / 2).ok());  // exactly max_age_s
}

TEST(PoseBufferAge, RefusesFramesBeforeTheOldestStateKept) {
  PoseBuffer buffer({.capacity = 10});
  for (int i = 0; i < 25; ++i) {
    ASSERT_TRUE(buffer.Add(State(i * kSecond / 100, 43.68, 10.39, 50)).ok());
  }
  EXPECT_EQ(buffer.size(), 10u);
  const PoseLookup lookup = buffer.At(10 * kSecond / 100);  // states 15..24 are kept
  EXPECT_EQ(lookup.status, GeoStatus::kFrameTooOld);
  EXPECT_EQ(lookup.message, "frame before the oldest pose (0.05 s)");
  EXPECT_TRUE(buffer.At(15 * kSecond / 100).ok());
}

TEST(PoseBufferAge, RefusesInterpolationAcrossAGap) {
  PoseBuffer buffer({.max_age_s = 5});
  ASSERT_TRUE(buffer.Add(State(0, 43.68, 10.39, 50)).ok());
  ASSERT_TRUE(buffer.Add(State(kSecond, 43.68, 10.39, 50)).ok());
  const PoseLookup lookup = buffer.At(kSecond / 2);
  EXPECT_EQ(lookup.status, GeoStatus::kPoseGap);
  EXPECT_EQ(lookup.message, "pose gap (1.00 s) at the frame");
  EXPECT_TRUE(buffer.At(0).ok());  // the states themselves are fine
}

TEST(PoseBufferExtrapolation, UsesTheNedVelocityWithinTheMargin) {
  PoseBuffer buffer;
  AddFlight(buffer);
  const VehicleState newest = *buffer.Newest();
  const PoseLookup lookup = buffer.At(kSecond + kSecond / 20);  // 50 ms ahead
  ASSERT_TRUE(lookup.ok()) << lookup.message;
  EXPECT_TRUE(lookup.pose->extrapolated);
  const VehicleState& s = lookup.pose->state;
  double s12 = 0, azi1 = 0, azi2 = 0;
  Wgs84().Inverse(newest.lat_deg, newest.lon_deg, s.lat_deg, s.lon_deg, s12, azi1, azi2);
  EXPECT_NEAR(s12, 30 * 0.05, 1e-3);
  EXPECT_NEAR(azi1, 60, 1e-4);
  EXPECT_NEAR(s.alt_m, newest.alt_m + 2 * 0.05, 1e-3);
  EXPECT_NEAR(s.yaw_deg, 60, 1e-9);
  EXPECT_EQ(s.t_ns, kSecond + kSecond / 20);
}

TEST(PoseBufferExtrapolation, RefusesBeyondTheMargin) {
  PoseBuffer buffer;  // max_extrapolation_s 0.1
  AddFlight(buffer);
  const PoseLookup lookup = buffer.At(kSecond + 82 * kSecond / 100);
  EXPECT_EQ(lookup.status, GeoStatus::kPoseTooOld);
  EXPECT_EQ(lookup.message, "pose too old (0.82 s)");
  EXPECT_FALSE(lookup.pose.has_value());
  EXPECT_EQ(buffer.At(kSecond + kSecond / 9).status, GeoStatus::kPoseTooOld);
  EXPECT_TRUE(buffer.At(kSecond + kSecond / 10).ok());
  // With no margin, only the newest state's own time is served.
  PoseBuffer strict({.max_extrapolation_s = 0});
  AddFlight(strict);
  EXPECT_EQ(strict.At(kSecond + 1).status, GeoStatus::kPoseTooOld);
  EXPECT_TRUE(strict.At(kSecond).ok());
}

TEST(PoseBufferExtrapolation, TurnsTheAttitudeWithTheLastAngularRate) {
  PoseBuffer buffer;
  ASSERT_TRUE(buffer.Add(State(0, 43.68, 10.39, 50, 0)).ok());
  ASSERT_TRUE(buffer.Add(State(kSecond / 10, 43.68, 10.39, 50, 3)).ok());  // 30 deg/s
  const PoseLookup lookup = buffer.At(kSecond / 10 + kSecond / 20);
  ASSERT_TRUE(lookup.ok()) << lookup.message;
  EXPECT_NEAR(lookup.pose->state.yaw_deg, 4.5, 1e-9);
  // A single state: no rate, the attitude is held.
  PoseBuffer single;
  ASSERT_TRUE(single.Add(State(0, 43.68, 10.39, 50, 3)).ok());
  const PoseLookup held = single.At(kSecond / 20);
  ASSERT_TRUE(held.ok());
  EXPECT_NEAR(held.pose->state.yaw_deg, 3, 1e-9);
  EXPECT_EQ(held.pose->angular_rate_body_rps, Eigen::Vector3d::Zero());
}

TEST(PoseBuffer, ConcurrentAddAndAt) {
  // One writer at "100 Hz", three readers asking for the pose 5 ms behind the newest state.
  PoseBuffer buffer({.capacity = 50});
  std::atomic<bool> done = false;
  std::atomic<int64_t> newest_t = -1;
  std::atomic<int> served = 0, bad = 0;
  std::vector<std::thread> readers;
  for (int r = 0; r < 3; ++r) {
    readers.emplace_back([&] {
      while (!done) {
        const int64_t t = newest_t.load() - kSecond / 200;
        if (t < 0) continue;
        const PoseLookup lookup = buffer.At(t);
        if (!lookup.ok()) {
          if (lookup.status != GeoStatus::kFrameTooOld) ++bad;  // the reader may lag behind
          continue;
        }
        // The vehicle flies north at 1 m per 10 ms: alt encodes time (1 m per state).
        const double expected_alt = 100 + static_cast<double>(t) / (kSecond / 100);
        if (std::abs(lookup.pose->state.alt_m - expected_alt) > 1e-6) ++bad;
        ++served;
      }
    });
  }
  for (int i = 0; i < 2000; ++i) {
    ASSERT_TRUE(buffer.Add(State(i * kSecond / 100, 43.68, 10.39, 100 + i)).ok());
    newest_t = i * kSecond / 100;
    std::this_thread::sleep_for(std::chrono::microseconds(50));  // let the readers in
  }
  done = true;
  for (std::thread& t : readers) t.join();
  EXPECT_EQ(bad.load(), 0);
  EXPECT_GT(served.load(), 0);
  EXPECT_EQ(buffer.size(), 50u);
}

TEST(PoseBufferOptionsValidate, NamesEveryBadField) {
  EXPECT_THAT(PoseBufferOptions{}.Validate(), IsEmpty());
  const PoseBufferOptions bad{.capacity = 1,
                              .max_age_s = 0,
                              .max_extrapolation_s = -0.1,
                              .max_gap_s = std::numeric_limits<double>::infinity()};
  const std::vector<std::string> problems = bad.Validate();
  EXPECT_THAT(problems, SizeIs(4));
  EXPECT_THAT(problems, Contains(AllOf(HasSubstr("capacity: must be >= 2"), HasSubstr("(got 1)"))));
  EXPECT_THAT(problems, Contains(AllOf(HasSubstr("max_age_s: must be > 0"), HasSubstr("(got 0)"))));
  EXPECT_THAT(problems, Contains(AllOf(HasSubstr("max_extrapolation_s: must be >= 0"),
                                       HasSubstr("(got -0.1)"))));
  EXPECT_THAT(problems, Contains(AllOf(HasSubstr("max_gap_s:"), HasSubstr("(got inf)"))));
  EXPECT_THROW(PoseBuffer{bad}, std::invalid_argument);
}

TEST(GeoStatusName, WireNames) {
  EXPECT_EQ(GeoStatusName(GeoStatus::kOk), "OK");
  EXPECT_EQ(GeoStatusName(GeoStatus::kNoPose), "NO_POSE");
  EXPECT_EQ(GeoStatusName(GeoStatus::kPoseTooOld), "POSE_TOO_OLD");
  EXPECT_EQ(GeoStatusName(GeoStatus::kFrameTooOld), "FRAME_TOO_OLD");
  EXPECT_EQ(GeoStatusName(GeoStatus::kPoseGap), "POSE_GAP");
}

}  // namespace
}  // namespace stevi::geo
