// A constant-velocity Kalman filter on three independent axes, and the measurement model of a
// detection (image position over f, and depth). The model and its units are derived in
// core/tracking/README.md.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/common/fields.h"

namespace stevi::tracking {

// The rectified left camera and the baseline: all the tracker needs to go between pixels and the
// cam frame (x right, y down, z forward, metres).
struct CameraModel {
  double f_px = 0;  // focal length, pixels
  double cx = 0;    // principal point, pixels
  double cy = 0;
  double baseline_m = 0;  // stereo baseline, metres
  // The image size (pixels; 0 = unknown): blobs cut by the border are anchored on their inner edge
  // and tracks predicted out of the image are dropped.
  int width = 0;
  int height = 0;

  // Lists every problem ("f_px: must be > 0 (got 0)").
  std::vector<std::string> Validate() const;
};

// Pixel (u, v) of a cam-frame point. The point must be in front of the camera (z > 0).
Eigen::Vector2d Project(const CameraModel& camera, const Eigen::Vector3d& point_in_cam_m);

// What the tracker filters: s = (a, b, z), a = (u - cx) / f and b = (v - cy) / f the image
// position over the focal length (the tangents of the viewing angles) and z the depth. Their noises
// are independent (the centroid's pixel noise on a and b, the disparity's on z), so the filter
// never explains a sideways miss by a change of depth (README.md: why not x, y, z).
struct AngleDepth {
  Eigen::Vector3d s;           // (a, b, z): dimensionless, dimensionless, metres
  Eigen::Matrix3d covariance;  // diagonal
};

// The measurement of a detection centred at pixel (u, v) at depth `depth_m` with 1-sigma
// `depth_sigma_m` (when not finite and positive: the centroid's pixel variance on the disparity,
// z^2 / (f B) per pixel), with centroid variance `centroid_variance_px2` on u and v.
AngleDepth MeasureAngleDepth(const CameraModel& camera, double u_px, double v_px, double depth_m,
                             double depth_sigma_m, double centroid_variance_px2);

// The cam-frame point (a z, b z, z) of s = (a, b, z).
Eigen::Vector3d PointFromAngleDepth(const Eigen::Vector3d& s);

// The noises of the filter. Defaults are the thesis's numbers, given units in this model
// (README.md): process noises are white-acceleration densities in the cam frame, measurement noises
// are pixel variances.
struct KalmanOptions {
  // Process noise while the track is measured: power spectral density of the white acceleration on
  // each cam axis (m^2/s^3). 1e-2 lets the velocity wander by 0.1 m/s in one second.
  double process_noise = 1e-2;
  // Measurement noise: variance of a detection's centroid on u and v (pixel^2; 0.1 is a 0.32 px
  // sigma). The depth noise is the detection's own range_sigma_m.
  double measurement_noise = 1e-1;
  // Process noise while occluded (no detection), m^2/s^3. Smaller than process_noise, as in the
  // thesis: the track runs in free prediction and trusts its constant-velocity model.
  double occluded_process_noise = 1e-5;
  // While occluded, the prediction itself is fed back as a pseudo-measurement with this variance
  // on u, v and the disparity (pixel^2). It never moves the state (its innovation is zero) and only
  // shrinks the covariance; 1e7 makes it a no-op, the thesis's free prediction.
  double occluded_measurement_noise = 1e7;
  // 1-sigma of a new track's unknown velocity on each axis (m/s): about the fastest relative speed
  // expected.
  double initial_velocity_sigma_mps = 20;

