#include "client/advisory/track_points.h"

namespace stevi::client {

void CollectTrackPoints(const v1::TrackFrame& frame, std::vector<TrackPoint>& points) {
  for (const v1::Track& t : frame.tracks()) {
    if (!t.has_geodetic() || t.state() == v1::TRACK_STATE_TENTATIVE) continue;
    TrackPoint p;
    p.track_id = t.track_id();
    p.unix_time_ns = frame.capture_unix_time_ns();
    p.lat_deg = t.geodetic().lat_deg();
    p.lon_deg = t.geodetic().lon_deg();
    p.alt_m = t.geodetic().alt_m();
    if (t.has_position_sigma_m()) p.horizontal_sigma_m = t.position_sigma_m().horizontal_m();
    points.push_back(p);
  }
}

}  // namespace stevi::client
