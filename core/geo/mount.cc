#include "core/geo/mount.h"

#include <cmath>
#include <cstdio>

#include "core/common/error.h"
#include "core/geo/vehicle_state.h"

namespace stevi::geo {
namespace {

void CheckRange(std::vector<std::string>& problems, const char* name, double value, double lo,
                double hi, const char* unit) {
  if (!(value >= lo && value <= hi)) {  // NaN fails
    char buf[160];
    std::snprintf(buf, sizeof buf, "%s: must be in [%g, %g] %s", name, lo, hi, unit);
    std::string p = buf;
    p += Got(value);
    problems.push_back(std::move(p));
  }
}

}  // namespace

std::vector<std::string> MountOptions::Validate() const {
  std::vector<std::string> problems;
  CheckRange(problems, "roll_deg", roll_deg, -180, 180, "degrees");
  CheckRange(problems, "pitch_deg", pitch_deg, -90, 90, "degrees");
  CheckRange(problems, "yaw_deg", yaw_deg, -180, 180, "degrees");
  static constexpr const char* kNames[3] = {"lever_arm_x_m", "lever_arm_y_m", "lever_arm_z_m"};
  for (int i = 0; i < 3; ++i) {
    CheckRange(problems, kNames[i], lever_arm_m[i], -100, 100, "metres (body frame)");
  }
  return problems;
}

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
