#include "core/tracking/kalman.h"

#include <cmath>

#include <Eigen/Cholesky>
#include <Eigen/LU>

#include "core/common/error.h"

namespace stevi::tracking {
namespace {

bool PositiveFinite(double x) { return std::isfinite(x) && x > 0; }

}  // namespace

std::vector<std::string> CameraModel::Validate() const {
  std::vector<std::string> problems;
  if (!PositiveFinite(f_px)) problems.push_back("f_px: must be > 0 pixels" + Got(f_px));
  if (!std::isfinite(cx)) problems.push_back("cx: must be finite" + Got(cx));
  if (!std::isfinite(cy)) problems.push_back("cy: must be finite" + Got(cy));
  if (!PositiveFinite(baseline_m)) {
    problems.push_back("baseline_m: must be > 0 metres" + Got(baseline_m));
  }
  if (width < 0) problems.push_back("width: must be >= 0 pixels (0 = unknown)" + Got(width));
  if (height < 0) problems.push_back("height: must be >= 0 pixels (0 = unknown)" + Got(height));
  return problems;
}

Eigen::Vector2d Project(const CameraModel& camera, const Eigen::Vector3d& point_in_cam_m) {
  const double inv_z = 1.0 / point_in_cam_m.z();
  return {camera.cx + camera.f_px * point_in_cam_m.x() * inv_z,
          camera.cy + camera.f_px * point_in_cam_m.y() * inv_z};
}

AngleDepth MeasureAngleDepth(const CameraModel& camera, double u_px, double v_px, double depth_m,
                             double depth_sigma_m, double centroid_variance_px2) {
  AngleDepth m;
  const double f = camera.f_px;
  m.s = Eigen::Vector3d((u_px - camera.cx) / f, (v_px - camera.cy) / f, depth_m);
  // dz/dd = -z^2 / (f B): one pixel of disparity noise in metres of depth.
  const double depth_per_px = depth_m * depth_m / (f * camera.baseline_m);
  const double depth_variance = PositiveFinite(depth_sigma_m)
                                    ? depth_sigma_m * depth_sigma_m
                                    : centroid_variance_px2 * depth_per_px * depth_per_px;
  m.covariance = Eigen::Vector3d(centroid_variance_px2 / (f * f), centroid_variance_px2 / (f * f),
                                 depth_variance)
                     .asDiagonal();
  return m;
}

Eigen::Vector3d PointFromAngleDepth(const Eigen::Vector3d& s) {
  return {s.x() * s.z(), s.y() * s.z(), s.z()};
}

std::vector<std::string> KalmanOptions::Validate() const { return fields::Check(*this); }

void ConstantVelocityKalman::Initialize(const Eigen::Vector3d& position_m,
                                        const Eigen::Matrix3d& position_cov_m2,
                                        double velocity_sigma_mps) {
  Initialize(position_m, position_cov_m2, Eigen::Vector3d::Constant(velocity_sigma_mps));
}

void ConstantVelocityKalman::Initialize(const Eigen::Vector3d& position_m,
                                        const Eigen::Matrix3d& position_cov_m2,
                                        const Eigen::Vector3d& velocity_sigma) {
  x_.head<3>() = position_m;
  x_.tail<3>().setZero();
  P_.setZero();
  P_.topLeftCorner<3, 3>() = position_cov_m2;
  P_.bottomRightCorner<3, 3>() = velocity_sigma.cwiseProduct(velocity_sigma).asDiagonal();
}

Eigen::Vector3d ConstantVelocityKalman::PredictedPosition(double dt_s) const {
  if (!(dt_s > 0)) dt_s = 0;
  return x_.head<3>() + dt_s * x_.tail<3>();
}

void ConstantVelocityKalman::Predict(double dt_s, double process_noise) {
  Predict(dt_s, Eigen::Vector3d::Constant(process_noise));
}

void ConstantVelocityKalman::Predict(double dt_s, const Eigen::Vector3d& q) {
  if (!(dt_s > 0)) dt_s = 0;
  Covariance F = Covariance::Identity();
  F.topRightCorner<3, 3>().diagonal().setConstant(dt_s);
  x_ = F * x_;
  // Continuous white acceleration of density q_i on axis i, integrated over dt:
  // Q = [dt^3/3 q, dt^2/2 q; dt^2/2 q, dt q] (q diagonal).
  const double dt2 = dt_s * dt_s;
  Covariance Q = Covariance::Zero();
  Q.topLeftCorner<3, 3>().diagonal() = q * (dt2 * dt_s / 3);
  Q.topRightCorner<3, 3>().diagonal() = q * (dt2 / 2);
  Q.bottomLeftCorner<3, 3>().diagonal() = q * (dt2 / 2);
  Q.bottomRightCorner<3, 3>().diagonal() = q * dt_s;
  P_ = F * P_ * F.transpose() + Q;
}

namespace {

using Vector6 = Eigen::Matrix<double, 6, 1>;
using Matrix6 = Eigen::Matrix<double, 6, 6>;

// Points nearer than this along the optical axis have passed the camera: the motion is frozen
// there rather than divided by ~0.
constexpr double kMinDepthM = 1e-3;

// (p, v) in the camera frame from s = (a, b, z, a', b', z').
Vector6 CamFromAngleDepth(const Vector6& s) {
  Vector6 c;
  c << s(0) * s(2), s(1) * s(2), s(2), s(3) * s(2) + s(0) * s(5), s(4) * s(2) + s(1) * s(5), s(5);
  return c;
}

// s from (p, v).
Vector6 AngleDepthFromCam(const Vector6& c) {
  const double z = std::max(c(2), kMinDepthM);
  const double a = c(0) / z, b = c(1) / z;
  Vector6 s;
  s << a, b, z, (c(3) - a * c(5)) / z, (c(4) - b * c(5)) / z, c(5);
  return s;
}

// s after dt of straight-line motion.
Vector6 MoveAngleDepth(const Vector6& s, double dt) {
  Vector6 c = CamFromAngleDepth(s);
  c.head<3>() += dt * c.tail<3>();
  return AngleDepthFromCam(c);
}

// Central-difference Jacobian of f at x, steps scaled to each component.
template <typename F>
Matrix6 NumericJacobian(const F& f, const Vector6& x) {
  Matrix6 J;
  for (int i = 0; i < 6; ++i) {
    const double h = 1e-6 * std::max(1.0, std::abs(x(i)));
    Vector6 plus = x, minus = x;
    plus(i) += h;
    minus(i) -= h;
    J.col(i) = (f(plus) - f(minus)) / (2 * h);
  }
  return J;
}

}  // namespace

Eigen::Vector3d ConstantVelocityKalman::PredictedAngleDepth(double dt_s) const {
  if (!(dt_s > 0)) return x_.head<3>();
  return MoveAngleDepth(x_, dt_s).head<3>();
}

void ConstantVelocityKalman::PredictAngleDepth(double dt_s, double q) {
  if (!(dt_s > 0)) dt_s = 0;
  const Matrix6 F =
      NumericJacobian([dt_s](const Vector6& s) { return MoveAngleDepth(s, dt_s); }, x_);
  x_ = MoveAngleDepth(x_, dt_s);
  // White acceleration of density q on each cam axis over dt, mapped into s at the new state.
  const double dt2 = dt_s * dt_s;
  Matrix6 Q = Matrix6::Zero();
  Q.topLeftCorner<3, 3>().diagonal().setConstant(q * dt2 * dt_s / 3);
  Q.topRightCorner<3, 3>().diagonal().setConstant(q * dt2 / 2);
  Q.bottomLeftCorner<3, 3>().diagonal().setConstant(q * dt2 / 2);
  Q.bottomRightCorner<3, 3>().diagonal().setConstant(q * dt_s);
  const Matrix6 G = NumericJacobian(AngleDepthFromCam, CamFromAngleDepth(x_));
  P_ = F * P_ * F.transpose() + G * Q * G.transpose();
  P_ = 0.5 * (P_ + P_.transpose()).eval();
}

void ConstantVelocityKalman::MapAngleDepth(const Matrix6& linear, const Vector6& offset) {
  const auto map = [&linear, &offset](const Vector6& s) {
    return AngleDepthFromCam(linear * CamFromAngleDepth(s) + offset);
  };
  const Matrix6 F = NumericJacobian(map, x_);
  x_ = map(x_);
  P_ = F * P_ * F.transpose();
  P_ = 0.5 * (P_ + P_.transpose()).eval();
}

bool ConstantVelocityKalman::Update(const Eigen::Vector3d& measured_m,
                                    const Eigen::Matrix3d& covariance_m2) {
  // H = [I 0], so H P = the top three rows of P and H P H^T its top-left block.
  const Eigen::Matrix3d S = P_.topLeftCorner<3, 3>() + covariance_m2;
  if (!S.allFinite()) return false;
  // The Cholesky factorisation only checks that S is positive definite; the closed-form 3x3
  // inverse is then exact enough and much faster than a triangular solve.
  if (Eigen::LLT<Eigen::Matrix3d>(S).info() != Eigen::Success) return false;
  const Eigen::Matrix<double, 6, 3> K = P_.leftCols<3>() * S.inverse();
  const Eigen::Vector3d innovation = measured_m - x_.head<3>();
  if (!innovation.allFinite()) return false;
  x_ += K * innovation;
  Covariance I_KH = Covariance::Identity();
  I_KH.leftCols<3>() -= K;
  P_ = I_KH * P_ * I_KH.transpose() + K * covariance_m2 * K.transpose();
  P_ = 0.5 * (P_ + P_.transpose()).eval();
  return true;
}

}  // namespace stevi::tracking
