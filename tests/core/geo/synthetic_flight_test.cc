// A synthetic flight: the vehicle flies north at 30 m/s with a small roll/pitch/yaw wobble
// towards a fixed obstacle. Each frame's cam-frame point is computed exactly through an
// independent chain (ECEF, written-out rotation matrices), measured like a stereo rig (pixel and
// disparity noise) and georeferenced with poses that carry errors at their stated accuracy,
// through the PoseBuffer. The georeferenced position must stay at the obstacle within the
// propagated sigma.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Eigenvalues>
#include <GeographicLib/Geodesic.hpp>
#include <gtest/gtest.h>

#include "core/geo/georeferencer.h"
#include "core/geo/pose_buffer.h"
#include "tests/core/geo/geo_reference.h"

namespace stevi::geo {
namespace {

using ref::Geodetic;
using ref::kDeg;

constexpr int64_t kSecond = 1'000'000'000;
constexpr double kTwoPi = 2 * std::numbers::pi;

// The stereo rig: f 700 px, baseline 0.6 m, 640x480.
constexpr double kFocalPx = 700, kBaselineM = 0.6, kCx = 320, kCy = 240;

const Geodetic kStart{43.6839, 10.3927, 150};  // height above the ellipsoid
constexpr double kSpeedMps = 30;               // north
const Eigen::Vector3d kLeverArm(0.4, 0, 0.1);

struct Attitude {
  double roll_deg, pitch_deg, yaw_deg;
};

// The true wobble.
Attitude TrueAttitude(double t) {
  return {2.0 * std::sin(kTwoPi * 0.7 * t), 1.5 * std::sin(kTwoPi * 0.5 * t + 1.0),
          1.0 * std::sin(kTwoPi * 0.3 * t)};
}

Geodetic TruePosition(double t) {
  Geodetic g = kStart;
  GeographicLib::Geodesic::WGS84().Direct(kStart.lat_deg, kStart.lon_deg, 0.0, kSpeedMps * t,
                                          g.lat_deg, g.lon_deg);
  return g;
}

// The obstacle: 140 m north of the start, 6 m east, 3 m above.
Geodetic Obstacle() { return ref::ReferenceFromNed(kStart, Eigen::Vector3d(140, 6, -3)); }

// The exact cam-frame point of a WGS84 point seen at time t: through ECEF and the written-out
// matrices (default mount, kLeverArm), independent of the library.
Eigen::Vector3d TrueCamPoint(double t, const Geodetic& point) {
  const Attitude a = TrueAttitude(t);
  const Eigen::Vector3d ned = ref::ReferenceNedOffset(TruePosition(t), point);
  const Eigen::Vector3d body =
      ref::ReferenceDcm(a.roll_deg, a.pitch_deg, a.yaw_deg).transpose() * ned;
  return ref::ReferenceFrdFromCam().transpose() * (body - kLeverArm);
}

// A first-order Gauss-Markov error with stationary 1-sigma `sigma` and correlation time tau.
class GaussMarkov {
 public:
  GaussMarkov(double sigma, double tau_s, double dt_s, std::mt19937& rng)
      : sigma_(sigma), rho_(std::exp(-dt_s / tau_s)), rng_(rng) {
    value_ = sigma_ * n01_(rng_);
  }
  double value() const { return value_; }
  void Step() { value_ = rho_ * value_ + std::sqrt(1 - rho_ * rho_) * sigma_ * n01_(rng_); }

 private:
  double sigma_, rho_;
  std::mt19937& rng_;
  std::normal_distribution<double> n01_{0, 1};
  double value_ = 0;
};

struct Noise {
  const char* name;
  PoseSigma pose;         // the stated (and simulated) pose accuracy
  double pixel_sigma_px;  // centroid noise on u and v
  double disparity_sigma_px;
};

struct Stats {
  int frames = 0;
  double max_h = 0, max_v = 0;                        // max |e_h| / sigma_h, |e_v| / sigma_v
  double sum_major2 = 0, sum_minor2 = 0, sum_v2 = 0;  // normalised squared errors
  double sum_eh2 = 0, sum_trace_h = 0, sum_ev2 = 0, sum_sv2 = 0;  // unnormalised
  double sum_sigma_h = 0;
  double min_range = 1e9, max_range = 0;

