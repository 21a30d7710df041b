#include "core/geo/georeferencer.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include <Eigen/Cholesky>
#include <GeographicLib/Constants.hpp>
#include <GeographicLib/Geodesic.hpp>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/core/geo/geo_reference.h"
#include "tests/testing/status_matchers.h"

using stevi::testing::IsError;

namespace stevi::geo {
namespace {

using ref::Geodetic;
using ref::kDeg;
using ref::NormalSectionRadius;
using ref::OnOsculatingSphere;
using ref::ReferenceDcm;
using ref::ReferenceFrdFromCam;
using ref::ReferenceFromNed;
using ::testing::HasSubstr;

const double kE2 = GeographicLib::Constants::WGS84_f() * (2 - GeographicLib::Constants::WGS84_f());
constexpr double kPisaLat = 43.6839;  // Pisa airport
constexpr double kPisaLon = 10.3927;

VehicleState Level(double lat, double lon, double alt, double heading_deg) {
  return VehicleState{.lat_deg = lat, .lon_deg = lon, .alt_m = alt, .yaw_deg = heading_deg};
}

GeoPoint MustGeoreference(const Georeferencer& g, const VehicleState& state,
                          const Eigen::Vector3d& p_cam, const Eigen::Vector3d& v_cam = {0, 0, 0},
                          const Eigen::Vector3d& rate = {0, 0, 0}) {
  const Result<GeoPoint> r =
      g.Georeference(VehiclePose{.state = state, .angular_rate_body_rps = rate},
                     PointInCam{.position_m = p_cam, .velocity_mps = v_cam});
  EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().message);
  return r.ok() ? r.value() : GeoPoint{};
}

struct Inverse {
  double distance_m = 0;
  double azimuth_deg = 0;  // at the first point
};

Inverse Geodesic(double lat0, double lon0, double lat1, double lon1) {
  Inverse inv;
  double azi2 = 0;
  GeographicLib::Geodesic::WGS84().Inverse(lat0, lon0, lat1, lon1, inv.distance_m, inv.azimuth_deg,
                                           azi2);
  return inv;
}

double AngleDiffDeg(double a, double b) { return std::remainder(a - b, 360.0); }

// The brief's acceptance test: a level, forward-looking rig; the obstacle's geodesic distance
// from the rig equals the horizontal range sqrt(x^2 + z^2) and its azimuth the heading plus the
// bearing atan2(x, z). The range is measured in the tangent plane at the rig's height, the geodesic
// on the ellipsoid: the osculating sphere model accounts for the scale R / (R + h) (7.8 mm per
// 100 m at 500 m) and the curvature drop (0.78 mm at 100 m).
TEST(GeoreferenceLevel, MatchesIndependentGeodesy) {
  const Georeferencer g;
  struct Case {
    double lat, lon, alt, heading;
  };
  const std::vector<Case> rigs = {{kPisaLat, kPisaLon, 0, 0}, {kPisaLat, kPisaLon, 50, 37},
                                  {-33.9, 151.2, 500, 200},   {64.1, -21.9, 3000, -90},
                                  {0.0, 179.9995, 120, 95},   {-78.0, 166.7, 10, 311}};
  const std::vector<Eigen::Vector3d> points = {
      {0, 0, 100}, {20, -5, 80}, {-30, 10, 250}, {5, 2, 10}, {0, -40, 300}};
  double worst_distance = 0, worst_alt = 0, worst_azimuth = 0, worst_azimuth_skew = 0;
  for (const Case& rig : rigs) {
    const VehicleState state = Level(rig.lat, rig.lon, rig.alt, rig.heading);
    for (const Eigen::Vector3d& p : points) {
      const GeoPoint out = MustGeoreference(g, state, p);
      const double horizontal = std::hypot(p.x(), p.z());
      const double bearing = std::atan2(p.x(), p.z()) / kDeg;
      const Inverse inv = Geodesic(rig.lat, rig.lon, out.lat_deg, out.lon_deg);
      const double radius = NormalSectionRadius(rig.lat, rig.heading + bearing);
      const ref::SphereModel want = OnOsculatingSphere(radius, rig.alt, horizontal, -p.y());
      const std::string where = "rig " + std::to_string(rig.lat) + "," + std::to_string(rig.lon) +
                                " alt " + std::to_string(rig.alt) + " point (" +
                                std::to_string(p.x()) + ", " + std::to_string(p.y()) + ", " +
                                std::to_string(p.z()) + ")";
      EXPECT_NEAR(inv.distance_m, want.surface_distance_m, 1e-3) << where;
      // The ellipsoid's normals are skew: the obstacle's foot point leaves the rig's normal
      // section by up to e^2 h / R radians (h the larger height of the two), 1.8e-4 deg at 3 km.
      const double skew_deg = kE2 * std::max(std::abs(rig.alt), std::abs(rig.alt - p.y())) /
                              GeographicLib::Constants::WGS84_a() / kDeg;
      EXPECT_NEAR(AngleDiffDeg(inv.azimuth_deg, rig.heading + bearing), 0, 1e-7 + skew_deg)
          << where;
      EXPECT_NEAR(out.alt_m, want.alt_m, 1e-3) << where;
      worst_distance = std::max(worst_distance, std::abs(inv.distance_m - want.surface_distance_m));
      worst_alt = std::max(worst_alt, std::abs(out.alt_m - want.alt_m));
      const double azimuth_error = std::abs(AngleDiffDeg(inv.azimuth_deg, rig.heading + bearing));
      worst_azimuth = std::max(worst_azimuth, azimuth_error);
      worst_azimuth_skew = std::max(worst_azimuth_skew, azimuth_error / (1e-7 + skew_deg));
      // The curvature drop stays below the sphere's s^2 / (2 R) bound, e.g. < 1 mm at 100 m.
      const double drop = out.alt_m - (rig.alt - p.y());
      EXPECT_GE(drop, 0) << where;
      EXPECT_LE(drop, horizontal * horizontal / (2 * 6.3e6)) << where;
    }
  }
  std::printf(
      "level rig vs geodesy: worst |distance| %.3g m, |alt| %.3g m, |azimuth| %.3g deg "
      "(%.2f of its bound)\n",
      worst_distance, worst_alt, worst_azimuth, worst_azimuth_skew);
}

TEST(GeoreferenceLevel, OnTheEllipsoidDistanceIsTheHorizontalRange) {
  // At alt 0 with the obstacle at the rig's height no correction is needed: the tangent-plane
  // range and the geodesic differ by s^3 / (3 R^2) (nanometres).
  const Georeferencer g;
  const VehicleState state = Level(kPisaLat, kPisaLon, 0, 123);
  for (double z : {10.0, 100.0, 300.0}) {
    const Eigen::Vector3d p(0.3 * z, 0, z);
    const GeoPoint out = MustGeoreference(g, state, p);
    const Inverse inv = Geodesic(kPisaLat, kPisaLon, out.lat_deg, out.lon_deg);
    EXPECT_NEAR(inv.distance_m, std::hypot(p.x(), p.z()), 1e-3);
    EXPECT_NEAR(AngleDiffDeg(inv.azimuth_deg, 123 + std::atan2(0.3, 1.0) / kDeg), 0, 1e-7);
    if (z <= 100) {
      EXPECT_NEAR(out.alt_m, 0, 1e-3);  // the curvature drop is < 1 mm within ~110 m
    }
  }
}

TEST(GeoreferenceAttitude, PitchUpRaisesTheObstacle) {
  const Georeferencer g;
  VehicleState state = Level(kPisaLat, kPisaLon, 100, 0);
  state.pitch_deg = 10;
  const GeoPoint out = MustGeoreference(g, state, {0, 0, 100});
  const double up = 100 * std::sin(10 * kDeg), forward = 100 * std::cos(10 * kDeg);
  const ref::SphereModel want =
      OnOsculatingSphere(NormalSectionRadius(kPisaLat, 0), 100, forward, up);
  EXPECT_NEAR(out.alt_m, want.alt_m, 1e-3);  // 117.3648 m + 0.76 mm of curvature
  EXPECT_NEAR(out.alt_m, 100 + up, 2e-3);
  const Inverse inv = Geodesic(kPisaLat, kPisaLon, out.lat_deg, out.lon_deg);
  EXPECT_NEAR(inv.distance_m, want.surface_distance_m, 1e-3);
  EXPECT_NEAR(AngleDiffDeg(inv.azimuth_deg, 0), 0, 1e-6);
}

TEST(GeoreferenceAttitude, RollRightLowersPointsOnTheRight) {
  const Georeferencer g;
  VehicleState state = Level(kPisaLat, kPisaLon, 100, 0);
  state.roll_deg = 30;
  const GeoPoint out = MustGeoreference(g, state, {10, 0, 100});  // 10 m right of the axis
  EXPECT_NEAR(out.offset_ned_m.z(), 10 * std::sin(30 * kDeg), 1e-12);
  const double horizontal = std::hypot(100, 10 * std::cos(30 * kDeg));
  const ref::SphereModel want =
      OnOsculatingSphere(NormalSectionRadius(kPisaLat, 0), 100, horizontal, -5);
  EXPECT_NEAR(out.alt_m, want.alt_m, 1e-3);
}

TEST(GeoreferenceMount, CameraTurnedRightLooksEastWhenHeadingNorth) {
  const Georeferencer g(MountOptions{.yaw_deg = 90});
  const GeoPoint out = MustGeoreference(g, Level(kPisaLat, kPisaLon, 0, 0), {0, 0, 100});
  const Inverse inv = Geodesic(kPisaLat, kPisaLon, out.lat_deg, out.lon_deg);
  EXPECT_NEAR(AngleDiffDeg(inv.azimuth_deg, 90), 0, 1e-6);
  EXPECT_NEAR(inv.distance_m, 100, 1e-3);
  EXPECT_GT(out.lon_deg, kPisaLon);
}

TEST(GeoreferenceMount, DownLookingCameraSeesBelow) {
  const Georeferencer g(MountOptions{.pitch_deg = -90});
  const GeoPoint out = MustGeoreference(g, Level(kPisaLat, kPisaLon, 400, 70), {0, 0, 150});
  EXPECT_NEAR(out.alt_m, 250, 1e-6);
  EXPECT_LT(Geodesic(kPisaLat, kPisaLon, out.lat_deg, out.lon_deg).distance_m, 1e-6);
}

TEST(GeoreferenceMount, LeverArmShiftsByItsLength) {
  const Eigen::Vector3d lever(2, 1, -0.5);
  const Georeferencer without;
  const Georeferencer with(MountOptions{.lever_arm_m = lever});
  const VehicleState state = Level(kPisaLat, kPisaLon, 80, 30);
  const Eigen::Vector3d p(3, -2, 60);
  const GeoPoint a = MustGeoreference(without, state, p);
  const GeoPoint b = MustGeoreference(with, state, p);
  const Inverse inv = Geodesic(a.lat_deg, a.lon_deg, b.lat_deg, b.lon_deg);
  EXPECT_NEAR(inv.distance_m, std::hypot(2.0, 1.0), 1e-3);
  EXPECT_NEAR(AngleDiffDeg(inv.azimuth_deg, 30 + std::atan2(1.0, 2.0) / kDeg), 0, 1e-3);
  EXPECT_NEAR(b.alt_m - a.alt_m, 0.5, 1e-3);
}

// The whole chain for arbitrary attitudes and mountings against the ECEF route with the written-out
// matrices (no LocalCartesian, no quaternions).
TEST(GeoreferenceChain, MatchesTheEcefRouteForAnyAttitude) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> angle(-80, 80), heading(-180, 180), lat(-70, 70),
      lon(-180, 180), alt(-50, 5000), coord(-50, 50), depth(1, 400), lever(-3, 3);
  double worst = 0;
  for (int i = 0; i < 300; ++i) {
    const MountOptions mount{.roll_deg = angle(rng),
                             .pitch_deg = angle(rng),
                             .yaw_deg = heading(rng),
                             .lever_arm_m = {lever(rng), lever(rng), lever(rng)}};
    const Georeferencer g(mount);
    VehicleState state{.lat_deg = lat(rng),
                       .lon_deg = lon(rng),
                       .alt_m = alt(rng),
                       .roll_deg = angle(rng),
                       .pitch_deg = angle(rng),
                       .yaw_deg = heading(rng)};
    const Eigen::Vector3d p(coord(rng), coord(rng), depth(rng));
    const GeoPoint out = MustGeoreference(g, state, p);

    const Eigen::Matrix3d body_from_cam =
        ReferenceDcm(mount.roll_deg, mount.pitch_deg, mount.yaw_deg) * ReferenceFrdFromCam();
    const Eigen::Vector3d ned = ReferenceDcm(state.roll_deg, state.pitch_deg, state.yaw_deg) *
                                (body_from_cam * p + mount.lever_arm_m);
    const Geodetic want = ReferenceFromNed({state.lat_deg, state.lon_deg, state.alt_m}, ned);
    const double miss = Geodesic(want.lat_deg, want.lon_deg, out.lat_deg, out.lon_deg).distance_m;
    EXPECT_LT(miss, 1e-6) << "case " << i;
    EXPECT_NEAR(out.alt_m, want.alt_m, 1e-6) << "case " << i;
    EXPECT_LT((out.offset_ned_m - ned).norm(), 1e-9) << "case " << i;
    worst = std::max(worst, miss);
    // The inverse brings the point back.
    EXPECT_LT((g.PointInCamOf(state, out.lat_deg, out.lon_deg, out.alt_m) - p).norm(), 1e-6);
  }
  std::printf("chain vs ECEF route: worst horizontal miss %.3g m\n", worst);
}

