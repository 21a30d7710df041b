#include "core/geo/vehicle_state.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>

#include "core/common/error.h"

namespace stevi::geo {
namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;
constexpr double kRadToDeg = 180.0 / std::numbers::pi;

// False for NaN.
bool InRange(double value, double lo, double hi) { return value >= lo && value <= hi; }

void CheckSigma(std::vector<std::string>& problems, const char* name, double value,
                const char* unit) {
  if (!(std::isfinite(value) && value >= 0)) {
    std::string p = name;
    p += ": must be >= 0 ";
    p += unit;
    p += " and finite";
    p += Got(value);
    problems.push_back(std::move(p));
  }
}

void CheckRange(std::vector<std::string>& problems, const char* name, double value, double lo,
                double hi, const char* unit) {
  if (!InRange(value, lo, hi)) {
    char buf[160];
    std::snprintf(buf, sizeof buf, "%s: must be in [%g, %g] %s", name, lo, hi, unit);
    std::string p = buf;
    p += Got(value);
    problems.push_back(std::move(p));
  }
}

// Maps an angle in degrees to (-180, 180].
double WrapDeg(double deg) {
  double wrapped = std::remainder(deg, 360.0);
  if (wrapped <= -180.0) wrapped += 360.0;
  return wrapped;
}

}  // namespace

std::vector<std::string> PoseSigma::Validate() const {
  std::vector<std::string> problems;
  CheckSigma(problems, "horizontal_m", horizontal_m, "metres");
  CheckSigma(problems, "vertical_m", vertical_m, "metres");
  CheckSigma(problems, "tilt_deg", tilt_deg, "degrees");
  CheckSigma(problems, "yaw_deg", yaw_deg, "degrees");
  return problems;
}

std::vector<std::string> VehicleState::Validate() const {
  std::vector<std::string> problems;
  CheckRange(problems, "lat_deg", lat_deg, -90, 90, "degrees");
  CheckRange(problems, "lon_deg", lon_deg, -180, 180, "degrees");
  CheckRange(problems, "alt_m", alt_m, -1000, 100000, "metres above the WGS84 ellipsoid");
  CheckRange(problems, "roll_deg", roll_deg, -180, 180, "degrees");
  CheckRange(problems, "pitch_deg", pitch_deg, -90, 90, "degrees");
  CheckRange(problems, "yaw_deg", yaw_deg, -360, 360, "degrees");
  static constexpr const char* kVelocityNames[3] = {"velocity_ned_mps.n", "velocity_ned_mps.e",
                                                    "velocity_ned_mps.d"};
  for (int i = 0; i < 3; ++i) {
    if (!std::isfinite(velocity_ned_mps[i])) {
      std::string p = kVelocityNames[i];
      p += ": must be finite";
      p += Got(velocity_ned_mps[i]);
      problems.push_back(std::move(p));
    }
  }
  AppendPrefixed(problems, "sigma.", sigma.Validate());
  return problems;
}

Eigen::Quaterniond NedFromBody(double roll_deg, double pitch_deg, double yaw_deg) {
  const Eigen::AngleAxisd yaw(yaw_deg * kDegToRad, Eigen::Vector3d::UnitZ());
  const Eigen::AngleAxisd pitch(pitch_deg * kDegToRad, Eigen::Vector3d::UnitY());
  const Eigen::AngleAxisd roll(roll_deg * kDegToRad, Eigen::Vector3d::UnitX());
  return Eigen::Quaterniond(yaw * pitch * roll).normalized();
}

Eigen::Quaterniond NedFromBody(const VehicleState& state) {
  return NedFromBody(state.roll_deg, state.pitch_deg, state.yaw_deg);
}

EulerDeg EulerFromNedFromBody(const Eigen::Quaterniond& ned_from_body) {
  const Eigen::Matrix3d r = ned_from_body.normalized().toRotationMatrix();
  EulerDeg e;
  const double sin_pitch = std::clamp(-r(2, 0), -1.0, 1.0);
  e.pitch_deg = std::asin(sin_pitch) * kRadToDeg;
  if (std::hypot(r(2, 1), r(2, 2)) < 1e-12) {
    // Gimbal lock: only yaw - roll (pitch up) or yaw + roll (pitch down) is defined; roll = 0.
    e.roll_deg = 0;
    e.yaw_deg = WrapDeg(std::atan2(-r(0, 1), r(1, 1)) * kRadToDeg);
  } else {
    e.roll_deg = WrapDeg(std::atan2(r(2, 1), r(2, 2)) * kRadToDeg);
    e.yaw_deg = WrapDeg(std::atan2(r(1, 0), r(0, 0)) * kRadToDeg);
  }
  return e;
}

}  // namespace stevi::geo