  double RmsMajor() const { return std::sqrt(sum_major2 / frames); }
  double RmsMinor() const { return std::sqrt(sum_minor2 / frames); }
  double RmsVertical() const { return std::sqrt(sum_v2 / frames); }
  double RmsRatioH() const { return std::sqrt(sum_eh2 / sum_trace_h); }
  double RmsRatioV() const { return std::sqrt(sum_ev2 / sum_sv2); }
};

// Flies once with one seed and adds each frame to `stats`.
void Fly(const Noise& noise, unsigned seed, Stats& stats) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n01(0, 1);
  const double kPoseDt = 0.01;  // 100 Hz navigation solution
  const double kTau = 0.2;      // correlation time of its errors
  GaussMarkov north(noise.pose.horizontal_m, kTau, kPoseDt, rng);
  GaussMarkov east(noise.pose.horizontal_m, kTau, kPoseDt, rng);
  GaussMarkov down(noise.pose.vertical_m, kTau, kPoseDt, rng);
  GaussMarkov roll(noise.pose.tilt_deg, kTau, kPoseDt, rng);
  GaussMarkov pitch(noise.pose.tilt_deg, kTau, kPoseDt, rng);
  GaussMarkov yaw(noise.pose.yaw_deg, kTau, kPoseDt, rng);

  PoseBuffer buffer;
  const Georeferencer georeferencer(MountOptions{.lever_arm_m = kLeverArm});
  const Geodetic obstacle = Obstacle();
  int next_pose = 0;