TEST(GeoreferenceVelocity, StationaryObstacleFromAMovingVehicle) {
  const Georeferencer g(MountOptions{.pitch_deg = -5, .yaw_deg = 20});
  VehicleState state = Level(kPisaLat, kPisaLon, 100, 15);
  state.roll_deg = 4;
  state.pitch_deg = -3;
  state.velocity_ned_mps = {29, 7, -1};
  // The obstacle moves east at 5 m/s; the camera sees (v_obstacle - v_vehicle) in its axes.
  const Eigen::Vector3d v_obstacle(0, 5, 0);
  const Eigen::Matrix3d cam_from_ned =
      (ReferenceDcm(4, -3, 15) * ReferenceDcm(0, -5, 20) * ReferenceFrdFromCam()).transpose();
  const Eigen::Vector3d v_cam = cam_from_ned * (v_obstacle - state.velocity_ned_mps);
  const GeoPoint out = MustGeoreference(g, state, {5, 1, 70}, v_cam);
  EXPECT_LT((out.velocity_ned_mps - v_obstacle).norm(), 1e-12);
}

TEST(GeoreferenceVelocity, AccountsForTheBodyRotation) {
  // A hovering vehicle yawing at 20 deg/s sees a stationary obstacle sweep across the image; with
  // the angular rate the obstacle's absolute velocity is zero.
  const Georeferencer g(MountOptions{.lever_arm_m = {0.5, 0, 0.2}});
  const double yaw_rate = 20 * kDeg;
  VehicleState state = Level(kPisaLat, kPisaLon, 60, 40);
  state.roll_deg = 3;
  state.pitch_deg = 5;
  const Eigen::Vector3d p_cam(12, -4, 90);
  const GeoPoint at = MustGeoreference(g, state, p_cam);
  // The cam-frame velocity by central differences of the exact inverse chain.
  const double dt = 1e-4;
  VehicleState before = state, after = state;
  before.yaw_deg -= yaw_rate * dt / kDeg;
  after.yaw_deg += yaw_rate * dt / kDeg;
  const Eigen::Vector3d v_cam = (g.PointInCamOf(after, at.lat_deg, at.lon_deg, at.alt_m) -
                                 g.PointInCamOf(before, at.lat_deg, at.lon_deg, at.alt_m)) /
                                (2 * dt);
  // A yaw rate in NED is R^T (0, 0, rate) in body axes.
  const Eigen::Vector3d rate_body =
      NedFromBody(state).conjugate() * Eigen::Vector3d(0, 0, yaw_rate);
  const GeoPoint out = MustGeoreference(g, state, p_cam, v_cam, rate_body);
  EXPECT_LT(out.velocity_ned_mps.norm(), 1e-5);
  // Without the rate the obstacle would seem to fly at rate * horizontal distance (~32 m/s).
  const GeoPoint no_rate = MustGeoreference(g, state, p_cam, v_cam);
  EXPECT_NEAR(no_rate.velocity_ned_mps.norm(), yaw_rate * at.offset_ned_m.head<2>().norm(), 1e-4);
}

