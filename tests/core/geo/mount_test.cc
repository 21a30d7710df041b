#include "core/geo/mount.h"

#include <limits>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace stevi::geo {
namespace {

using ::testing::AllOf;
using ::testing::Contains;
using ::testing::HasSubstr;
using ::testing::IsEmpty;
using ::testing::SizeIs;

const Eigen::Vector3d kCamX = Eigen::Vector3d::UnitX();  // right in the image
const Eigen::Vector3d kCamY = Eigen::Vector3d::UnitY();  // down in the image
const Eigen::Vector3d kCamZ = Eigen::Vector3d::UnitZ();  // the optical axis

void ExpectNear(const Eigen::Vector3d& got, const Eigen::Vector3d& want, double tol = 1e-15) {
  EXPECT_LT((got - want).norm(), tol) << "got " << got.transpose() << ", want " << want.transpose();
}

TEST(BodyFromCam, DefaultLooksForwardLevel) {
  const Eigen::Matrix3d r = BodyFromCamRotation({});
  ExpectNear(r * kCamZ, {1, 0, 0});  // optical axis -> forward
  ExpectNear(r * kCamX, {0, 1, 0});  // image right -> right wing
  ExpectNear(r * kCamY, {0, 0, 1});  // image down -> down
  EXPECT_NEAR(r.determinant(), 1.0, 1e-15);
}

TEST(BodyFromCam, YawNinetyLooksRight) {
  const Eigen::Matrix3d r = BodyFromCamRotation({.yaw_deg = 90});
  ExpectNear(r * kCamZ, {0, 1, 0});
  ExpectNear(r * kCamX, {-1, 0, 0});  // image right -> backwards
  ExpectNear(r * kCamY, {0, 0, 1});
}

TEST(BodyFromCam, PitchMinusNinetyLooksDown) {
  const Eigen::Matrix3d r = BodyFromCamRotation({.pitch_deg = -90});
  ExpectNear(r * kCamZ, {0, 0, 1});   // optical axis -> down
  ExpectNear(r * kCamX, {0, 1, 0});   // image right -> right wing
  ExpectNear(r * kCamY, {-1, 0, 0});  // image down -> backwards (image top is forward)
}

TEST(BodyFromCam, RollTurnsAboutTheOpticalAxis) {
  const Eigen::Matrix3d r = BodyFromCamRotation({.roll_deg = 90});
  ExpectNear(r * kCamZ, {1, 0, 0});
  ExpectNear(r * kCamX, {0, 0, 1});  // right side down
  ExpectNear(r * kCamY, {0, -1, 0});
}

TEST(BodyFromCam, TransformAddsTheLeverArm) {
  const MountOptions mount{.yaw_deg = 90, .lever_arm_m = {0.5, -0.2, 0.1}};
  const Eigen::Isometry3d t = BodyFromCam(mount);
  ExpectNear(t * Eigen::Vector3d(0, 0, 10), Eigen::Vector3d(0.5, 9.8, 0.1), 1e-13);
}

TEST(MountOptionsValidate, DefaultIsValid) { EXPECT_THAT(MountOptions{}.Validate(), IsEmpty()); }

TEST(MountOptionsValidate, NamesEveryBadField) {
  MountOptions m;
  m.roll_deg = 200;
  m.pitch_deg = -91;
  m.yaw_deg = std::numeric_limits<double>::quiet_NaN();
  m.lever_arm_m = {150, std::numeric_limits<double>::infinity(), 0.3};  // mm, not m; inf
  const std::vector<std::string> problems = m.Validate();
  EXPECT_THAT(problems, SizeIs(5));
  EXPECT_THAT(problems, Contains(AllOf(HasSubstr("roll_deg: must be in [-180, 180]"),
                                       HasSubstr("(got 200)"))));
  EXPECT_THAT(problems, Contains(AllOf(HasSubstr("pitch_deg: must be in [-90, 90]"),
                                       HasSubstr("(got -91)"))));
  EXPECT_THAT(problems, Contains(AllOf(HasSubstr("yaw_deg:"), HasSubstr("(got nan)"))));
  EXPECT_THAT(problems, Contains(AllOf(HasSubstr("lever_arm_x_m: must be in [-100, 100] m"),
                                       HasSubstr("(got 150)"))));
  EXPECT_THAT(problems, Contains(AllOf(HasSubstr("lever_arm_y_m:"), HasSubstr("(got inf)"))));
}

}  // namespace
}  // namespace stevi::geo