  // 30 Hz frames (5 ms + k / 30 s: at every phase between the 100 Hz pose ticks), from 120 m to
  // 20 m ahead.
  for (int k = 0;; ++k) {
    const double t = 0.005 + k / 30.0;
    const int64_t t_ns = static_cast<int64_t>(std::llround(t * 1e9));
    const Eigen::Vector3d truth = TrueCamPoint(t, obstacle);
    if (truth.z() < 20) break;
    if (truth.z() > 120) continue;

    // The navigation solution arrives up to 20 ms after the frame time.
    while (next_pose * kPoseDt <= t + 0.02) {
      const double tp = next_pose * kPoseDt;
      const Attitude a = TrueAttitude(tp);
      const Geodetic p = ref::ReferenceFromNed(
          TruePosition(tp), Eigen::Vector3d(north.value(), east.value(), down.value()));
      const VehicleState state{.t_ns = next_pose * (kSecond / 100),
                               .lat_deg = p.lat_deg,
                               .lon_deg = p.lon_deg,
                               .alt_m = p.alt_m,
                               .roll_deg = a.roll_deg + roll.value(),
                               .pitch_deg = a.pitch_deg + pitch.value(),
                               .yaw_deg = a.yaw_deg + yaw.value(),
                               .velocity_ned_mps = {kSpeedMps, 0, 0},
                               .sigma = noise.pose};
      ASSERT_TRUE(buffer.Add(state).ok());
      for (GaussMarkov* g : {&north, &east, &down, &roll, &pitch, &yaw}) g->Step();
      ++next_pose;
    }

    // The stereo measurement: centroid and disparity noise, then back-projection.
    const double u = kCx + kFocalPx * truth.x() / truth.z() + noise.pixel_sigma_px * n01(rng);
    const double v = kCy + kFocalPx * truth.y() / truth.z() + noise.pixel_sigma_px * n01(rng);
    const double d = kFocalPx * kBaselineM / truth.z() + noise.disparity_sigma_px * n01(rng);
    ASSERT_GT(d, 0);
    ASSERT_TRUE(u > 0 && u < 640 && v > 0 && v < 480) << "out of view at t " << t;
    const double z = kFocalPx * kBaselineM / d;
    const Eigen::Vector3d measured((u - kCx) * z / kFocalPx, (v - kCy) * z / kFocalPx, z);
    // The rig's own sigma, from the measured point: dZ = Z^2 / (f B) * dd along the ray.
    const double depth_sigma = z * z / (kFocalPx * kBaselineM) * noise.disparity_sigma_px;
    const double range_sigma = depth_sigma * measured.norm() / z;
    const Eigen::Matrix3d cov =
        LineOfSightCovariance(measured, range_sigma, noise.pixel_sigma_px, kFocalPx);

    const PoseLookup lookup = buffer.At(t_ns);
    ASSERT_TRUE(lookup.ok()) << lookup.message << " at t " << t;
    const Result<GeoPoint> out =
        georeferencer.Georeference(*lookup.pose, {.position_m = measured, .covariance_m2 = cov});
    ASSERT_TRUE(out.ok()) << out.error().message;

    // The error in metres, NED at the obstacle.
    const Eigen::Vector3d e =
        ref::ReferenceNedOffset(obstacle, {out->lat_deg, out->lon_deg, out->alt_m});
    const Eigen::Matrix3d& c = out->sigma.covariance_ned_m2;
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(c.topLeftCorner<2, 2>());
    const Eigen::Vector2d eh = e.head<2>();
    const double sigma_minor = std::sqrt(eig.eigenvalues()(0));
    const double sigma_major = std::sqrt(eig.eigenvalues()(1));
    EXPECT_NEAR(sigma_major, out->sigma.horizontal_m, 1e-9);
    const double e_minor = eig.eigenvectors().col(0).dot(eh);
    const double e_major = eig.eigenvectors().col(1).dot(eh);
    const double sigma_v = out->sigma.vertical_m;

    ++stats.frames;
    stats.max_h = std::max(stats.max_h, eh.norm() / out->sigma.horizontal_m);
    stats.max_v = std::max(stats.max_v, std::abs(e.z()) / sigma_v);
    stats.sum_major2 += (e_major / sigma_major) * (e_major / sigma_major);
    stats.sum_minor2 += (e_minor / sigma_minor) * (e_minor / sigma_minor);
    stats.sum_v2 += (e.z() / sigma_v) * (e.z() / sigma_v);
    stats.sum_eh2 += eh.squaredNorm();
    stats.sum_trace_h += c(0, 0) + c(1, 1);
    stats.sum_ev2 += e.z() * e.z();
    stats.sum_sv2 += sigma_v * sigma_v;
    stats.sum_sigma_h += out->sigma.horizontal_m;
    stats.min_range = std::min(stats.min_range, truth.norm());
    stats.max_range = std::max(stats.max_range, truth.norm());
  }
}

// k = 4: a frame beyond 4 sigma has probability 6e-5 on one axis (3e-4 for |e_h| against the
// major axis when the ellipse is round); over 8 x 100 frames a stray one would be unusual.
constexpr double kK = 4.0;

void RunScenario(const Noise& noise) {
  Stats stats;
  for (unsigned seed = 1; seed <= 8; ++seed) {
    Fly(noise, seed, stats);
    if (::testing::Test::HasFatalFailure()) return;
  }
  std::printf(
      "%s: %d frames, range %.0f-%.0f m, mean sigma_h %.2f m\n"
      "  max |e_h|/sigma_h %.2f, max |e_v|/sigma_v %.2f\n"
      "  RMS normalised error: major %.3f, minor %.3f, vertical %.3f\n"
      "  RMS error / RMS sigma: horizontal %.3f, vertical %.3f\n",
      noise.name, stats.frames, stats.min_range, stats.max_range, stats.sum_sigma_h / stats.frames,
      stats.max_h, stats.max_v, stats.RmsMajor(), stats.RmsMinor(), stats.RmsVertical(),
      stats.RmsRatioH(), stats.RmsRatioV());
  EXPECT_GE(stats.frames, 8 * 90);
  EXPECT_LE(stats.max_h, kK);
  EXPECT_LE(stats.max_v, kK);
  for (double ratio : {stats.RmsMajor(), stats.RmsMinor(), stats.RmsVertical(), stats.RmsRatioH(),
                       stats.RmsRatioV()}) {
    EXPECT_GE(ratio, 0.5);
    EXPECT_LE(ratio, 1.5);
  }
}

TEST(SyntheticFlight, StereoNoiseDominates) {
  // A GNSS/INS of a small UAV and the thesis rig: depth noise (8.6 m at 120 m) dominates the
  // horizontal error, the GNSS height the vertical one.
  RunScenario({.name = "stereo-dominated",
               .pose = {.horizontal_m = 1.0, .vertical_m = 1.5, .tilt_deg = 0.2, .yaw_deg = 0.5},
               .pixel_sigma_px = 0.3,
               .disparity_sigma_px = 0.25});
}

TEST(SyntheticFlight, PoseNoiseDominates) {
  // A poor heading (2 deg: 4 m across the line of sight at 120 m) and tilt (0.5 deg) with a near
  // perfect rig: the attitude propagation must carry the error budget.
  RunScenario({.name = "pose-dominated",
               .pose = {.horizontal_m = 0.5, .vertical_m = 0.5, .tilt_deg = 0.5, .yaw_deg = 2.0},
               .pixel_sigma_px = 0.1,
               .disparity_sigma_px = 0.02});
}

TEST(SyntheticFlight, StationaryObstacleHasNoVelocity) {
  // Exact poses and the exact apparent cam-frame velocity: the obstacle's absolute velocity is
  // the vehicle's plus the rotated relative one plus omega x r. The buffer's angular rate is that
  // of the 10 ms chord; at a frame up to 5 ms from the chord's middle it lags the true rate by up
  // to |d omega/dt| * 5 ms, which bounds the error at |r| * that.
  PoseBuffer buffer({.max_age_s = 10});  // the whole flight is buffered before the frames
  const Georeferencer georeferencer(MountOptions{.lever_arm_m = kLeverArm});
  const Geodetic obstacle = Obstacle();
  for (int i = 0; i <= 400; ++i) {
    const double tp = i * 0.01;
    const Attitude a = TrueAttitude(tp);
    const Geodetic p = TruePosition(tp);
    ASSERT_TRUE(buffer
                    .Add({.t_ns = i * (kSecond / 100),
                          .lat_deg = p.lat_deg,
                          .lon_deg = p.lon_deg,
                          .alt_m = p.alt_m,
                          .roll_deg = a.roll_deg,
                          .pitch_deg = a.pitch_deg,
                          .yaw_deg = a.yaw_deg,
                          .velocity_ned_mps = {kSpeedMps, 0, 0}})
                    .ok());
  }
  // The largest angular acceleration of the wobble, rad/s^2.
  const double max_accel = (2.0 * std::pow(kTwoPi * 0.7, 2) + 1.5 * std::pow(kTwoPi * 0.5, 2) +
                            1.0 * std::pow(kTwoPi * 0.3, 2)) *
                           kDeg;
  double worst = 0, worst_without_rate = 0;
  for (int k = 0; k < 110; ++k) {
    const double t = 0.005 + k / 30.0;
    const Eigen::Vector3d p_cam = TrueCamPoint(t, obstacle);
    const double h = 1e-5;
    const Eigen::Vector3d v_cam =
        (TrueCamPoint(t + h, obstacle) - TrueCamPoint(t - h, obstacle)) / (2 * h);
    // Frames fall between the 100 Hz states.
    const PoseLookup lookup = buffer.At(static_cast<int64_t>(std::llround(t * 1e9)));
    ASSERT_TRUE(lookup.ok()) << lookup.message;
    const Result<GeoPoint> out =
        georeferencer.Georeference(*lookup.pose, {.position_m = p_cam, .velocity_mps = v_cam});
    ASSERT_TRUE(out.ok());
    const double bound = max_accel * 0.005 * p_cam.norm() + 0.01;
    EXPECT_LT(out->velocity_ned_mps.norm(), bound) << "t " << t;
    worst = std::max(worst, out->velocity_ned_mps.norm());
    VehiclePose no_rate = *lookup.pose;
    no_rate.angular_rate_body_rps.setZero();
    const Result<GeoPoint> without =
        georeferencer.Georeference(no_rate, {.position_m = p_cam, .velocity_mps = v_cam});
    worst_without_rate = std::max(worst_without_rate, without->velocity_ned_mps.norm());
  }
  std::printf(
      "stationary obstacle: worst |velocity| %.3f m/s with the angular rate, %.2f m/s "
      "without\n",
      worst, worst_without_rate);
  EXPECT_GT(worst_without_rate, 10 * worst);
}

}  // namespace
}  // namespace stevi::geo