// ---- Uncertainty ----

TEST(PositionSigma, RangeAndPixelSigmaAlongAndAcrossTheLineOfSight) {
  const Georeferencer g;
  for (double heading : {0.0, 45.0, 200.0}) {
    const VehicleState state = Level(kPisaLat, kPisaLon, 100, heading);
    const Eigen::Vector3d p(0, 0, 100);
    // 5 m along the line of sight, 0.7 px at f = 700 px -> 0.1 m across it.
    const PositionSigma s = g.Sigma(state, p, LineOfSightCovariance(p, 5, 0.7, 700));
    EXPECT_NEAR(s.horizontal_m, 5, 1e-9) << heading;
    EXPECT_NEAR(s.vertical_m, 0.1, 1e-9) << heading;
    // The minor horizontal axis is the lateral 0.1 m.
    const Eigen::Matrix2d ne = s.covariance_ned_m2.topLeftCorner<2, 2>();
    EXPECT_NEAR(ne.determinant(), 25 * 0.01, 1e-9) << heading;
  }
}

TEST(PositionSigma, AttitudeActsThroughTheLever) {
  const Georeferencer g;
  VehicleState state = Level(kPisaLat, kPisaLon, 100, 0);
  const Eigen::Vector3d ahead(0, 0, 100);
  const Eigen::Matrix3d zero = Eigen::Matrix3d::Zero();
  state.sigma = {.yaw_deg = 1};
  PositionSigma s = g.Sigma(state, ahead, zero);
  EXPECT_NEAR(s.horizontal_m, 100 * 1 * kDeg, 1e-9);  // 1.745 m
  EXPECT_NEAR(s.vertical_m, 0, 1e-9);
  state.sigma = {.tilt_deg = 0.5};
  s = g.Sigma(state, ahead, zero);
  EXPECT_NEAR(s.vertical_m, 100 * 0.5 * kDeg, 1e-9);  // pitch: 0.873 m; roll: none ahead
  EXPECT_NEAR(s.horizontal_m, 0, 1e-9);
  // A point 45 degrees to the right: roll and pitch both act, |r| * tilt in all.
  s = g.Sigma(state, Eigen::Vector3d(50, 0, 50), zero);
  EXPECT_NEAR(s.vertical_m, std::hypot(50.0, 50.0) * 0.5 * kDeg, 1e-9);
  // Position accuracy adds directly.
  state.sigma = {.horizontal_m = 1.5, .vertical_m = 3};
  s = g.Sigma(state, ahead, zero);
  EXPECT_NEAR(s.horizontal_m, 1.5, 1e-12);
  EXPECT_NEAR(s.vertical_m, 3, 1e-12);
}

