#include "client/advisory/local_ned.h"

#include <cmath>
#include <numbers>

namespace stevi::client {

Ned LocalNed(const GeoPoint& origin, const GeoPoint& point) {
  constexpr double a = 6378137.0, e2 = 6.69437999014e-3, deg = std::numbers::pi / 180;
  const double s = std::sin(origin.lat_deg * deg);
  const double w = std::sqrt(1 - e2 * s * s);
  const double meridian = a * (1 - e2) / (w * w * w), normal = a / w;
  double dlon = point.lon_deg - origin.lon_deg;
  if (dlon > 180) dlon -= 360;
  if (dlon < -180) dlon += 360;
  return {(point.lat_deg - origin.lat_deg) * deg * (meridian + origin.alt_m),
          dlon * deg * (normal + origin.alt_m) * std::cos(origin.lat_deg * deg),
          origin.alt_m - point.alt_m};
}

}  // namespace stevi::client
