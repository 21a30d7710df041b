// LocalNed (the flat-earth frame of `stevi avoid`) against GeographicLib: points placed with
// Geodesic::Direct at a known distance and azimuth, their true north-east-down coordinates from
// LocalCartesian (east-north-up, rigorous on the WGS84 ellipsoid). The client does not link
// GeographicLib; only this test does.
#include "client/advisory/local_ned.h"

#include <gtest/gtest.h>

#include <GeographicLib/Geodesic.hpp>
#include <GeographicLib/LocalCartesian.hpp>
#include <algorithm>
#include <cmath>
#include <iomanip>
#include <iostream>
#include <numbers>

namespace stevi::client {
namespace {

constexpr double kEarthRadiusM = 6371000;  // the mean radius: the bounds' R
constexpr double kLonDeg = 10.4;

// The true NED coordinates of `point` at `origin`.
Ned TrueNed(const GeoPoint& origin, const GeoPoint& point) {
  const GeographicLib::LocalCartesian frame(origin.lat_deg, origin.lon_deg, origin.alt_m);
  double east = 0, north = 0, up = 0;
  frame.Forward(point.lat_deg, point.lon_deg, point.alt_m, east, north, up);
  return {north, east, -up};
}

// The point `distance_m` from `from` along `azimuth_deg`, `dh_m` higher.
GeoPoint Direct(const GeoPoint& from, double azimuth_deg, double distance_m, double dh_m) {
  GeoPoint to{0, 0, from.alt_m + dh_m};
  GeographicLib::Geodesic::WGS84().Direct(from.lat_deg, from.lon_deg, azimuth_deg, distance_m,
                                          to.lat_deg, to.lon_deg);
  return to;
}

double Horizontal(const Ned& a, const Ned& b) { return std::hypot(a.n - b.n, a.e - b.e); }

double TanLat(double lat_deg) { return std::tan(std::abs(lat_deg) * std::numbers::pi / 180); }

TEST(LocalNed, TheOriginIsZeroAndHeightIsDown) {
  const GeoPoint origin{43.7, kLonDeg, 120};
  EXPECT_EQ(LocalNed(origin, origin), (Ned{0, 0, 0}));
  const Ned above = LocalNed(origin, {43.7, kLonDeg, 170});
  EXPECT_DOUBLE_EQ(above.n, 0);
  EXPECT_DOUBLE_EQ(above.e, 0);
  EXPECT_DOUBLE_EQ(above.d, -50);
}

TEST(LocalNed, AxesPointNorthAndEast) {
  const GeoPoint origin{-33.9, 151.2, 0};
  const Ned north = LocalNed(origin, Direct(origin, 0, 200, 0));
  EXPECT_NEAR(north.n, 200, 0.01);
  EXPECT_NEAR(north.e, 0, 1e-9);
  const Ned east = LocalNed(origin, Direct(origin, 90, 200, 0));
  EXPECT_NEAR(east.n, 0, 0.01);
  EXPECT_NEAR(east.e, 200, 0.01);
  const Ned south_west = LocalNed(origin, Direct(origin, 225, 200, 0));
  EXPECT_LT(south_west.n, 0);
  EXPECT_LT(south_west.e, 0);
}

// Up to 85 degrees of latitude, at any height and in any direction, at the distances of an obstacle
// picture and beyond: within (1 + tan|lat|) s^2 / (2 R) + s |dh| / R horizontally (10 % for the
// higher orders) and s^2 / (2 R) vertically (2 % for the ellipsoid's smaller radii), plus 1 mm.
TEST(LocalNed, MatchesGeographicLibWithinTheCurvatureBound) {
  std::cout << "  distance m   max horizontal error m   max vertical error m   s^2/2R m\n";
  for (const double s : {10.0, 100.0, 300.0, 1000.0, 3000.0, 10000.0}) {
    double worst_h = 0, worst_v = 0;
    for (const double lat : {0.0, 20.0, 43.7, 60.0, 70.0, 80.0, 85.0, -45.0, -85.0}) {
      for (const double alt : {0.0, 3000.0}) {
        for (const double dh : {-100.0, 0.0, 300.0}) {
          for (double azimuth = 0; azimuth < 360; azimuth += 15) {
            const GeoPoint origin{lat, kLonDeg, alt};
            const GeoPoint point = Direct(origin, azimuth, s, dh);
            const Ned got = LocalNed(origin, point);
            const Ned truth = TrueNed(origin, point);
            const double curvature = s * s / (2 * kEarthRadiusM);
            const double h_bound =
                1.1 * (1 + TanLat(lat)) * curvature + s * std::abs(dh) / kEarthRadiusM + 1e-3;
            ASSERT_LE(Horizontal(got, truth), h_bound)
                << "lat " << lat << " alt " << alt << " dh " << dh << " azimuth " << azimuth
                << " s " << s;
            ASSERT_LE(std::abs(got.d - truth.d), 1.02 * curvature + 1e-3)
                << "lat " << lat << " alt " << alt << " dh " << dh << " azimuth " << azimuth
                << " s " << s;
            if (std::abs(lat) <= 60) worst_h = std::max(worst_h, Horizontal(got, truth));
            worst_v = std::max(worst_v, std::abs(got.d - truth.d));
          }
        }
      }
    }
    std::cout << std::fixed << std::setprecision(0) << std::setw(12) << s << std::setprecision(4)
              << std::setw(25) << worst_h << std::setw(23) << worst_v << std::setw(11)
              << s * s / (2 * kEarthRadiusM) << "  (horizontal: |lat| <= 60)\n";
  }
}

// What `stevi avoid` uses: the origin is the vehicle's first position, and the advisor looks at
// obstacle minus vehicle. After the vehicle has flown D from the origin, that vector for an
// obstacle r away is off by about (1 + tan|lat|) (D / R) r, the tilt of the flat frame there: 0.14
// % of r after 5 km at 60 degrees, against the true NED vector at the vehicle.
TEST(LocalNed, ObstacleMinusVehicleDriftsWithTheDistanceFromTheOrigin) {
  for (const double flown : {0.0, 1000.0, 5000.0, 20000.0}) {
    for (const double r : {100.0, 500.0, 1000.0}) {
      double worst = 0;
      for (const double lat : {0.0, 43.7, 60.0, -33.9}) {
        for (double heading = 0; heading < 360; heading += 45) {
          for (double bearing = 0; bearing < 360; bearing += 30) {
            const GeoPoint origin{lat, kLonDeg, 100};
            const GeoPoint vehicle = Direct(origin, heading, flown, 0);
            const GeoPoint obstacle = Direct(vehicle, bearing, r, 20);
            const Ned v = LocalNed(origin, vehicle), o = LocalNed(origin, obstacle);
            const Ned truth = TrueNed(vehicle, obstacle);
            const double error =
                std::sqrt(std::pow(o.n - v.n - truth.n, 2) + std::pow(o.e - v.e - truth.e, 2) +
                          std::pow(o.d - v.d - truth.d, 2));
            const double bound = 1.1 * (1 + TanLat(lat)) *
                                     (flown / kEarthRadiusM * r + r * r / (2 * kEarthRadiusM)) +
                                 1e-3;
            ASSERT_LE(error, bound) << "lat " << lat << " flown " << flown << " r " << r;
            worst = std::max(worst, error);
          }
        }
      }
      std::cout << "  flown " << std::setw(7) << std::setprecision(0) << flown << " m, obstacle at "
                << std::setw(5) << r << " m: obstacle - vehicle off by up to "
                << std::setprecision(3) << worst << " m (" << 100 * worst / r << " %)\n";
    }
  }
}

TEST(LocalNed, LongitudeWrapsAcrossTheAntimeridian) {
  // Eastwards from just west of it, westwards from just east of it.
  const struct {
    double lon, azimuth;
  } cases[] = {{179.9995, 45}, {179.9995, 90}, {-179.9995, 270}, {-179.9995, 225}};
  for (const auto& c : cases) {
    const GeoPoint origin{10, c.lon, 0};
    const GeoPoint point = Direct(origin, c.azimuth, 500, 0);
    ASSERT_GT(std::abs(point.lon_deg - origin.lon_deg), 180) << "the test must cross it";
    const Ned got = LocalNed(origin, point);
    EXPECT_LT(Horizontal(got, TrueNed(origin, point)), 0.05)
        << "lon " << c.lon << " azimuth " << c.azimuth;
    EXPECT_NEAR(std::hypot(got.n, got.e), 500, 0.05);
  }
}

}  // namespace
}  // namespace stevi::client