// The first-order covariance against a Monte Carlo of the exact chain, at an attitude and mounting
// where the Euler-angle Jacobian is far from the identity.
TEST(PositionSigma, MatchesMonteCarloOfTheExactChain) {
  const MountOptions mount{
      .roll_deg = 5, .pitch_deg = -10, .yaw_deg = 30, .lever_arm_m = {1, 0.5, 0.3}};
  const Georeferencer g(mount);
  VehicleState state{
      .lat_deg = kPisaLat,
      .lon_deg = kPisaLon,
      .alt_m = 150,
      .roll_deg = 20,
      .pitch_deg = 25,
      .yaw_deg = 140,
      .sigma = {.horizontal_m = 0.8, .vertical_m = 1.2, .tilt_deg = 0.6, .yaw_deg = 1.5}};
  const Eigen::Vector3d p(-10, 4, 80);
  const Eigen::Matrix3d cov_cam = LineOfSightCovariance(p, 3, 0.5, 700);
  const PositionSigma want = g.Sigma(state, p, cov_cam);

  std::mt19937 rng(5);
  std::normal_distribution<double> n01(0, 1);
  const Eigen::Matrix3d chol = cov_cam.llt().matrixL();
  const int kSamples = 40000;
  Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
  const Eigen::Vector3d mean = g.OffsetNed(state, p);
  for (int i = 0; i < kSamples; ++i) {
    VehicleState noisy = state;
    noisy.roll_deg += state.sigma.tilt_deg * n01(rng);
    noisy.pitch_deg += state.sigma.tilt_deg * n01(rng);
    noisy.yaw_deg += state.sigma.yaw_deg * n01(rng);
    const Eigen::Vector3d position_error(state.sigma.horizontal_m * n01(rng),
                                         state.sigma.horizontal_m * n01(rng),
                                         state.sigma.vertical_m * n01(rng));
    const Eigen::Vector3d p_noisy = p + chol * Eigen::Vector3d(n01(rng), n01(rng), n01(rng));
    // The point's error relative to the true point: the vehicle's position error moves it too.
    const Eigen::Vector3d e = g.OffsetNed(noisy, p_noisy) + position_error - mean;
    sum += e * e.transpose();
  }
  const Eigen::Matrix3d sample = sum / kSamples;
  const double rel = (sample - want.covariance_ned_m2).norm() / want.covariance_ned_m2.norm();
  EXPECT_LT(rel, 0.03) << "sample\n" << sample << "\nfirst order\n" << want.covariance_ned_m2;
  std::printf(
      "sigma vs Monte Carlo (%d samples): relative Frobenius difference %.4f; "
      "horizontal %.3f m, vertical %.3f m\n",
      kSamples, rel, want.horizontal_m, want.vertical_m);
}

