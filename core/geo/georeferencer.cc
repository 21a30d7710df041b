#include "core/geo/georeferencer.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <utility>

#include <GeographicLib/LocalCartesian.hpp>

namespace stevi::geo {
namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;

const MountOptions& Checked(const MountOptions& mount) {
  if (std::vector<std::string> problems = mount.Validate(); !problems.empty()) {
    throw std::invalid_argument("MountOptions: " + InvalidArgument(problems).message);
  }
  return mount;
}

Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d s;
  s << 0, -v.z(), v.y(),  //
      v.z(), 0, -v.x(),   //
      -v.y(), v.x(), 0;
  return s;
}

}  // namespace

Georeferencer::Georeferencer(MountOptions mount)
    : mount_(Checked(mount)), body_from_cam_(BodyFromCamRotation(mount_)) {}

Eigen::Vector3d Georeferencer::OffsetNed(const VehicleState& state,
                                         const Eigen::Vector3d& position_in_cam_m) const {
  return NedFromBody(state) * (body_from_cam_ * position_in_cam_m + mount_.lever_arm_m);
}

PositionSigma Georeferencer::Sigma(const VehicleState& state,
                                   const Eigen::Vector3d& position_in_cam_m,
                                   const Eigen::Matrix3d& covariance_in_cam_m2) const {
  const Eigen::Matrix3d ned_from_body = NedFromBody(state).toRotationMatrix();
  const Eigen::Matrix3d ned_from_cam = ned_from_body * body_from_cam_;
  const Eigen::Vector3d r =
      ned_from_body * (body_from_cam_ * position_in_cam_m + mount_.lever_arm_m);

  // Attitude: d(ned_from_body) = [dtheta]x ned_from_body with dtheta = J (droll, dpitch, dyaw),
  // J = [Rz(yaw) Ry(pitch) e_x, Rz(yaw) e_y, e_z]; the point moves by dtheta x r = -[r]x dtheta.
  const Eigen::Matrix3d rz =
      Eigen::AngleAxisd(state.yaw_deg * kDegToRad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const Eigen::Matrix3d ry =
      Eigen::AngleAxisd(state.pitch_deg * kDegToRad, Eigen::Vector3d::UnitY()).toRotationMatrix();
  Eigen::Matrix3d j;
  j.col(0) = rz * ry * Eigen::Vector3d::UnitX();
  j.col(1) = rz * Eigen::Vector3d::UnitY();
  j.col(2) = Eigen::Vector3d::UnitZ();
  const double tilt = state.sigma.tilt_deg * kDegToRad;
  const double yaw = state.sigma.yaw_deg * kDegToRad;
  const Eigen::Matrix3d attitude_cov =
      j * Eigen::Vector3d(tilt * tilt, tilt * tilt, yaw * yaw).asDiagonal() * j.transpose();
  const Eigen::Matrix3d lever = Skew(r);

  PositionSigma sigma;
  Eigen::Matrix3d& c = sigma.covariance_ned_m2;
  c = ned_from_cam * covariance_in_cam_m2 * ned_from_cam.transpose() +
      lever * attitude_cov * lever.transpose();
  const double h2 = state.sigma.horizontal_m * state.sigma.horizontal_m;
  c(0, 0) += h2;
  c(1, 1) += h2;
  c(2, 2) += state.sigma.vertical_m * state.sigma.vertical_m;
  c = 0.5 * (c + c.transpose()).eval();

  // The larger eigenvalue of the north-east block.
  const double mean = 0.5 * (c(0, 0) + c(1, 1));
  const double half_diff = 0.5 * (c(0, 0) - c(1, 1));
  const double major = mean + std::hypot(half_diff, c(0, 1));
  sigma.horizontal_m = std::sqrt(std::max(0.0, major));
  sigma.vertical_m = std::sqrt(std::max(0.0, c(2, 2)));
  return sigma;
}

Result<GeoPoint> Georeferencer::Georeference(const VehiclePose& pose,
                                             const PointInCam& point) const {
  std::vector<std::string> problems;
  AppendPrefixed(problems, "pose.state.", pose.state.Validate());
  if (!pose.angular_rate_body_rps.allFinite()) {
    problems.push_back("pose.angular_rate_body_rps: must be finite");
  }
  if (!point.position_m.allFinite()) problems.push_back("point.position_m: must be finite");
  if (!point.velocity_mps.allFinite()) problems.push_back("point.velocity_mps: must be finite");
  const Eigen::Matrix3d& cov = point.covariance_m2;
  if (!cov.allFinite()) {
    problems.push_back("point.covariance_m2: must be finite");
  } else {
    const double scale = std::max(1.0, cov.cwiseAbs().maxCoeff());
    if ((cov - cov.transpose()).cwiseAbs().maxCoeff() > 1e-9 * scale ||
        (cov.diagonal().array() < 0).any()) {
      problems.push_back("point.covariance_m2: must be symmetric with a non-negative diagonal");
    }
  }
  if (!problems.empty()) return InvalidArgument(problems);

  const VehicleState& state = pose.state;
  const Eigen::Matrix3d ned_from_body = NedFromBody(state).toRotationMatrix();
  const Eigen::Vector3d in_body = body_from_cam_ * point.position_m + mount_.lever_arm_m;

  GeoPoint out;
  out.offset_ned_m = ned_from_body * in_body;
  // The tangent plane at the vehicle, east-north-up, to WGS84: exact (through geocentric).
  const GeographicLib::LocalCartesian local(state.lat_deg, state.lon_deg, state.alt_m);
  local.Reverse(out.offset_ned_m.y(), out.offset_ned_m.x(), -out.offset_ned_m.z(), out.lat_deg,
                out.lon_deg, out.alt_m);
  // d/dt (p_vehicle + R r_body) = v_vehicle + R (omega x r_body + dr_body/dt).
  out.velocity_ned_mps =
      state.velocity_ned_mps + ned_from_body * (pose.angular_rate_body_rps.cross(in_body) +
                                                body_from_cam_ * point.velocity_mps);
  out.sigma = Sigma(state, point.position_m, cov);
  return out;
}

Eigen::Vector3d Georeferencer::PointInCamOf(const VehicleState& state, double lat_deg,
                                            double lon_deg, double alt_m) const {
  const GeographicLib::LocalCartesian local(state.lat_deg, state.lon_deg, state.alt_m);
  double e = 0, n = 0, u = 0;
  local.Forward(lat_deg, lon_deg, alt_m, e, n, u);
  const Eigen::Vector3d in_body = NedFromBody(state).conjugate() * Eigen::Vector3d(n, e, -u);
  return body_from_cam_.transpose() * (in_body - mount_.lever_arm_m);
}

Eigen::Matrix3d LineOfSightCovariance(const Eigen::Vector3d& position_in_cam_m,
                                      double range_sigma_m, double pixel_sigma_px,
                                      double focal_px) {
  const double range = position_in_cam_m.norm();
  const Eigen::Vector3d ray = position_in_cam_m / range;
  const Eigen::Matrix3d along = ray * ray.transpose();
  const double lateral = range * pixel_sigma_px / focal_px;
  return range_sigma_m * range_sigma_m * along +
         lateral * lateral * (Eigen::Matrix3d::Identity() - along);
}

Eigen::Matrix3d DiagonalCovariance(const cv::Vec3d& sigma_m) {
  return Eigen::Vector3d(sigma_m[0] * sigma_m[0], sigma_m[1] * sigma_m[1], sigma_m[2] * sigma_m[2])
      .asDiagonal();
}

}  // namespace stevi::geo
