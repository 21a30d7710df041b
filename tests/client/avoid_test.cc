#include "client/advisory/avoid.h"

#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/client/json_check.h"

namespace stevi::client {
namespace {

using ::testing::AllOf;
using ::testing::ElementsAre;
using ::testing::HasSubstr;
using ::testing::IsEmpty;
using testing::Json;
using testing::JsonParser;

constexpr std::int64_t kMs = 1'000'000;

// An encounter's level, time and distance of the closest approach, within `tol` (s and m).
MATCHER_P4(IsEncounter, level, t_cpa_s, d_cpa_m, tol,
           std::string(AdvisoryLevelName(level)) + " with t_cpa " + std::to_string(t_cpa_s) +
               " s and d_cpa " + std::to_string(d_cpa_m) + " m") {
  *result_listener << "is " << AdvisoryLevelName(arg.level) << " with t_cpa " << arg.t_cpa_s
                   << " s, d_cpa " << arg.d_cpa_m << " m";
  return arg.level == level && std::abs(arg.t_cpa_s - t_cpa_s) <= tol &&
         std::abs(arg.d_cpa_m - d_cpa_m) <= tol;
}

Obstacle MakeObstacle(std::uint64_t id, Ned position_m, Ned velocity_mps) {
  Obstacle o;
  o.track_id = id;
  o.position_m = position_m;
  o.velocity_mps = velocity_mps;
  return o;
}

const OwnVehicle kNorthAt10{{0, 0, 0}, {10, 0, 0}};  // at the origin, flying north at 10 m/s

// The geometry cases below were worked out for a 30 m protected radius and a 100 m caution range
// (a larger aircraft than the defaults' small UAV): they pass them explicitly.
const AvoidOptions kR30 = [] {
  AvoidOptions o;
  o.protected_radius_m = 30;
  o.caution_range_m = 100;
  return o;
}();

TEST(Assess, HeadOnCollisionCourseIsAvoidAtDistanceOverClosingSpeed) {
  // 200 m ahead, closing at 10 + 10 m/s: collision in 10 s.
  const Encounter e = Assess(kNorthAt10, MakeObstacle(1, {200, 0, 0}, {-10, 0, 0}), kR30);
  EXPECT_THAT(e, IsEncounter(AdvisoryLevel::kAvoid, 200.0 / 20.0, 0.0, 1e-9));
  EXPECT_DOUBLE_EQ(e.distance_m, 200);
  EXPECT_DOUBLE_EQ(e.bearing_deg, 0);
  EXPECT_DOUBLE_EQ(e.protected_radius_m, 30);
  // The same at 500 m: 25 s away, beyond the 15 s AVOID horizon but inside WARNING's 30 s.
  EXPECT_THAT(Assess(kNorthAt10, MakeObstacle(1, {500, 0, 0}, {-10, 0, 0}), kR30),
              IsEncounter(AdvisoryLevel::kWarning, 25.0, 0.0, 1e-9));
  // At 1000 m (50 s): CAUTION's 60 s horizon; at 1400 m (70 s): beyond every horizon.
  EXPECT_THAT(Assess(kNorthAt10, MakeObstacle(1, {1000, 0, 0}, {-10, 0, 0}), kR30),
              IsEncounter(AdvisoryLevel::kCaution, 50.0, 0.0, 1e-9));
  EXPECT_THAT(Assess(kNorthAt10, MakeObstacle(1, {1400, 0, 0}, {-10, 0, 0}), kR30),
              IsEncounter(AdvisoryLevel::kClear, 70.0, 0.0, 1e-9));
}

TEST(Assess, DivergingObstacleIsClear) {
  const OwnVehicle hovering{{0, 0, 0}, {0, 0, 0}};
  const Encounter e = Assess(hovering, MakeObstacle(2, {0, 300, 0}, {0, 10, 0}), kR30);
  EXPECT_THAT(e, IsEncounter(AdvisoryLevel::kClear, 0.0, 300.0, 1e-9));
  EXPECT_DOUBLE_EQ(e.bearing_deg, 90);
  // Diverging diagonally while the vehicle flies the other way.
  EXPECT_THAT(Assess(kNorthAt10, MakeObstacle(2, {-200, -200, 0}, {-5, -5, 0}), kR30),
              IsEncounter(AdvisoryLevel::kClear, 0.0, std::hypot(200.0, 200.0), 1e-9));
}

TEST(Assess, CrossingAtKnownMissDistance) {
  // The obstacle flies east at 10 m/s while the vehicle flies north at 10 m/s: relative velocity
  // v = (-10, 10, 0). From p = (150, -100, 0): t_cpa = -p.v / |v|^2 = 2500 / 200 = 12.5 s, the
  // relative position then is (25, 25, 0), and the miss distance |p x v| / |v| = 500 / sqrt(200).
  const Obstacle crossing = MakeObstacle(3, {150, -100, 0}, {0, 10, 0});
  const double miss_m = 500 / std::sqrt(200.0);
  ASSERT_NEAR(miss_m, std::hypot(25.0, 25.0), 1e-12);
  const Encounter e = Assess(kNorthAt10, crossing, kR30);
  // 35.4 m misses the 30 m protected radius but not twice it.
  EXPECT_THAT(e, IsEncounter(AdvisoryLevel::kWarning, 12.5, miss_m, 1e-9));
  EXPECT_NEAR(e.bearing_deg, 360 - std::atan2(100.0, 150.0) * 180 / std::numbers::pi, 1e-9);
  EXPECT_NEAR(e.distance_m, std::hypot(150.0, 100.0), 1e-9);

  // A 3 m horizontal sigma widens the radius to 30 + 2 * 3 = 36 m: now inside it.
  Obstacle uncertain = crossing;
  uncertain.sigma_horizontal_m = 3;
  const Encounter u = Assess(kNorthAt10, uncertain, kR30);
  EXPECT_DOUBLE_EQ(u.protected_radius_m, 36);
  EXPECT_THAT(u, IsEncounter(AdvisoryLevel::kAvoid, 12.5, miss_m, 1e-9));
  // The vertical sigma counts the same way (the larger of the two).
  uncertain.sigma_horizontal_m = 0.5;
  uncertain.sigma_vertical_m = 3;
  EXPECT_THAT(Assess(kNorthAt10, uncertain, kR30),
              IsEncounter(AdvisoryLevel::kAvoid, 12.5, miss_m, 1e-9));
}

TEST(Assess, VerticalSeparationCountsIn3D) {
  // Head-on, 10 s away, but 20 m or 40 m above (down is negative): the miss is vertical.
  EXPECT_THAT(Assess(kNorthAt10, MakeObstacle(4, {200, 0, -20}, {-10, 0, 0}), kR30),
              IsEncounter(AdvisoryLevel::kAvoid, 10.0, 20.0, 1e-9));
  EXPECT_THAT(Assess(kNorthAt10, MakeObstacle(4, {200, 0, -40}, {-10, 0, 0}), kR30),
              IsEncounter(AdvisoryLevel::kWarning, 10.0, 40.0, 1e-9));
  // A climbing vehicle meets a level obstacle: relative v = (-10, 0, 2) from p = (100, 0, -20),
  // t_cpa = (1000 + 40) / 104 = 10 s, where p + v t = (0, 0, 0).
  const OwnVehicle climbing{{0, 0, 0}, {10, 0, -2}};
  EXPECT_THAT(Assess(climbing, MakeObstacle(4, {100, 0, -20}, {0, 0, 0}), kR30),
              IsEncounter(AdvisoryLevel::kAvoid, 10.0, 0.0, 1e-9));
}

TEST(Assess, StationaryObstacleAheadOfAMovingVehicle) {
  // The vehicle flies east at 15 m/s from (0, 200, 0); a hovering obstacle 10 m north of its path,
  // 300 m ahead: closest approach in 20 s at 10 m.
  OwnVehicle own{{0, 200, 0}, {0, 15, 0}};
  const Obstacle hovering = MakeObstacle(5, {10, 500, 0}, {0, 0, 0});
  const Encounter far = Assess(own, hovering, kR30);
  EXPECT_THAT(far, IsEncounter(AdvisoryLevel::kWarning, 20.0, 10.0, 1e-9));
  EXPECT_NEAR(far.bearing_deg, std::atan2(300.0, 10.0) * 180 / std::numbers::pi, 1e-9);
  // 200 m further on it is 100 m ahead: 6.7 s, AVOID.
  own.position_m.e += 200;
  EXPECT_THAT(Assess(own, hovering, kR30),
              IsEncounter(AdvisoryLevel::kAvoid, 100.0 / 15, 10.0, 1e-9));
  // Passed: behind and receding at 100 m, 10 m to the side. Closest approach is now (t = 0).
  own.position_m.e += 210;
  const Encounter passed = Assess(own, hovering, kR30);
  EXPECT_DOUBLE_EQ(passed.t_cpa_s, 0);
  EXPECT_NEAR(passed.d_cpa_m, std::hypot(10.0, 110.0), 1e-9);
  EXPECT_NEAR(passed.bearing_deg, 270 + std::atan2(10.0, 110.0) * 180 / std::numbers::pi, 1e-9);
  EXPECT_EQ(passed.level, AdvisoryLevel::kClear)
      << "within 4 R = 120 m but receding, outside R and beyond the 100 m caution range";
  own.position_m.e -= 20;  // 90 m behind: within the caution range
  EXPECT_EQ(Assess(own, hovering, kR30).level, AdvisoryLevel::kCaution);
}

TEST(Assess, WithTheDefaultsADivergingObstacleOutsideTheRadiusIsClear) {
  // The defaults (a small UAV: R = 10 m, no caution range): an obstacle 25 m ahead moving away
  // faster than the vehicle is CLEAR; the same obstacle closing at 5 m/s is AVOID (t_cpa 5 s,
  // d_cpa 0); one inside R is AVOID even while receding.
  const Obstacle diverging = MakeObstacle(8, {25, 0, 0}, {15, 0, 0});
  EXPECT_EQ(Assess(kNorthAt10, diverging, {}).level, AdvisoryLevel::kClear);
  const Obstacle closing = MakeObstacle(8, {25, 0, 0}, {5, 0, 0});
  EXPECT_THAT(Assess(kNorthAt10, closing, {}), IsEncounter(AdvisoryLevel::kAvoid, 5.0, 0.0, 1e-9));
  const Obstacle inside = MakeObstacle(8, {8, 0, 0}, {15, 0, 0});
  EXPECT_EQ(Assess(kNorthAt10, inside, {}).level, AdvisoryLevel::kAvoid);
}

TEST(Assess, AnApproachWithinTheVelocityNoiseIsNotClosing) {
  // A hovering vehicle and a just-confirmed track 14 m out whose first velocity estimate drifts
  // towards the vehicle at 0.85 m/s, crossing inside R (the departing scene's first frames): with a
  // range-rate sigma of 1 m/s that is noise, so CLEAR; measured to 0.1 m/s it is a real approach.
  const OwnVehicle hover{{0, 0, 0}, {0, 0, 0}};
  Obstacle young = MakeObstacle(2, {10, 10, 0}, {-1.0, -0.2, 0});
  young.range_rate_sigma_mps = 1.0;
  EXPECT_EQ(Assess(hover, young, {}).level, AdvisoryLevel::kClear);
  young.range_rate_sigma_mps = 0.1;
  EXPECT_EQ(Assess(hover, young, {}).level, AdvisoryLevel::kAvoid);
  // A track with a handful of detections is not extrapolated, whatever its sigma says; from
  // min_hits_to_extrapolate on it is.
  young.hits = 3;
  EXPECT_EQ(Assess(hover, young, {}).level, AdvisoryLevel::kClear);
  young.hits = AvoidOptions().min_hits_to_extrapolate;
  EXPECT_EQ(Assess(hover, young, {}).level, AdvisoryLevel::kAvoid);
  // Noise and youth never hide an obstacle already inside R.
  young.hits = 1;
  young.position_m = {5, 5, 0};
  young.range_rate_sigma_mps = 1.0;
  EXPECT_EQ(Assess(hover, young, {}).level, AdvisoryLevel::kAvoid);
}

TEST(Assess, ObstacleBehindAndRecedingIsClear) {
  // 150 m behind, following at 5 m/s while the vehicle makes 10 m/s.
  const Encounter e = Assess(kNorthAt10, MakeObstacle(6, {-150, 0, 0}, {5, 0, 0}), kR30);
  EXPECT_THAT(e, IsEncounter(AdvisoryLevel::kClear, 0.0, 150.0, 1e-9));
  EXPECT_DOUBLE_EQ(e.bearing_deg, 180);
  // The proximity rule alone makes it CAUTION when the caution range reaches it.
  AvoidOptions wide;
  wide.caution_range_m = 200;
  EXPECT_EQ(Assess(kNorthAt10, MakeObstacle(6, {-150, 0, 0}, {5, 0, 0}), wide).level,
            AdvisoryLevel::kCaution);
  // Already inside the protected radius and receding: still AVOID, the separation is lost now.
  EXPECT_THAT(Assess(kNorthAt10, MakeObstacle(6, {-20, 0, 0}, {5, 0, 0}), kR30),
              IsEncounter(AdvisoryLevel::kAvoid, 0.0, 20.0, 1e-9));
}

TEST(Assess, NoRelativeMotionKeepsTheDistance) {
  // Formation flight: same velocity, 25 m to the right. No approach, but inside the radius.
  const Encounter e = Assess(kNorthAt10, MakeObstacle(7, {0, 25, 0}, {10, 0, 0}), kR30);
  EXPECT_THAT(e, IsEncounter(AdvisoryLevel::kAvoid, 0.0, 25.0, 0));
  EXPECT_THAT(Assess(kNorthAt10, MakeObstacle(7, {0, 500, 0}, {10, 0, 0}), kR30),
              IsEncounter(AdvisoryLevel::kClear, 0.0, 500.0, 0));
}

TEST(Assess, BearingIsClockwiseFromNorthInZeroTo360) {
  const OwnVehicle own{{100, -50, 0}, {0, 0, 0}};
  auto bearing = [&](double dn, double de) {
    return Assess(own, MakeObstacle(1, {100 + dn, -50 + de, 0}, {}), kR30).bearing_deg;
  };
  EXPECT_DOUBLE_EQ(bearing(10, 0), 0);
  EXPECT_DOUBLE_EQ(bearing(10, 10), 45);
  EXPECT_DOUBLE_EQ(bearing(0, 10), 90);
  EXPECT_DOUBLE_EQ(bearing(-10, 0), 180);
  EXPECT_DOUBLE_EQ(bearing(0, -10), 270);
  EXPECT_DOUBLE_EQ(bearing(10, -10), 315);
  EXPECT_DOUBLE_EQ(bearing(0, 0), 0) << "straight above or below";
  // Just west of north: -tiny + 360 rounds to 360, which must come back as 0.
  EXPECT_EQ(Assess(OwnVehicle{}, MakeObstacle(1, {10, -1e-300, 0}, {}), kR30).bearing_deg, 0);
}

TEST(AssessFrame, TheWorstOfSeveralWins) {
  const std::vector<Obstacle> obstacles = {
      MakeObstacle(10, {1000, 0, 0}, {-10, 0, 0}),   // CAUTION: 50 s
      MakeObstacle(11, {200, 0, 0}, {-10, 0, 0}),    // AVOID: 10 s
      MakeObstacle(12, {150, -100, 0}, {0, 10, 0}),  // WARNING: 12.5 s, 35 m
      MakeObstacle(13, {0, 300, 0}, {0, 10, 0}),     // CLEAR
  };
  const Advisory a = AssessFrame(7, kNorthAt10, obstacles, kR30);
  EXPECT_EQ(a.t_ns, 7);
  EXPECT_EQ(a.level, AdvisoryLevel::kAvoid);
  ASSERT_TRUE(a.worst.has_value());
  EXPECT_EQ(a.worst->track_id, 11u);
  EXPECT_THAT(*a.worst, IsEncounter(AdvisoryLevel::kAvoid, 10.0, 0.0, 1e-9));
  EXPECT_TRUE(a.reason.empty());
  EXPECT_EQ(a.invalid_obstacles, 0);

  // Without the AVOID one the WARNING wins, whatever the order.
  const std::vector<Obstacle> rest = {obstacles[3], obstacles[2], obstacles[0]};
  const Advisory b = AssessFrame(7, kNorthAt10, rest, kR30);
  EXPECT_EQ(b.level, AdvisoryLevel::kWarning);
  ASSERT_TRUE(b.worst.has_value());
  EXPECT_EQ(b.worst->track_id, 12u);

  // Two at the same level: the sooner closest approach wins (8 s against 10 s).
  const std::vector<Obstacle> two_avoid = {obstacles[1],
                                           MakeObstacle(14, {160, 5, 0}, {-10, 0, 0})};
  const Advisory c = AssessFrame(7, kNorthAt10, two_avoid, kR30);
  ASSERT_TRUE(c.worst.has_value());
  EXPECT_EQ(c.worst->track_id, 14u);
  EXPECT_NEAR(c.worst->t_cpa_s, 8, 1e-9);
}

TEST(AssessFrame, ClearWithoutObstacleFields) {
  const Advisory empty = AssessFrame(1, kNorthAt10, {}, kR30);
  EXPECT_EQ(empty.level, AdvisoryLevel::kClear);
  EXPECT_FALSE(empty.worst.has_value());
  const Advisory far = AssessFrame(1, kNorthAt10, {MakeObstacle(1, {0, 300, 0}, {0, 10, 0})}, kR30);
  EXPECT_EQ(far.level, AdvisoryLevel::kClear);
  EXPECT_FALSE(far.worst.has_value());
}

TEST(AssessFrame, TentativeTracksAreIgnoredUnlessAsked) {
  Obstacle head_on = MakeObstacle(20, {200, 0, 0}, {-10, 0, 0});
  head_on.state = ObstacleState::kTentative;
  EXPECT_EQ(AssessFrame(1, kNorthAt10, {head_on}, kR30).level, AdvisoryLevel::kClear);
  AvoidOptions all;
  all.ignore_tentative = false;
  EXPECT_EQ(AssessFrame(1, kNorthAt10, {head_on}, all).level, AdvisoryLevel::kAvoid);
  // A coasting (occluded) track is still an obstacle.
  head_on.state = ObstacleState::kCoasting;
  EXPECT_EQ(AssessFrame(1, kNorthAt10, {head_on}, kR30).level, AdvisoryLevel::kAvoid);
  // Below the minimum score it is ignored.
  head_on.score = 0.2;
  AvoidOptions picky;
  picky.min_score = 0.5;
  EXPECT_EQ(AssessFrame(1, kNorthAt10, {head_on}, picky).level, AdvisoryLevel::kClear);
}

TEST(AssessFrame, NonFiniteInputsAreNeverClear) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  // A vehicle state that cannot be used: NO_DATA, not CLEAR.
  const OwnVehicle lost{{0, 0, 0}, {nan, 0, 0}};
  const Advisory a = AssessFrame(3, lost, {MakeObstacle(1, {200, 0, 0}, {})}, kR30);
  EXPECT_EQ(a.level, AdvisoryLevel::kNoData);
  EXPECT_EQ(a.reason, "vehicle state not finite");
  // Obstacles that cannot be assessed are counted, the others still assessed.
  Obstacle bad_sigma = MakeObstacle(2, {200, 0, 0}, {-10, 0, 0});
  bad_sigma.sigma_vertical_m = -1;
  Obstacle bad_rate_sigma = MakeObstacle(6, {200, 0, 0}, {-10, 0, 0});
  bad_rate_sigma.range_rate_sigma_mps = nan;
  const std::vector<Obstacle> obstacles = {
      MakeObstacle(1, {nan, 0, 0}, {}),          bad_rate_sigma,
      MakeObstacle(3, {0, 0, 0}, {inf, 0, 0}),   bad_sigma,
      MakeObstacle(4, {500, 0, 0}, {-10, 0, 0}), MakeObstacle(5, {1e300, 1e300, 0}, {0, 0, 0})};
  const Advisory b = AssessFrame(3, kNorthAt10, obstacles, kR30);
  EXPECT_EQ(b.invalid_obstacles, 5) << "4 non-finite or negative inputs and 1 overflowing";
  EXPECT_EQ(b.level, AdvisoryLevel::kWarning);
  ASSERT_TRUE(b.worst.has_value());
  EXPECT_EQ(b.worst->track_id, 4u);
}

TEST(AvoidOptions, DefaultsAreValidAndValidateNamesEveryBadField) {
  EXPECT_THAT(AvoidOptions{}.Validate(), IsEmpty());
  EXPECT_THAT(AdvisorOptions{}.Validate(), IsEmpty());
  AvoidOptions bad;
  bad.protected_radius_m = 0;
  bad.sigma_factor = -1;
  bad.avoid_time_s = std::numeric_limits<double>::quiet_NaN();
  bad.warning_time_s = 20;
  bad.caution_time_s = 10;  // below warning_time_s
  bad.warning_radius_factor = 0.5;
  bad.caution_radius_factor = 0.4;
  bad.caution_range_m = -5;
  bad.min_score = 2;
  const std::vector<std::string> problems = bad.Validate();
  EXPECT_THAT(problems, ElementsAre(HasSubstr("protected_radius_m"), HasSubstr("sigma_factor"),
                                    HasSubstr("avoid_time_s"), HasSubstr("warning_time_s"),
                                    HasSubstr("caution_time_s"), HasSubstr("warning_radius_factor"),
                                    AllOf(HasSubstr("caution_radius_factor"), HasSubstr("0.4")),
                                    HasSubstr("caution_range_m"), HasSubstr("min_score")));
  AvoidOptions order;
  order.warning_time_s = 10;  // below avoid_time_s = 15
  EXPECT_THAT(order.Validate(), ElementsAre(HasSubstr("warning_time_s: must be >= avoid_time_s")));

  AdvisorOptions advisor;
  advisor.avoid.protected_radius_m = -1;
  advisor.no_data_after_ns = 0;
  EXPECT_THAT(advisor.Validate(),
              ElementsAre(HasSubstr("avoid.protected_radius_m"), HasSubstr("no_data_after_ns")));
  EXPECT_THROW(Advisor{advisor}, std::invalid_argument);
}

TEST(Advisor, NoDataBeforeTheFirstFrame) {
  const Advisor advisor;
  for (std::int64_t t : {std::int64_t{0}, 100 * kMs, 10'000 * kMs}) {
    const Advisory a = advisor.OnTick(t);
    EXPECT_EQ(a.level, AdvisoryLevel::kNoData);
    EXPECT_EQ(a.t_ns, t);
    EXPECT_EQ(a.reason, "no frame yet");
  }
}

TEST(Advisor, WatchdogSaysNoDataAfter500MsAndNeverClearWhileStale) {
  Advisor advisor;
  const std::int64_t t0 = 1'000'000 * kMs;
  const Advisory clear = advisor.OnFrame(t0, kNorthAt10, {});
  EXPECT_EQ(clear.level, AdvisoryLevel::kClear);
  EXPECT_EQ(advisor.OnTick(t0 + 100 * kMs).level, AdvisoryLevel::kClear);
  EXPECT_EQ(advisor.OnTick(t0 + 500 * kMs).level, AdvisoryLevel::kClear) << "500 ms is not late";
  const Advisory stale = advisor.OnTick(t0 + 501 * kMs);
  EXPECT_EQ(stale.level, AdvisoryLevel::kNoData);
  EXPECT_EQ(stale.t_ns, t0 + 501 * kMs);
  EXPECT_EQ(stale.reason, "no frame for 501 ms");
  EXPECT_FALSE(stale.worst.has_value());
  // Every tick of the next 10 s, one per millisecond: never CLEAR once the frame is older than
  // 500 ms, and always CLEAR before.
  int clear_ticks = 0;
  for (std::int64_t t = t0; t <= t0 + 10'000 * kMs; t += kMs) {
    const AdvisoryLevel level = advisor.OnTick(t).level;
    if (t - t0 > 500 * kMs) {
      ASSERT_EQ(level, AdvisoryLevel::kNoData) << "at " << (t - t0) / kMs << " ms";
    } else {
      ASSERT_EQ(level, AdvisoryLevel::kClear) << "at " << (t - t0) / kMs << " ms";
      ++clear_ticks;
    }
  }
  EXPECT_EQ(clear_ticks, 501);

  // A new frame makes it fresh again, and the ticks repeat its advisory.
  const std::int64_t t1 = t0 + 20'000 * kMs;
  const Advisory avoid =
      advisor.OnFrame(t1, kNorthAt10, {MakeObstacle(8, {200, 0, 0}, {-10, 0, 0})});
  EXPECT_EQ(avoid.level, AdvisoryLevel::kAvoid);
  const Advisory tick = advisor.OnTick(t1 + 300 * kMs);
  EXPECT_EQ(tick.level, AdvisoryLevel::kAvoid);
  ASSERT_TRUE(tick.worst.has_value());
  EXPECT_EQ(tick.worst->track_id, 8u);
  EXPECT_EQ(tick.t_ns, t1) << "the advisory of the frame at t1";
  EXPECT_EQ(advisor.OnTick(t1 + 501 * kMs).level, AdvisoryLevel::kNoData);
  // A clock that goes back before the last frame is a fault, not fresh data.
  EXPECT_EQ(advisor.OnTick(t1 - kMs).level, AdvisoryLevel::kNoData);
}

TEST(Advisor, TimeoutIsConfigurable) {
  AdvisorOptions options;
  options.no_data_after_ns = 2000 * kMs;
  Advisor advisor(options);
  advisor.OnFrame(0, kNorthAt10, {});
  EXPECT_EQ(advisor.OnTick(2000 * kMs).level, AdvisoryLevel::kClear);
  EXPECT_EQ(advisor.OnTick(2001 * kMs).level, AdvisoryLevel::kNoData);
}

TEST(AdvisoryJson, ExactLinesForEachKind) {
  Advisory warning;
  warning.t_ns = 1234567890123;
  warning.level = AdvisoryLevel::kWarning;
  warning.worst = Encounter{.track_id = 42,
                            .bearing_deg = 326.30993247402023,
                            .distance_m = 180.27756377319946,
                            .t_cpa_s = 12.5,
                            .d_cpa_m = 35.35533905932738,
                            .protected_radius_m = 30,
                            .level = AdvisoryLevel::kWarning};
  EXPECT_EQ(AdvisoryJson(warning),
            R"({"t_ns":1234567890123,"level":"WARNING","track_id":42,"bearing_deg":326.3,)"
            R"("distance_m":180.28,"t_cpa_s":12.50,"d_cpa_m":35.36})");

  Advisory clear;
  clear.t_ns = 5;
  clear.level = AdvisoryLevel::kClear;
  EXPECT_EQ(AdvisoryJson(clear), R"({"t_ns":5,"level":"CLEAR"})");

  Advisory no_data;
  no_data.t_ns = -3;
  no_data.reason = "no frame for 612 ms";
  EXPECT_EQ(AdvisoryJson(no_data),
            R"({"t_ns":-3,"level":"NO_DATA","reason":"no frame for 612 ms"})");

  // A bearing that rounds up to 360 is written as 0; a negative zero without its sign.
  Advisory north = warning;
  north.invalid_obstacles = 2;
  north.worst->bearing_deg = 359.96;
  north.worst->d_cpa_m = -0.0;
  EXPECT_EQ(AdvisoryJson(north),
            R"({"t_ns":1234567890123,"level":"WARNING","track_id":42,"bearing_deg":0.0,)"
            R"("distance_m":180.28,"t_cpa_s":12.50,"d_cpa_m":0.00,"invalid_obstacles":2})");
}

TEST(AdvisoryJson, ParsesAsJsonWithEscapedStrings) {
  Advisory no_data;
  no_data.t_ns = 1;
  no_data.reason = "quote \" backslash \\ newline \n tab \t bell \x07 end";
  const std::string line = AdvisoryJson(no_data);
  EXPECT_EQ(line.find('\n'), std::string::npos) << "one line";
  std::string error;
  const std::optional<Json> json = JsonParser::Parse(line, &error);
  ASSERT_TRUE(json.has_value()) << error << " in " << line;
  EXPECT_THAT(json->Keys(), ElementsAre("t_ns", "level", "reason"));
  EXPECT_EQ(json->Find("reason")->string, no_data.reason) << "the escapes decode to the input";

  // A real frame's advisory, end to end.
  Advisor advisor;
  const Advisory avoid = advisor.OnFrame(
      77, kNorthAt10,
      {MakeObstacle(9, {150, -100, 0}, {0, 10, 0}), MakeObstacle(8, {200, 0, 0}, {-10, 0, 0})});
  const std::optional<Json> parsed = JsonParser::Parse(AdvisoryJson(avoid), &error);
  ASSERT_TRUE(parsed.has_value()) << error;
  EXPECT_THAT(parsed->Keys(), ElementsAre("t_ns", "level", "track_id", "bearing_deg", "distance_m",
                                          "t_cpa_s", "d_cpa_m"));
  EXPECT_EQ(parsed->Find("level")->string, "AVOID");
  EXPECT_EQ(parsed->Find("track_id")->number, 8);
  EXPECT_EQ(parsed->Find("t_cpa_s")->number, 10);
  EXPECT_EQ(parsed->Find("distance_m")->number, 200);
  // The NO_DATA of the watchdog as well.
  const std::optional<Json> stale = JsonParser::Parse(AdvisoryJson(advisor.OnTick(77 + kMs * 600)));
  ASSERT_TRUE(stale.has_value());
  EXPECT_EQ(stale->Find("level")->string, "NO_DATA");
  EXPECT_EQ(stale->Find("track_id"), nullptr);
}

TEST(AdvisoryJson, NonFiniteNumbersBecomeNull) {
  Advisory a;
  a.level = AdvisoryLevel::kAvoid;
  a.worst = Encounter{};
  a.worst->t_cpa_s = std::numeric_limits<double>::infinity();
  const std::string line = AdvisoryJson(a);
  EXPECT_THAT(line, HasSubstr("\"t_cpa_s\":null"));
  EXPECT_TRUE(JsonParser::Parse(line).has_value()) << line;
}

}  // namespace
}  // namespace stevi::client
