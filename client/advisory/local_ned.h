// WGS84 positions to a local north-east-down frame, for `stevi avoid`. The standard library only.
#pragma once

#include "client/advisory/avoid.h"

namespace stevi::client {

// A WGS84 position: degrees, and metres above the ellipsoid.
struct GeoPoint {
  double lat_deg = 0;
  double lon_deg = 0;
  double alt_m = 0;
};

// `point` in metres north, east and down of `origin`: a flat earth with the ellipsoid's radii of
// curvature at the origin's latitude and height (longitude differences wrap across the
// antimeridian). It leaves out the earth's curvature and the point's own height, so at a distance
// s, with R the earth's radius and dh the height difference, the error is at most about
// (1 + tan|lat|) s^2 / (2 R) + s |dh| / R horizontally and s^2 / (2 R) vertically (up to 85
// degrees of latitude): millimetres at 100 m, centimetres at 300 m, decimetres at 1 km (half a
// metre at 80 degrees). tests/client/local_ned_test.cc holds it to that against GeographicLib.
Ned LocalNed(const GeoPoint& origin, const GeoPoint& point);

}  // namespace stevi::client
