// How the stereo rig is mounted on the vehicle: body_from_cam, from the cam frame (the rectified
// left camera: x right, y down, z forward) to the body frame (x forward, y right, z down).
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "core/common/fields.h"

namespace stevi::geo {

// The camera's orientation relative to the body, as Z-Y-X Euler angles in degrees (the
// VehicleState convention applied to the camera's forward-right-down axes: z, x, y of the cam
// frame), and its position. All zero: looking forward along the body x axis, level, image rows
// along the body y axis (cam z -> body x, cam x -> body y, cam y -> body z).
struct MountOptions {
  // About the optical axis; positive rolls the camera's right side down (as the vehicle's roll
  // does), [-180, 180].
  double roll_deg = 0;
  // Optical axis up positive; -90 looks straight down, [-90, 90].
  double pitch_deg = 0;
  // Optical axis to the right positive; 90 looks along body y (right), [-180, 180].
  double yaw_deg = 0;
  // The left camera's optical centre in the body frame, metres from the vehicle reference point
  // (the point VehicleState's position refers to); each component finite and within +-100 m.
  Eigen::Vector3d lever_arm_m = Eigen::Vector3d::Zero();

  // Every problem, as "field: problem (got X)".
  std::vector<std::string> Validate() const;
  bool operator==(const MountOptions&) const = default;

  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Number(s.roll_deg,
             Field("roll_deg", "degrees", "about the optical axis; right side down positive")
                 .In(-180, 180));
    v.Number(s.pitch_deg,
             Field("pitch_deg", "degrees", "optical axis up positive; -90 looks straight down")
                 .In(-90, 90));
    v.Number(s.yaw_deg,
             Field("yaw_deg", "degrees", "optical axis to the right positive").In(-180, 180));
    v.Number(s.lever_arm_m.x(),
             Field("lever_arm_x_m", "m", "left camera's optical centre, body x (forward)")
                 .In(-100, 100));
    v.Number(
        s.lever_arm_m.y(),
        Field("lever_arm_y_m", "m", "left camera's optical centre, body y (right)").In(-100, 100));
    v.Number(
        s.lever_arm_m.z(),
        Field("lever_arm_z_m", "m", "left camera's optical centre, body z (down)").In(-100, 100));
  }
};

// The rotation body_from_cam of a mounting (the options need not be validated; angles are used as
// given).
Eigen::Matrix3d BodyFromCamRotation(const MountOptions& mount);

// The rigid transform body_from_cam: point_in_body = R * point_in_cam + lever_arm_m.
Eigen::Isometry3d BodyFromCam(const MountOptions& mount);

}  // namespace stevi::geo
