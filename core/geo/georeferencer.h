// Georeferencing: a cam-frame point (and its velocity) -> body -> local NED at the vehicle ->
// WGS84 latitude, longitude and height above the ellipsoid, with its absolute NED velocity and a
// first-order horizontal and vertical 1-sigma. Formulas and choices: core/geo/README.md.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "core/common/error.h"
#include "core/geo/mount.h"
#include "core/geo/vehicle_state.h"

namespace stevi::geo {

// A tracked point in the cam frame (x right, y down, z forward), relative to the left camera.
struct PointInCam {
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();
  // d/dt of position_m as the camera sees it (relative to the camera, in its rotating frame).
  Eigen::Vector3d velocity_mps = Eigen::Vector3d::Zero();
  // Covariance of position_m, cam axes, m^2: symmetric with a non-negative diagonal. See
  // LineOfSightCovariance() and DiagonalCovariance().
  Eigen::Matrix3d covariance_m2 = Eigen::Matrix3d::Zero();
};

// 1-sigma position uncertainty of a georeferenced point, first order.
struct PositionSigma {
  // Along the worst horizontal direction: the square root of the larger eigenvalue of the
  // north-east covariance (the semi-major axis of the 1-sigma error ellipse), metres.
  double horizontal_m = 0;
  double vertical_m = 0;  // the down axis, metres
  // The full covariance in the local NED frame at the vehicle, m^2.
  Eigen::Matrix3d covariance_ned_m2 = Eigen::Matrix3d::Zero();
};

// A georeferenced point.
struct GeoPoint {
  // WGS84, degrees; alt_m is the height above the WGS84 ellipsoid (as VehicleState's).
  double lat_deg = 0;
  double lon_deg = 0;
  double alt_m = 0;
  // The point relative to the vehicle reference point, in the local NED frame there, metres.
  Eigen::Vector3d offset_ned_m = Eigen::Vector3d::Zero();
  // The point's absolute velocity over the ground, NED at the vehicle, m/s: the vehicle's
  // velocity + the rotation of the body (omega x r) + the relative velocity, rotated.
  Eigen::Vector3d velocity_ned_mps = Eigen::Vector3d::Zero();
  PositionSigma sigma{};
};

// Immutable after construction: every method may be called concurrently.
class Georeferencer {
 public:
  // The mount must be valid (call Validate() first): an invalid mount is a programming error
  // (std::invalid_argument listing the problems).
  explicit Georeferencer(MountOptions mount = {});

  // Georeferences one point with the vehicle pose at its frame's time. Refused
  // (kInvalidArgument, naming the fields) when the pose is invalid or the point, its velocity or
  // its covariance is not finite, or the covariance is not symmetric with a non-negative diagonal.
  Result<GeoPoint> Georeference(const VehiclePose& pose, const PointInCam& point) const;

  // The point relative to the vehicle reference point in the local NED frame:
  // ned_from_body * (body_from_cam * p + lever_arm).
  Eigen::Vector3d OffsetNed(const VehicleState& state,
                            const Eigen::Vector3d& position_in_cam_m) const;

  // First-order propagation of the point's cam-frame covariance and the vehicle's accuracy
  // (state.sigma) into NED, and its horizontal and vertical 1-sigma:
  //   C_ned = R C_cam R^T + [r]x J S J^T [r]x^T + diag(sh^2, sh^2, sv^2),
  // R = ned_from_cam, r = OffsetNed(), S = diag(tilt^2, tilt^2, yaw^2) (radians) on (roll, pitch,
  // yaw) and J the Jacobian of the NED rotation vector on them (README.md). The mounting is taken
  // as exact.
  PositionSigma Sigma(const VehicleState& state, const Eigen::Vector3d& position_in_cam_m,
                      const Eigen::Matrix3d& covariance_in_cam_m2) const;

  // The inverse: where the WGS84 point (lat, lon, height above the ellipsoid) is in the cam frame.
  Eigen::Vector3d PointInCamOf(const VehicleState& state, double lat_deg, double lon_deg,
                               double alt_m) const;

  const MountOptions& mount() const { return mount_; }
  const Eigen::Matrix3d& body_from_cam() const { return body_from_cam_; }

 private:
  MountOptions mount_;
  Eigen::Matrix3d body_from_cam_;
};

// The covariance of a stereo point in the cam frame: `range_sigma_m` along the line of sight and
// range * pixel_sigma_px / focal_px across it (both lateral axes), m^2. The point must not be the
// origin.
Eigen::Matrix3d LineOfSightCovariance(const Eigen::Vector3d& position_in_cam_m,
                                      double range_sigma_m, double pixel_sigma_px, double focal_px);

// A diagonal covariance from per-axis 1-sigmas (tracking::Track::position_sigma_m), m^2.
Eigen::Matrix3d DiagonalCovariance(const cv::Vec3d& sigma_m);

}  // namespace stevi::geo