TEST(PositionSigma, DiagonalCovarianceFromTrackSigmas) {
  const Eigen::Matrix3d c = DiagonalCovariance(cv::Vec3d(0.1, 0.2, 3));
  const Eigen::Matrix3d want = Eigen::Vector3d(0.01, 0.04, 9).asDiagonal();
  EXPECT_LT((c - want).cwiseAbs().maxCoeff(), 1e-15);
  // Fed to the georeferencer, depth 3 m ahead is horizontal and the y sigma is vertical.
  const PositionSigma s = Georeferencer().Sigma(Level(0, 0, 0, 0), {0, 0, 50}, c);
  EXPECT_NEAR(s.horizontal_m, 3, 1e-12);
  EXPECT_NEAR(s.vertical_m, 0.2, 1e-12);
}

TEST(Georeference, ReturnsTheSigmaWithThePosition) {
  const Georeferencer g;
  VehicleState state = Level(kPisaLat, kPisaLon, 100, 10);
  state.sigma = {.horizontal_m = 1, .vertical_m = 2, .tilt_deg = 0.2, .yaw_deg = 0.5};
  const Eigen::Vector3d p(4, 1, 60);
  const Eigen::Matrix3d cov = LineOfSightCovariance(p, 2, 0.3, 700);
  const Result<GeoPoint> out = g.Georeference(VehiclePose{.state = state},
                                              PointInCam{.position_m = p, .covariance_m2 = cov});
  ASSERT_TRUE(out.ok());
  const PositionSigma want = g.Sigma(state, p, cov);
  EXPECT_EQ(out->sigma.horizontal_m, want.horizontal_m);
  EXPECT_EQ(out->sigma.vertical_m, want.vertical_m);
  EXPECT_GT(out->sigma.horizontal_m, 2);
}

