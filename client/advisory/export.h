// Track trajectories for ground stations, for `stevi export`: KML (Google Earth) and GeoJSON
// (QGIS). Plain structs only (no protobuf): the command maps the stream's or a JSON-lines file's
// tracks onto TrackPoint.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace stevi::client {

// One georeferenced position of one track.
struct TrackPoint {
  std::uint64_t track_id = 0;
  // Capture time on the Unix epoch (UTC), nanoseconds.
  std::int64_t unix_time_ns = 0;
  // WGS84, degrees: lat in [-90, 90], lon in [-180, 180].
  double lat_deg = 0;
  double lon_deg = 0;
  // Height above the WGS84 ellipsoid, metres (as the georeferencer gives it; not mean sea level).
  double alt_m = 0;
  // 1-sigma of the position per horizontal axis, metres, >= 0, when known.
  std::optional<double> horizontal_sigma_m;
};

// True when the point's numbers are finite and within the ranges above.
bool TrackPointIsValid(const TrackPoint& point);

// Every problem of `points`, as "points[3].lat_deg: must be in [-90, 90] degrees (got 91)". The
// exporters leave such points out, so the caller should report these.
std::vector<std::string> ValidateTrackPoints(const std::vector<TrackPoint>& points);

// ISO 8601 UTC with milliseconds, "2024-05-01T12:00:00.123Z" (rounded down to the millisecond,
// also before 1970).
std::string IsoUtc(std::int64_t unix_time_ns);

struct KmlOptions {
  // The Document's name, any text (it is XML-escaped).
  std::string document_name = "stevi tracks";
  // Each Placemark is named this followed by the track id ("track 12"); XML-escaped.
  std::string track_name_prefix = "track ";
  // KML's altitudeMode "absolute" means metres above mean sea level (Google Earth uses EGM96),
  // while TrackPoint::alt_m is above the ellipsoid. The KML altitude is alt_m minus this: the
  // geoid undulation N at the site (EGM96 or EGM2008; roughly +47 m at Pisa), metres, in
  // [-120, 100] (the geoid's extremes are -106 and +85). 0 leaves ellipsoid heights as they are,
  // which puts the tracks N metres too high or low (up to about 100 m).
  double geoid_undulation_m = 0;

  // Every problem, as "field: problem (got X)".
  std::vector<std::string> Validate() const;
  bool operator==(const KmlOptions&) const = default;
};

// A KML 2.2 document with one Placemark per track, in increasing track id: its name, a TimeSpan
// from the first to the last point (for Google Earth's time slider), ExtendedData (track_id,
// points, max_horizontal_sigma_m when known) and a MultiGeometry of a LineString through the
// points in time order (when there are two or more) and a Point at the last one, altitudeMode
// absolute. Coordinates are "lon,lat,alt" with 1e-7 degree (about 1 cm) and 1 mm. Invalid points
// are left out; no points gives a valid Document without Placemarks. `options` must be valid.
std::string ToKml(const std::vector<TrackPoint>& points, const KmlOptions& options = {});

// An RFC 7946 FeatureCollection with one Feature per track, in increasing track id: id and
// properties {track_id, start, end (ISO 8601 UTC), points, max_horizontal_sigma_m when known} and
// a geometry through the points in time order: a LineString, or a Point for a track of one point
// (a LineString needs two). Positions are [lon, lat, alt] with the altitude above the WGS84
// ellipsoid, as RFC 7946 defines it; 1e-7 degree and 1 mm. Invalid points are left out, so no
// number is NaN or infinite. One feature per line.
std::string ToGeoJson(const std::vector<TrackPoint>& points);

}  // namespace stevi::client
