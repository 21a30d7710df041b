#include "core/geo/mount.h"

#include "core/geo/vehicle_state.h"

namespace stevi::geo {

std::vector<std::string> MountOptions::Validate() const { return fields::Check(*this); }

Eigen::Matrix3d BodyFromCamRotation(const MountOptions& mount) {
  // The camera's forward-right-down axes (cam z, x, y) relative to the body: columns are the cam
  // axes x, y, z in the camera's FRD frame.
  Eigen::Matrix3d frd_from_cam;
  frd_from_cam << 0, 0, 1,  //
      1, 0, 0,              //
      0, 1, 0;
  const Eigen::Matrix3d body_from_frd =
      NedFromBody(mount.roll_deg, mount.pitch_deg, mount.yaw_deg).toRotationMatrix();
  return body_from_frd * frd_from_cam;
}

Eigen::Isometry3d BodyFromCam(const MountOptions& mount) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = BodyFromCamRotation(mount);
  t.translation() = mount.lever_arm_m;
  return t;
}

}  // namespace stevi::geo