TEST(Georeference, RefusesInvalidInputNamingTheFields) {
  const Georeferencer g;
  VehicleState bad_state = Level(100, kPisaLon, 0, 0);
  PointInCam bad_point{.position_m = {std::numeric_limits<double>::quiet_NaN(), 0, 10}};
  bad_point.covariance_m2(0, 1) = 1;  // not symmetric
  const Result<GeoPoint> out = g.Georeference(VehiclePose{.state = bad_state}, bad_point);
  ASSERT_FALSE(out.ok());
  EXPECT_THAT(out, IsError(ErrorCode::kInvalidArgument,
                           HasSubstr("pose.state.lat_deg: must be in [-90, 90]")));
  EXPECT_THAT(out.error().message, HasSubstr("point.position_m: must be finite"));
  EXPECT_THAT(out.error().message, HasSubstr("point.covariance_m2: must be symmetric"));

  PointInCam negative{.position_m = {0, 0, 10}};
  negative.covariance_m2(2, 2) = -1;
  const Result<GeoPoint> neg = g.Georeference(VehiclePose{.state = Level(0, 0, 0, 0)}, negative);
  ASSERT_FALSE(neg.ok());
  EXPECT_THAT(neg.error().message, HasSubstr("non-negative diagonal"));

  VehiclePose spinning{.state = Level(0, 0, 0, 0)};
  spinning.angular_rate_body_rps.x() = std::numeric_limits<double>::infinity();
  const Result<GeoPoint> spin = g.Georeference(spinning, PointInCam{.position_m = {0, 0, 10}});
  ASSERT_FALSE(spin.ok());
  EXPECT_THAT(spin.error().message, HasSubstr("pose.angular_rate_body_rps: must be finite"));
}

TEST(Georeferencer, RefusesAnInvalidMount) {
  EXPECT_THROW(Georeferencer(MountOptions{.pitch_deg = 120}), std::invalid_argument);
}

}  // namespace
}  // namespace stevi::geo
