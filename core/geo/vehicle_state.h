// The vehicle's navigation state (WGS84 position, NED attitude and velocity, accuracy) and its
// attitude conventions. Frames and datums: core/geo/README.md.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace stevi::geo {

// 1-sigma accuracy of a VehicleState, as the navigation solution reports it. All >= 0 and finite.
struct PoseSigma {
  double horizontal_m = 0;  // position, per horizontal axis (north and east each), metres
  double vertical_m = 0;    // position, down axis, metres
  double tilt_deg = 0;      // roll and pitch each, degrees
  double yaw_deg = 0;       // heading, degrees

  // Every problem, as "field: problem (got X)".
  std::vector<std::string> Validate() const;
  bool operator==(const PoseSigma&) const = default;
};

// The vehicle's state at one instant: the position of its reference point (the point the
// navigation solution refers to, e.g. the IMU or the GNSS antenna), its attitude and velocity.
struct VehicleState {
  // Time of validity, nanoseconds, on the clock frames are looked up with (the pipeline asks with
  // the frame's capture_unix_time_ns: Unix time, which a GNSS-disciplined autopilot shares).
  int64_t t_ns = 0;
  // WGS84 geodetic position, degrees. lat in [-90, 90], lon in [-180, 180].
  double lat_deg = 0;
  double lon_deg = 0;
  // Height above the WGS84 ellipsoid (not mean sea level: MSL height = alt_m - geoid undulation),
  // metres, in [-1000, 100000] (a millimetre value from an autopilot fails this).
  double alt_m = 0;
  // Attitude, degrees: aerospace Z-Y-X Euler angles, ned_from_body = Rz(yaw) Ry(pitch) Rx(roll),
  // body = forward-right-down. roll: right wing down positive, [-180, 180]; pitch: nose up
  // positive, [-90, 90]; yaw: heading from true north, clockwise (90 = east), [-360, 360].
  double roll_deg = 0;
  double pitch_deg = 0;
  double yaw_deg = 0;
  // Velocity of the reference point over the ground: north, east, down, m/s; finite.
  Eigen::Vector3d velocity_ned_mps = Eigen::Vector3d::Zero();
  PoseSigma sigma{};

  // Every problem, as "field: problem (got X)" ("lat_deg: must be in [-90, 90] degrees (got 91)").
  std::vector<std::string> Validate() const;
  bool operator==(const VehicleState&) const = default;
};

// A VehicleState as the georeferencer uses it: the state at the frame's time and the body's
// angular rate there (for the velocity of a body-fixed point, omega x r).
struct VehiclePose {
  VehicleState state{};
  // Angular rate of the body relative to NED, body (FRD) axes, rad/s. Zero when unknown (a fixed
  // pose, a single state).
  Eigen::Vector3d angular_rate_body_rps = Eigen::Vector3d::Zero();
  // True when `state` was extrapolated past the newest state (PoseBuffer).
  bool extrapolated = false;
};

// The rotation ned_from_body of Z-Y-X Euler angles in degrees (VehicleState's convention; also
// MountOptions's, for the camera relative to the body).
Eigen::Quaterniond NedFromBody(double roll_deg, double pitch_deg, double yaw_deg);
Eigen::Quaterniond NedFromBody(const VehicleState& state);

struct EulerDeg {
  double roll_deg = 0;   // (-180, 180]
  double pitch_deg = 0;  // [-90, 90]
  double yaw_deg = 0;    // (-180, 180]
};

// The Z-Y-X Euler angles of a rotation ned_from_body (inverse of NedFromBody away from pitch = +-90
// degrees, where roll and yaw are not separable and roll is set to 0).
EulerDeg EulerFromNedFromBody(const Eigen::Quaterniond& ned_from_body);

}  // namespace stevi::geo