  std::vector<std::string> Validate() const;
  bool operator==(const KalmanOptions&) const = default;

  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Number(s.process_noise, Field("process_noise", "m^2/s^3",
                                    "white-acceleration density on each camera axis while detected")
                                  .AtLeast(0));
    v.Number(s.measurement_noise,
             Field("measurement_noise", "pixels^2", "variance of a detection's centroid on u and v")
                 .Above(0));
    v.Number(s.occluded_process_noise,
             Field("occluded_process_noise", "m^2/s^3", "process noise while occluded").AtLeast(0));
    v.Number(s.occluded_measurement_noise,
             Field("occluded_measurement_noise", "pixels^2",
                   "pseudo-measurement variance while occluded; 1e7 = free prediction")
                 .Above(0));
    v.Number(s.initial_velocity_sigma_mps,
             Field("initial_velocity_sigma_mps", "m/s",
                   "1-sigma of a new track's unknown velocity per axis")
                 .Above(0));
  }
};

// State [x y z vx vy vz] in the cam frame (metres, m/s); measurement: the position.
// Thread-compatible.
class ConstantVelocityKalman {
 public:
  using State = Eigen::Matrix<double, 6, 1>;
  using Covariance = Eigen::Matrix<double, 6, 6>;

  // Starts at `position_m` with covariance `position_cov_m2`, at rest, with a velocity sigma of
  // `velocity_sigma_mps` on each axis (or per axis).
  void Initialize(const Eigen::Vector3d& position_m, const Eigen::Matrix3d& position_cov_m2,
                  double velocity_sigma_mps);
  void Initialize(const Eigen::Vector3d& position_m, const Eigen::Matrix3d& position_cov_m2,
                  const Eigen::Vector3d& velocity_sigma);

  // The position `dt_s` seconds ahead, leaving the filter unchanged. The predicted mean does not
  // depend on the process noise, so gating can use it before the noise is chosen.
  Eigen::Vector3d PredictedPosition(double dt_s) const;

  // Advances the state by `dt_s` seconds (negative is read as 0) with white-acceleration noise of
  // density `process_noise` (m^2/s^3), discretised exactly for dt.
  void Predict(double dt_s, double process_noise);
  // The same with a density per axis (in the axis' units squared per s^3).
  void Predict(double dt_s, const Eigen::Vector3d& process_noise);

  // For a state s = (a, b, z) and its rates (MeasureAngleDepth): the obstacle moves on a straight
  // line at constant velocity in the camera frame (not in s, where a passing or closing obstacle
  // accelerates), with white acceleration of density `process_noise` (m^2/s^3) on each cam axis.
  // An extended Kalman prediction: the mean goes through the exact motion, the covariance through
  // its Jacobian. PredictedAngleDepth() is the mean alone, leaving the filter unchanged.
  void PredictAngleDepth(double dt_s, double process_noise);
  Eigen::Vector3d PredictedAngleDepth(double dt_s) const;

  // For a state s = (a, b, z) and its rates: maps its cam-frame position and velocity (p, v)
  // through the affine map (p, v) -> linear * (p, v) + offset, the mean exactly and the covariance
  // through the map's Jacobian in s (no process noise). A rigid motion of the camera,
  // p' = R p + t, is linear = diag(R, R) and offset = (t, 0); a change of what the velocity is
  // relative to, v' = v + A p + c, is linear = [I 0; A I] and offset = (0, c). A point that ends
  // behind the camera is frozen at the smallest depth (see PredictAngleDepth).
  void MapAngleDepth(const Eigen::Matrix<double, 6, 6>& linear,
                     const Eigen::Matrix<double, 6, 1>& offset);

  // Corrects with a measured position (metres) of covariance `covariance_m2` (Joseph form, which
  // keeps the covariance symmetric and positive). Returns false, leaving the filter unchanged, when
  // the innovation covariance is not positive definite (a NaN in the input).
  bool Update(const Eigen::Vector3d& measured_m, const Eigen::Matrix3d& covariance_m2);

  const State& state() const { return x_; }
  const Covariance& covariance() const { return P_; }
  Eigen::Vector3d position() const { return x_.head<3>(); }
  Eigen::Vector3d velocity() const { return x_.tail<3>(); }

 private:
  State x_ = State::Zero();
  Covariance P_ = Covariance::Identity();
};

}  // namespace stevi::tracking
