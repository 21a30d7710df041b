// Ego-motion (tracker.h, "Ego-motion" in README.md): every track carried through the camera's
// motion into this frame's cam frame, its velocity kept over the ground, and back to relative to
// the camera when the poses drop out.
#include <cmath>

#include "core/tracking/tracker.h"

namespace stevi::tracking {

namespace {

// The cross-product matrix [w]x.
Eigen::Matrix3d Skew(const Eigen::Vector3d& w) {
  Eigen::Matrix3d m;
  m << 0, -w.z(), w.y(), w.z(), 0, -w.x(), -w.y(), w.x(), 0;
  return m;
}

}  // namespace

Tracker::ApparentMotion Tracker::ApparentMotionOf(const Eigen::Isometry3d& cam_now_from_cam_prev,
                                                  double dt) {
  // The logarithm of the rigid motion: rotation vector phi (angle theta) and the translation's
  // generator V^-1 t, V^-1 = I - W / 2 + (1 - theta sin(theta) / (2 (1 - cos(theta)))) W^2 /
  // theta^2 with W = [phi]x (I - W / 2 + W^2 / 12 for a small angle).
  const Eigen::AngleAxisd angle_axis(cam_now_from_cam_prev.linear());
  const double theta = angle_axis.angle();
  const Eigen::Vector3d phi = theta * angle_axis.axis();
  const Eigen::Matrix3d W = Skew(phi);
  double k = 1.0 / 12;
  if (theta > 1e-4)
    k = (1 - theta * std::sin(theta) / (2 * (1 - std::cos(theta)))) / (theta * theta);
  const Eigen::Matrix3d V_inv = Eigen::Matrix3d::Identity() - 0.5 * W + k * W * W;
  return {.linear = W / dt, .offset = V_inv * cam_now_from_cam_prev.translation() / dt};
}

void Tracker::ApplyEgoMotion(const EgoMotion& ego, double dt) {
  using Matrix6 = Eigen::Matrix<double, 6, 6>;
  using Vector6 = Eigen::Matrix<double, 6, 1>;
  const Eigen::Matrix3d R = ego.cam_now_from_cam_prev.linear();
  const Eigen::Vector3d t = ego.cam_now_from_cam_prev.translation();
  if (dt > 0) {
    const ApparentMotion apparent = ApparentMotionOf(ego.cam_now_from_cam_prev, dt);
    apparent_linear_ = apparent.linear;
    apparent_offset_ = apparent.offset;
  }
  // Relative velocities (the last update had no ego-motion) lose the apparent velocity of a static
  // point, A p + c, and are over the ground; then position and velocity turn with the camera. A
  // track started at the last update has no velocity of its own yet (the prior, at rest): it starts
  // at rest over the ground instead.
  const bool to_ground = !ground_velocity_ && dt > 0;
  Matrix6 rigid = Matrix6::Zero();
  rigid.topLeftCorner<3, 3>() = R;
  rigid.bottomRightCorner<3, 3>() = R;
  Vector6 moved = Vector6::Zero();
  moved.head<3>() = t;
  Matrix6 convert = Matrix6::Identity();
  Vector6 convert_offset = Vector6::Zero();
  if (to_ground) {
    convert.bottomLeftCorner<3, 3>() = -apparent_linear_;
    convert_offset.tail<3>() = -apparent_offset_;
  }
  const Matrix6 linear = rigid * convert;
  const Vector6 offset = rigid * convert_offset + moved;
  for (Entry& e : tracks_) {
    if (to_ground && e.age_frames > 1) {
      e.kalman.MapAngleDepth(linear, offset);
    } else {
      e.kalman.MapAngleDepth(rigid, moved);
    }
  }
  if (dt > 0) ground_velocity_ = true;
}

void Tracker::ToRelativeVelocity() {
  Eigen::Matrix<double, 6, 6> linear = Eigen::Matrix<double, 6, 6>::Identity();
  linear.bottomLeftCorner<3, 3>() = apparent_linear_;
  Eigen::Matrix<double, 6, 1> offset = Eigen::Matrix<double, 6, 1>::Zero();
  offset.tail<3>() = apparent_offset_;
  for (Entry& e : tracks_) e.kalman.MapAngleDepth(linear, offset);
  ground_velocity_ = false;
}

}  // namespace stevi::tracking
