// The bridge's logic on hand-made frames and messages: sectors from a range scan and tracks, ADS-B
// reports from tracks, and the autopilot's messages joined into VehicleStates.
#include "client/mavlink/translate.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace stevi::client::mavlink {
namespace {

constexpr uint16_t kUnknown = 0xFFFF;

// A frame whose scan covers [start, start + n w) with every bin clear (0), min 6.67 m, max 210 m.
v1::TrackFrame ScanFrame(double start_deg, double width_deg, int bins) {
  v1::TrackFrame f;
  f.set_capture_unix_time_ns(1'700'000'000'123'456'789);
  v1::RangeScan* scan = f.mutable_range_scan();
  scan->set_start_azimuth_deg(start_deg);
  scan->set_bin_width_deg(width_deg);
  for (int i = 0; i < bins; ++i) scan->add_range_m(0);
  scan->set_min_range_m(6.666);
  scan->set_max_range_m(210.0);
  return f;
}

ObstacleDistance Distances(const v1::TrackFrame& f) {
  std::string why;
  const std::optional<ObstacleDistance> m = ObstacleDistanceOf(f, why);
  EXPECT_TRUE(m.has_value()) << why;
  return m.value_or(ObstacleDistance{});
}

TEST(ObstacleDistanceOf, AFieldOfViewIsClearInsideAndUnknownOutside) {
  // A 50-degree view centred ahead: bins [-24.5, 25.5) of 1 degree, centred on whole degrees.
  const ObstacleDistance m = Distances(ScanFrame(-24.5, 1.0, 50));
  EXPECT_EQ(m.frame, kMavFrameBodyFrd);
  EXPECT_EQ(m.increment_f, 5.0f);
  EXPECT_EQ(m.increment, 5);
  EXPECT_EQ(m.angle_offset, 0.0f);
  EXPECT_EQ(m.min_distance, 667);  // rounded up: never claims to see nearer than it can
  EXPECT_EQ(m.max_distance, 21000);
  EXPECT_EQ(m.time_usec, 1'700'000'000'123'456u);
  EXPECT_EQ(m.sensor_type, kMavDistanceSensorUnknown);
  // Sectors 68..71 and 0..5 (-20..25 degrees, centred on multiples of 5) are seen; of the edge
  // sectors, +25 (22.5..27.5) is 3 degrees in view, so seen, and -25 (-27.5..-22.5) only 2, so
  // unknown. The rest is unknown.
  for (int s = 0; s < kSectors; ++s) {
    const bool seen = s <= 5 || s >= 68;
    EXPECT_EQ(m.distances[static_cast<size_t>(s)], seen ? 21001 : kUnknown) << "sector " << s;
  }
}

TEST(ObstacleDistanceOf, AReturnGoesToTheSectorOfItsBinsCentre) {
  v1::TrackFrame f = ScanFrame(-24.5, 1.0, 50);
  // Bin 12 is centred on -12 degrees: sector 70 (-12.5..-7.5), not sector 69.
  f.mutable_range_scan()->set_range_m(12, 20.25f);
  // Bin 30 (+6 degrees): sector 1; nearer than min: sent as min, never 0.
  f.mutable_range_scan()->set_range_m(30, 2.0f);
  // Bin 45 (+21 degrees): beyond max, so clear.
  f.mutable_range_scan()->set_range_m(45, 500.0f);
  const ObstacleDistance m = Distances(f);
  EXPECT_EQ(m.distances[70], 2025);
  EXPECT_EQ(m.distances[69], 21001);
  EXPECT_EQ(m.distances[1], 667);
  EXPECT_EQ(m.distances[4], 21001);
}

TEST(ObstacleDistanceOf, TracksShortenTheSectorOfTheirBearing) {
  v1::TrackFrame f = ScanFrame(-24.5, 1.0, 50);
  f.mutable_range_scan()->set_range_m(25, 30.0f);  // 0 degrees, 30 m
  const auto add_track = [&f](v1::TrackState state, double x, double y) {
    v1::Track* t = f.add_tracks();
    t->set_state(state);
    t->mutable_position_body()->set_x_m(x);
    t->mutable_position_body()->set_y_m(y);
    t->mutable_position_body()->set_z_m(-5);  // above: the range is horizontal
  };
  add_track(v1::TRACK_STATE_CONFIRMED, 20, 0);  // ahead, nearer than the scan
  add_track(v1::TRACK_STATE_COASTING, 10 * std::cos(0.7854), 10 * std::sin(0.7854));  // 45 deg
  add_track(v1::TRACK_STATE_TENTATIVE, 5, -5);    // not yet a track: ignored
  add_track(v1::TRACK_STATE_CONFIRMED, 0, -300);  // beyond max: ignored
  const ObstacleDistance m = Distances(f);
  EXPECT_EQ(m.distances[0], 2000);
  EXPECT_EQ(m.distances[9], 1000) << "a coasting track outside the view still counts";
  EXPECT_EQ(m.distances[63], kUnknown);
  EXPECT_EQ(m.distances[54], kUnknown);
}

TEST(ObstacleDistanceOf, NoScanNoMessage) {
  v1::TrackFrame f;
  std::string why;
  EXPECT_FALSE(ObstacleDistanceOf(f, why).has_value());
  EXPECT_NE(why.find("range_scan"), std::string::npos) << why;
}

TEST(ObstacleDistanceOf, AScanAcrossTheBackWrapsAround) {
  // A camera looking backwards: bins [170.5, 190.5) of 1 degree.
  const ObstacleDistance m = Distances(ScanFrame(170.5, 1.0, 20));
  EXPECT_EQ(m.distances[36], 21001);  // 180
  EXPECT_EQ(m.distances[35], 21001);  // 175
  EXPECT_EQ(m.distances[37], 21001);  // 185
  EXPECT_EQ(m.distances[0], kUnknown);
}

TEST(Sectors, BearingsAndSectorsFollowFrd) {
  v1::PointBody right;
  right.set_y_m(10);
  EXPECT_DOUBLE_EQ(BodyBearingDeg(right), 90.0);
  v1::PointBody left_back;
  left_back.set_x_m(-1);
  left_back.set_y_m(-1);
  EXPECT_DOUBLE_EQ(BodyBearingDeg(left_back), 225.0);
  EXPECT_DOUBLE_EQ(BodyHorizontalRangeM(left_back), std::sqrt(2.0));
  EXPECT_EQ(SectorOf(0), 0);
  EXPECT_EQ(SectorOf(2.49), 0);
  EXPECT_EQ(SectorOf(2.51), 1);
  EXPECT_EQ(SectorOf(357.6), 0);
  EXPECT_EQ(SectorOf(-10), 70);
}

TEST(LimitsOf, KeepsMaxPlusOneBelowUnknown) {
  v1::RangeScan scan;
  scan.set_min_range_m(0.5);
  scan.set_max_range_m(5000);
  const SectorLimits limits = LimitsOf(scan);
  EXPECT_EQ(limits.max_cm, 65533);
  EXPECT_EQ(limits.min_cm, 50);
}

v1::TrackFrame GeoFrame() {
  v1::TrackFrame f;
  f.set_geo_status(v1::GEO_STATUS_OK);
  f.set_capture_time_ns(10'000'000'000);
  return f;
}

v1::Track* AddGeoTrack(v1::TrackFrame& f, uint64_t id, v1::TrackState state) {
  v1::Track* t = f.add_tracks();
  t->set_track_id(id);
  t->set_state(state);
  t->mutable_geodetic()->set_lat_deg(43.6839123);
  t->mutable_geodetic()->set_lon_deg(10.3925456);
  t->mutable_geodetic()->set_alt_m(136.789);
  t->mutable_velocity_ned()->set_n_mps(-3);
  t->mutable_velocity_ned()->set_e_mps(3);
  t->mutable_velocity_ned()->set_d_mps(-1.5);
  return t;
}

TEST(AdsbTracks, OneReportPerHeldTrackWithItsPositionCourseAndSpeeds) {
  AdsbTracks adsb({.icao_base = 0xF00000, .geoid_undulation_m = 47.5, .simulated = true});
  v1::TrackFrame f = GeoFrame();
  AddGeoTrack(f, 42, v1::TRACK_STATE_CONFIRMED);
  AddGeoTrack(f, 43, v1::TRACK_STATE_TENTATIVE);
  const std::vector<AdsbVehicle> reports = adsb.Of(f);
  ASSERT_EQ(reports.size(), 1u);
  const AdsbVehicle& a = reports[0];
  EXPECT_EQ(a.icao_address, 0xF0002Au);
  EXPECT_EQ(std::string(a.callsign.data()), "STV00016");  // 42 in base 36
  EXPECT_EQ(a.lat, 436839123);
  EXPECT_EQ(a.lon, 103925456);
  EXPECT_EQ(a.altitude, 89289);  // (136.789 - 47.5) m above MSL, in mm
  EXPECT_EQ(a.altitude_type, kAdsbAltitudeTypeGeometric);
  EXPECT_EQ(a.heading, 13500);  // north-west... south-east: n -3, e +3 is 135 degrees
  EXPECT_EQ(a.hor_velocity, 424);
  EXPECT_EQ(a.ver_velocity, 150);  // climbing: d is down
  EXPECT_EQ(a.tslc, 0);
  EXPECT_EQ(a.flags, kAdsbFlagsValidCoords | kAdsbFlagsValidAltitude | kAdsbFlagsValidHeading |
                         kAdsbFlagsValidVelocity | kAdsbFlagsValidCallsign |
                         kAdsbFlagsVerticalVelocityValid | kAdsbFlagsSimulated);
}

TEST(AdsbTracks, ACoastingTrackCountsTheTimeSinceItsLastDetection) {
  AdsbTracks adsb({});
  v1::TrackFrame f = GeoFrame();
  AddGeoTrack(f, 7, v1::TRACK_STATE_CONFIRMED);
  ASSERT_EQ(adsb.Of(f).size(), 1u);
  v1::TrackFrame later = GeoFrame();
  later.set_capture_time_ns(f.capture_time_ns() + 2'600'000'000);
  AddGeoTrack(later, 7, v1::TRACK_STATE_COASTING)->mutable_velocity_ned()->set_e_mps(0.1);
  later.mutable_tracks(0)->mutable_velocity_ned()->set_n_mps(0.1);
  const std::vector<AdsbVehicle> reports = adsb.Of(later);
  ASSERT_EQ(reports.size(), 1u);
  EXPECT_EQ(reports[0].tslc, 2);
  EXPECT_EQ(reports[0].flags & kAdsbFlagsValidHeading, 0) << "too slow for a course";
  EXPECT_EQ(reports[0].flags & kAdsbFlagsValidAltitude, 0) << "no geoid undulation known";
  EXPECT_EQ(reports[0].flags & kAdsbFlagsSimulated, 0);
  v1::TrackFrame stale = later;
  stale.set_geo_status(v1::GEO_STATUS_POSE_TOO_OLD);
  EXPECT_TRUE(adsb.Of(stale).empty()) << "no report without a georeferenced frame";
}

TEST(Callsigns, StableAndWithinEightCharacters) {
  EXPECT_EQ(std::string(CallsignOf(0).data()), "STV00000");
  EXPECT_EQ(std::string(CallsignOf(36).data()), "STV00010");
  EXPECT_EQ(std::string(CallsignOf(60466175).data()), "STVZZZZZ");
  EXPECT_EQ(std::string(CallsignOf(60466176).data()), "STV00000");  // wraps
  EXPECT_EQ(IcaoAddressOf(1, 0xF00000), 0xF00001u);
  EXPECT_EQ(IcaoAddressOf((1u << 20) + 5, 0xF00000), 0xF00005u);
}

Frame FrameOf(uint32_t id, std::vector<uint8_t> payload) {
  Frame f;
  f.system_id = 1;
  f.component_id = 1;
  f.message_id = id;
  f.payload = std::move(payload);
  f.payload.resize(FindMessage(id)->max_length);
  return f;
}

template <class T>
Frame FrameOf(const T& m) {
  return FrameOf(T::kId, Pack(m));
}

GlobalPositionInt Position(uint32_t boot_ms) {
  GlobalPositionInt p;
  p.time_boot_ms = boot_ms;
  p.lat = 436839000;
  p.lon = 103925000;
  p.alt = 41'500;  // mm above MSL
  p.vx = 120;
  p.vy = -40;
  p.vz = 10;
  return p;
}

// Found by tests/fuzz/mavlink (regression-geoid-overflow, regression-unix-time-overflow): heights
// 2^31 mm apart overflowed the undulation's int subtraction, a SYSTEM_TIME near 2^63 us the
// boot-to-Unix offset. An impossible undulation, a non-finite attitude and a position
// outside the Earth are each dropped, named, and change nothing.
TEST(PoseJoiner, DropsImpossibleMessagesAndKeepsTheLastGoodState) {
  PoseJoiner joiner({.geoid_undulation_m = 40.0});
  const int64_t host = 1'800'000'000'000'000'000;
  GpsRawInt g;
  g.fix_type = kGpsFixType3dFix;
  g.alt = -2'097'152'000;
  g.alt_ellipsoid = 185'207'048;
  joiner.OnMessage(FrameOf(g), host);
  EXPECT_EQ(joiner.geoid_undulation_m(), 40.0) << "a 2287 km undulation is no geoid";
  Attitude a;
  a.time_boot_ms = 1000;
  a.roll = 0.1f;
  joiner.OnMessage(FrameOf(a), host);
  Attitude bad = a;
  bad.time_boot_ms = 1005;
  bad.pitch = std::numeric_limits<float>::quiet_NaN();
  joiner.OnMessage(FrameOf(bad), host);
  EXPECT_NE(joiner.rejected().find("ATTITUDE with a non-finite angle"), std::string::npos)
      << joiner.rejected();
  SystemTime far_future;  // found by the fuzzer: 2^63 us overflowed the boot-to-Unix offset
  far_future.time_unix_usec = 0x8000'0001'E000'0000ULL;
  far_future.time_boot_ms = 531'085'119;
  joiner.OnMessage(FrameOf(far_future), host);
  EXPECT_STREQ(joiner.time_source(), "host");
  GlobalPositionInt outside = Position(1010);
  outside.lat = 950'000'000;
  EXPECT_FALSE(joiner.OnMessage(FrameOf(outside), host));
  EXPECT_NE(joiner.rejected().find("outside the Earth"), std::string::npos) << joiner.rejected();
  const std::optional<v1::VehicleState> s = joiner.OnMessage(FrameOf(Position(1010)), host);
  ASSERT_TRUE(s.has_value()) << joiner.waiting();
  EXPECT_NEAR(s->roll_deg(), 0.1 * 180.0 / 3.14159265358979323846, 1e-4);
  EXPECT_EQ(s->pitch_deg(), 0.0) << "the NaN attitude did not replace the good one";
}

TEST(PoseJoiner, JoinsPositionAttitudeEllipsoidHeightAndUnixTime) {
  PoseJoiner joiner({});
  const int64_t host = 1'800'000'000'000'000'000;
  EXPECT_FALSE(joiner.OnMessage(FrameOf(Position(1000)), host));
  EXPECT_NE(joiner.waiting().find("attitude"), std::string::npos) << joiner.waiting();
  Attitude a;
  a.time_boot_ms = 1000;
  a.roll = 0.1f;
  a.pitch = -0.05f;
  a.yaw = -1.0f;
  EXPECT_FALSE(joiner.OnMessage(FrameOf(a), host));
  EXPECT_FALSE(joiner.OnMessage(FrameOf(Position(1010)), host));
  EXPECT_NE(joiner.waiting().find("--geoid-undulation"), std::string::npos) << joiner.waiting();
  GpsRawInt g;
  g.fix_type = kGpsFixType3dFix;
  g.alt = 41'500;
  g.alt_ellipsoid = 89'000;
  g.h_acc = 350;
  g.v_acc = 600;
  EXPECT_FALSE(joiner.OnMessage(FrameOf(g), host));
  EXPECT_EQ(joiner.geoid_undulation_m(), 47.5);
  EXPECT_STREQ(joiner.time_source(), "host");
  std::optional<v1::VehicleState> s = joiner.OnMessage(FrameOf(Position(1020)), host);
  ASSERT_TRUE(s.has_value()) << joiner.waiting();
  EXPECT_EQ(s->unix_time_ns(), host) << "no SYSTEM_TIME yet: the arrival time";
  SystemTime t;
  t.time_unix_usec = 1'700'000'000'000'000;
  t.time_boot_ms = 1000;
  joiner.OnMessage(FrameOf(t), host);
  EXPECT_STREQ(joiner.time_source(), "autopilot");
  s = joiner.OnMessage(FrameOf(Position(1030)), host);
  ASSERT_TRUE(s.has_value());
  EXPECT_EQ(s->unix_time_ns(), 1'700'000'000'030'000'000) << "SYSTEM_TIME + 30 ms of boot time";
  EXPECT_DOUBLE_EQ(s->position().lat_deg(), 43.6839);
  EXPECT_DOUBLE_EQ(s->position().lon_deg(), 10.3925);
  EXPECT_DOUBLE_EQ(s->position().alt_m(), 89.0) << "MSL + the GPS's undulation";
  EXPECT_NEAR(s->roll_deg(), 0.1 * 180 / M_PI, 1e-5);
  EXPECT_NEAR(s->pitch_deg(), -0.05 * 180 / M_PI, 1e-5);
  EXPECT_NEAR(s->yaw_deg(), -1.0 * 180 / M_PI, 1e-5);
  EXPECT_DOUBLE_EQ(s->velocity().n_mps(), 1.2);
  EXPECT_DOUBLE_EQ(s->velocity().e_mps(), -0.4);
  EXPECT_DOUBLE_EQ(s->velocity().d_mps(), 0.1);
  EXPECT_DOUBLE_EQ(s->position_sigma_horizontal_m(), 0.35);
  EXPECT_DOUBLE_EQ(s->position_sigma_vertical_m(), 0.6);
  EXPECT_TRUE(joiner.waiting().empty());
  // An attitude more than 500 ms older than the position does not join it.
  EXPECT_FALSE(joiner.OnMessage(FrameOf(Position(1600)), host));
}

TEST(PoseJoiner, UsesTheGivenUndulationWithoutAnEllipsoidHeightAndRefusesNoFix) {
  PoseJoiner joiner({.geoid_undulation_m = 40.0});
  AttitudeQuaternion q;  // a yaw of 90 degrees: w = cos 45, z = sin 45
  q.q1 = static_cast<float>(std::sqrt(0.5));
  q.q4 = static_cast<float>(std::sqrt(0.5));
  q.time_boot_ms = 500;
  joiner.OnMessage(FrameOf(q), 0);
  std::optional<v1::VehicleState> s = joiner.OnMessage(FrameOf(Position(510)), 5);
  ASSERT_TRUE(s.has_value()) << joiner.waiting();
  EXPECT_DOUBLE_EQ(s->position().alt_m(), 81.5);
  EXPECT_NEAR(s->yaw_deg(), 90, 1e-4);
  EXPECT_NEAR(s->roll_deg(), 0, 1e-4);
  EXPECT_DOUBLE_EQ(s->position_sigma_horizontal_m(), 2.0) << "the default without h_acc";
  GlobalPositionInt nowhere = Position(520);
  nowhere.lat = 0;
  nowhere.lon = 0;
  EXPECT_FALSE(joiner.OnMessage(FrameOf(nowhere), 5));
  EXPECT_NE(joiner.waiting().find("no position fix"), std::string::npos);
}

TEST(EulerDegOfQuaternion, MatchesTheZyxAnglesOfAComposedRotation) {
  // roll 10, pitch 20, yaw 30 degrees: q = qz(30) qy(20) qx(10).
  const double r = 5 * M_PI / 180, p = 10 * M_PI / 180, y = 15 * M_PI / 180;  // half angles
  const double w =
      std::cos(r) * std::cos(p) * std::cos(y) + std::sin(r) * std::sin(p) * std::sin(y);
  const double x =
      std::sin(r) * std::cos(p) * std::cos(y) - std::cos(r) * std::sin(p) * std::sin(y);
  const double yy =
      std::cos(r) * std::sin(p) * std::cos(y) + std::sin(r) * std::cos(p) * std::sin(y);
  const double z =
      std::cos(r) * std::cos(p) * std::sin(y) - std::sin(r) * std::sin(p) * std::cos(y);
  const std::array<double, 3> e = EulerDegOfQuaternion(w, x, yy, z);
  EXPECT_NEAR(e[0], 10, 1e-9);
  EXPECT_NEAR(e[1], 20, 1e-9);
  EXPECT_NEAR(e[2], 30, 1e-9);
}

TEST(Heartbeats, OnlyAutopilotsAreFollowed) {
  Heartbeat px4;
  px4.type = 2;        // quadrotor
  px4.autopilot = 12;  // PX4
  EXPECT_TRUE(IsAutopilotHeartbeat(px4));
  Heartbeat gcs = px4;
  gcs.type = 6;
  EXPECT_FALSE(IsAutopilotHeartbeat(gcs));
  Heartbeat companion;
  companion.type = kMavTypeOnboardController;
  companion.autopilot = kMavAutopilotInvalid;
  EXPECT_FALSE(IsAutopilotHeartbeat(companion));
}

TEST(SetMessageInterval, AsksTheAutopilotInMicroseconds) {
  const CommandLong c = SetMessageInterval(7, 1, 33, 50'000);
  EXPECT_EQ(c.command, 511);
  EXPECT_EQ(c.target_system, 7);
  EXPECT_EQ(c.target_component, 1);
  EXPECT_EQ(c.param1, 33.0f);
  EXPECT_EQ(c.param2, 50000.0f);
  EXPECT_EQ(c.param3, 0.0f);
  EXPECT_EQ(c.param7, 0.0f);
}

}  // namespace
}  // namespace stevi::client::mavlink
