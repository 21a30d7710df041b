// Independent references for the core/geo tests: the direction cosine matrix written out, the
// local-level frame from geocentric (ECEF) coordinates, and the camera-to-WGS84 chain computed
// through ECEF rather than GeographicLib::LocalCartesian.
#pragma once

#include <cmath>
#include <numbers>

#include <Eigen/Core>
#include <GeographicLib/Constants.hpp>
#include <GeographicLib/Geocentric.hpp>

namespace stevi::geo::ref {

inline constexpr double kDeg = std::numbers::pi / 180.0;

// C_b^n of aerospace Z-Y-X Euler angles, written out (Titterton & Weston, eq. 3.47).
inline Eigen::Matrix3d ReferenceDcm(double roll_deg, double pitch_deg, double yaw_deg) {
  const double cr = std::cos(roll_deg * kDeg), sr = std::sin(roll_deg * kDeg);
  const double cp = std::cos(pitch_deg * kDeg), sp = std::sin(pitch_deg * kDeg);
  const double cy = std::cos(yaw_deg * kDeg), sy = std::sin(yaw_deg * kDeg);
  Eigen::Matrix3d c;
  c << cp * cy, -cr * sy + sr * sp * cy, sr * sy + cr * sp * cy,  //
      cp * sy, cr * cy + sr * sp * sy, -sr * cy + cr * sp * sy,   //
      -sp, sr * cp, cr * cp;
  return c;
}

// The default mounting written out: cam z -> body x, cam x -> body y, cam y -> body z.
inline Eigen::Matrix3d ReferenceFrdFromCam() {
  Eigen::Matrix3d m;
  m.col(0) = Eigen::Vector3d(0, 1, 0);
  m.col(1) = Eigen::Vector3d(0, 0, 1);
  m.col(2) = Eigen::Vector3d(1, 0, 0);
  return m;
}

// ECEF axes from local NED axes at geodetic (lat, lon): the textbook matrix.
inline Eigen::Matrix3d EcefFromNed(double lat_deg, double lon_deg) {
  const double sl = std::sin(lat_deg * kDeg), cl = std::cos(lat_deg * kDeg);
  const double so = std::sin(lon_deg * kDeg), co = std::cos(lon_deg * kDeg);
  Eigen::Matrix3d m;
  m << -sl * co, -so, -cl * co,  //
      -sl * so, co, -cl * so,    //
      cl, 0, -sl;
  return m;
}

struct Geodetic {
  double lat_deg = 0;
  double lon_deg = 0;
  double alt_m = 0;
};

inline Eigen::Vector3d Ecef(const Geodetic& g) {
  Eigen::Vector3d x;
  GeographicLib::Geocentric::WGS84().Forward(g.lat_deg, g.lon_deg, g.alt_m, x.x(), x.y(), x.z());
  return x;
}

inline Geodetic FromEcef(const Eigen::Vector3d& x) {
  Geodetic g;
  GeographicLib::Geocentric::WGS84().Reverse(x.x(), x.y(), x.z(), g.lat_deg, g.lon_deg, g.alt_m);
  return g;
}

// Where a point at `offset_ned` (metres, local NED at `origin`) is, through ECEF.
inline Geodetic ReferenceFromNed(const Geodetic& origin, const Eigen::Vector3d& offset_ned) {
  return FromEcef(Ecef(origin) + EcefFromNed(origin.lat_deg, origin.lon_deg) * offset_ned);
}

// The local NED offset (metres) of `point` from `origin`, through ECEF.
inline Eigen::Vector3d ReferenceNedOffset(const Geodetic& origin, const Geodetic& point) {
  return EcefFromNed(origin.lat_deg, origin.lon_deg).transpose() * (Ecef(point) - Ecef(origin));
}

// Radius of curvature of the WGS84 normal section at latitude `lat_deg` in azimuth `azi_deg`
// (Euler: 1/R = cos^2(a)/M + sin^2(a)/N).
inline double NormalSectionRadius(double lat_deg, double azi_deg) {
  const double a = GeographicLib::Constants::WGS84_a();
  const double f = GeographicLib::Constants::WGS84_f();
  const double e2 = f * (2 - f);
  const double s = std::sin(lat_deg * kDeg);
  const double w = std::sqrt(1 - e2 * s * s);
  const double m = a * (1 - e2) / (w * w * w);
  const double n = a / w;
  const double ca = std::cos(azi_deg * kDeg), sa = std::sin(azi_deg * kDeg);
  return 1.0 / (ca * ca / m + sa * sa / n);
}

// A point `horizontal_m` away along the tangent plane of a rig at height `alt_m` and `up_m` above
// it, on the osculating sphere of radius `radius_m`: its distance along the ellipsoid surface from
// the rig's foot (metres) and its height above the ellipsoid (metres). The curvature drop is
// hypot(R + h + up, s) - (R + h + up) ~ s^2 / (2 R): 0.78 mm at 100 m.
struct SphereModel {
  double surface_distance_m = 0;
  double alt_m = 0;
};

inline SphereModel OnOsculatingSphere(double radius_m, double alt_m, double horizontal_m,
                                      double up_m) {
  const double centre_to_point = radius_m + alt_m + up_m;
  return SphereModel{radius_m * std::atan2(horizontal_m, centre_to_point),
                     std::hypot(centre_to_point, horizontal_m) - radius_m};
}

}  // namespace stevi::geo::ref
