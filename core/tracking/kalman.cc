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
  return problems;
}

Eigen::Vector2d Project(const CameraModel& camera, const Eigen::Vector3d& point_in_cam_m) {
  const double inv_z = 1.0 / point_in_cam_m.z();
  return {camera.cx + camera.f_px * point_in_cam_m.x() * inv_z,
          camera.cy + camera.f_px * point_in_cam_m.y() * inv_z};
}

Eigen::Matrix3d PixelNoiseCovariance(const CameraModel& camera,
                                     const Eigen::Vector3d& point_in_cam_m, double variance_px2) {
  // p = B / d * (u - cx, v - cy, f). dp/du = (z/f, 0, 0), dp/dv = (0, z/f, 0), and
  // dp/dd = -p / d = -(z^2 / (f B)) * p / z: along the ray through p.
  const double z = point_in_cam_m.z();
  const double lateral = z / camera.f_px;
  const Eigen::Vector3d along_ray = point_in_cam_m * (z / (camera.f_px * camera.baseline_m));
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  covariance(0, 0) = covariance(1, 1) = lateral * lateral;
  covariance += along_ray * along_ray.transpose();
  return variance_px2 * covariance;
}

Eigen::Matrix3d DetectionCovariance(const CameraModel& camera,
                                    const Eigen::Vector3d& point_in_cam_m,
                                    double centroid_variance_px2, double range_sigma_m) {
  const double range = point_in_cam_m.norm();
  if (!PositiveFinite(range_sigma_m) || !(range > 0)) {
    return PixelNoiseCovariance(camera, point_in_cam_m, centroid_variance_px2);
  }
  const double lateral = point_in_cam_m.z() / camera.f_px;
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  covariance(0, 0) = covariance(1, 1) = centroid_variance_px2 * lateral * lateral;
  const Eigen::Vector3d ray = point_in_cam_m / range;
  covariance += (range_sigma_m * range_sigma_m) * ray * ray.transpose();
  return covariance;
}

std::vector<std::string> KalmanOptions::Validate() const {
  std::vector<std::string> problems;
  if (!(std::isfinite(process_noise) && process_noise >= 0)) {
    problems.push_back("process_noise: must be >= 0 m^2/s^3 and finite" + Got(process_noise));
  }
  if (!PositiveFinite(measurement_noise)) {
    problems.push_back("measurement_noise: must be > 0 pixel^2 and finite" +
                       Got(measurement_noise));
  }
  if (!(std::isfinite(occluded_process_noise) && occluded_process_noise >= 0)) {
    problems.push_back("occluded_process_noise: must be >= 0 m^2/s^3 and finite" +
                       Got(occluded_process_noise));
  }
  if (!PositiveFinite(occluded_measurement_noise)) {
    problems.push_back("occluded_measurement_noise: must be > 0 pixel^2 and finite" +
                       Got(occluded_measurement_noise));
  }
  if (!PositiveFinite(initial_velocity_sigma_mps)) {
    problems.push_back("initial_velocity_sigma_mps: must be > 0 m/s and finite" +
                       Got(initial_velocity_sigma_mps));
  }
  return problems;
}

void ConstantVelocityKalman::Initialize(const Eigen::Vector3d& position_m,
                                        const Eigen::Matrix3d& position_cov_m2,
                                        double velocity_sigma_mps) {
  x_.head<3>() = position_m;
  x_.tail<3>().setZero();
  P_.setZero();
  P_.topLeftCorner<3, 3>() = position_cov_m2;
  P_.bottomRightCorner<3, 3>() =
      Eigen::Matrix3d::Identity() * (velocity_sigma_mps * velocity_sigma_mps);
}

Eigen::Vector3d ConstantVelocityKalman::PredictedPosition(double dt_s) const {
  if (!(dt_s > 0)) dt_s = 0;
  return x_.head<3>() + dt_s * x_.tail<3>();
}

void ConstantVelocityKalman::Predict(double dt_s, double process_noise) {
  if (!(dt_s > 0)) dt_s = 0;
  Covariance F = Covariance::Identity();
  F.topRightCorner<3, 3>().diagonal().setConstant(dt_s);
  x_ = F * x_;
  // Continuous white acceleration of density q on each axis, integrated over dt:
  // Q = q [dt^3/3 I, dt^2/2 I; dt^2/2 I, dt I].
  const double dt2 = dt_s * dt_s;
  Covariance Q = Covariance::Zero();
  Q.topLeftCorner<3, 3>().diagonal().setConstant(process_noise * dt2 * dt_s / 3);
  Q.topRightCorner<3, 3>().diagonal().setConstant(process_noise * dt2 / 2);
  Q.bottomLeftCorner<3, 3>().diagonal().setConstant(process_noise * dt2 / 2);
  Q.bottomRightCorner<3, 3>().diagonal().setConstant(process_noise * dt_s);
  P_ = F * P_ * F.transpose() + Q;
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
