#include "client/advisory/export.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <string_view>

#include "client/advisory/text_out.h"

namespace stevi::client {
namespace {

constexpr int kDegreeDecimals = 7;    // 1e-7 degree: 1.1 cm of latitude
constexpr int kAltitudeDecimals = 3;  // 1 mm
constexpr int kSigmaDecimals = 2;

std::string Got(double value) {
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), " (got %g)", value);
  return buffer;
}

std::int64_t FloorDiv(std::int64_t a, std::int64_t b) {
  std::int64_t q = a / b;
  if ((a % b != 0) && ((a < 0) != (b < 0))) --q;
  return q;
}

// The valid points of each track, in time order (stable: equal times keep the input order).
using Tracks = std::map<std::uint64_t, std::vector<TrackPoint>>;

Tracks GroupTracks(const std::vector<TrackPoint>& points) {
  Tracks tracks;
  for (const TrackPoint& p : points) {
    if (TrackPointIsValid(p)) tracks[p.track_id].push_back(p);
  }
  for (auto& [id, track] : tracks) {
    std::stable_sort(track.begin(), track.end(), [](const TrackPoint& a, const TrackPoint& b) {
      return a.unix_time_ns < b.unix_time_ns;
    });
  }
  return tracks;
}

std::optional<double> MaxSigma(const std::vector<TrackPoint>& track) {
  std::optional<double> max;
  for (const TrackPoint& p : track) {
    if (p.horizontal_sigma_m && (!max || *p.horizontal_sigma_m > *max)) {
      max = p.horizontal_sigma_m;
    }
  }
  return max;
}

// "lon,lat,alt", KML's tuple.
void AppendKmlCoord(std::string& out, const TrackPoint& p, double geoid_undulation_m) {
  text::AppendFixed(out, p.lon_deg, kDegreeDecimals);
  out += ',';
  text::AppendFixed(out, p.lat_deg, kDegreeDecimals);
  out += ',';
  text::AppendFixed(out, p.alt_m - geoid_undulation_m, kAltitudeDecimals);
}

// [lon,lat,alt], GeoJSON's position.
void AppendGeoJsonPosition(std::string& out, const TrackPoint& p) {
  out += '[';
  text::AppendFixed(out, p.lon_deg, kDegreeDecimals);
  out += ',';
  text::AppendFixed(out, p.lat_deg, kDegreeDecimals);
  out += ',';
  text::AppendFixed(out, p.alt_m, kAltitudeDecimals);
  out += ']';
}

void AppendKmlData(std::string& out, std::string_view name, std::string_view value) {
  out += "        <Data name=\"";
  out += name;
  out += "\"><value>";
  out += value;
  out += "</value></Data>\n";
}

}  // namespace

bool TrackPointIsValid(const TrackPoint& p) {
  return p.lat_deg >= -90 && p.lat_deg <= 90 && p.lon_deg >= -180 && p.lon_deg <= 180 &&
         std::isfinite(p.alt_m) &&
         (!p.horizontal_sigma_m ||
          (std::isfinite(*p.horizontal_sigma_m) && *p.horizontal_sigma_m >= 0));
}

std::vector<std::string> ValidateTrackPoints(const std::vector<TrackPoint>& points) {
  std::vector<std::string> problems;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const TrackPoint& p = points[i];
    std::string at = "points[";
    text::AppendUint(at, i);
    at += "].";
    if (!(p.lat_deg >= -90 && p.lat_deg <= 90)) {
      problems.push_back(at + "lat_deg: must be in [-90, 90] degrees" + Got(p.lat_deg));
    }
    if (!(p.lon_deg >= -180 && p.lon_deg <= 180)) {
      problems.push_back(at + "lon_deg: must be in [-180, 180] degrees" + Got(p.lon_deg));
    }
    if (!std::isfinite(p.alt_m)) {
      problems.push_back(at + "alt_m: must be finite" + Got(p.alt_m));
    }
    if (p.horizontal_sigma_m &&
        !(std::isfinite(*p.horizontal_sigma_m) && *p.horizontal_sigma_m >= 0)) {
      problems.push_back(at + "horizontal_sigma_m: must be >= 0 metres and finite" +
                         Got(*p.horizontal_sigma_m));
    }
  }
  return problems;
}

std::string IsoUtc(std::int64_t unix_time_ns) {
  using namespace std::chrono;
  constexpr std::int64_t kMsPerDay = 86'400'000;
  const std::int64_t ms = FloorDiv(unix_time_ns, 1'000'000);
  const std::int64_t day = FloorDiv(ms, kMsPerDay);
  const std::int64_t ms_of_day = ms - day * kMsPerDay;
  const year_month_day ymd{sys_days{days{day}}};
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), "%04d-%02u-%02uT%02d:%02d:%02d.%03dZ",
                static_cast<int>(ymd.year()), static_cast<unsigned>(ymd.month()),
                static_cast<unsigned>(ymd.day()), static_cast<int>(ms_of_day / 3'600'000),
                static_cast<int>(ms_of_day / 60'000 % 60), static_cast<int>(ms_of_day / 1000 % 60),
                static_cast<int>(ms_of_day % 1000));
  return buffer;
}

std::vector<std::string> KmlOptions::Validate() const {
  std::vector<std::string> problems;
  if (!(geoid_undulation_m >= -120 && geoid_undulation_m <= 100)) {
    problems.push_back("geoid_undulation_m: must be in [-120, 100] metres" +
                       Got(geoid_undulation_m));
  }
  return problems;
}

std::string ToKml(const std::vector<TrackPoint>& points, const KmlOptions& options) {
  std::string out =
      "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
      "<kml xmlns=\"http://www.opengis.net/kml/2.2\">\n"
      "  <Document>\n"
      "    <name>";
  text::AppendXmlEscaped(out, options.document_name);
  out +=
      "</name>\n"
      "    <Style id=\"track\"><LineStyle><color>ff0000ff</color><width>2</width></LineStyle>"
      "</Style>\n";
  for (const auto& [id, track] : GroupTracks(points)) {
    std::string value;
    out += "    <Placemark>\n      <name>";
    text::AppendXmlEscaped(out, options.track_name_prefix);
    text::AppendUint(out, id);
    out += "</name>\n      <TimeSpan>\n        <begin>";
    out += IsoUtc(track.front().unix_time_ns);
    out += "</begin>\n        <end>";
    out += IsoUtc(track.back().unix_time_ns);
    out += "</end>\n      </TimeSpan>\n      <styleUrl>#track</styleUrl>\n      <ExtendedData>\n";
    text::AppendUint(value, id);
    AppendKmlData(out, "track_id", value);
    value.clear();
    text::AppendUint(value, track.size());
    AppendKmlData(out, "points", value);
    if (const std::optional<double> sigma = MaxSigma(track)) {
      value.clear();
      text::AppendFixed(value, *sigma, kSigmaDecimals);
      AppendKmlData(out, "max_horizontal_sigma_m", value);
    }
    out += "      </ExtendedData>\n      <MultiGeometry>\n";
    if (track.size() >= 2) {
      out +=
          "        <LineString>\n"
          "          <altitudeMode>absolute</altitudeMode>\n"
          "          <coordinates>";
      for (std::size_t i = 0; i < track.size(); ++i) {
        if (i > 0) out += ' ';
        AppendKmlCoord(out, track[i], options.geoid_undulation_m);
      }
      out += "</coordinates>\n        </LineString>\n";
    }
    out +=
        "        <Point>\n"
        "          <altitudeMode>absolute</altitudeMode>\n"
        "          <coordinates>";
    AppendKmlCoord(out, track.back(), options.geoid_undulation_m);
    out +=
        "</coordinates>\n"
        "        </Point>\n"
        "      </MultiGeometry>\n"
        "    </Placemark>\n";
  }
  out += "  </Document>\n</kml>\n";
  return out;
}

std::string ToGeoJson(const std::vector<TrackPoint>& points) {
  std::string out = "{\"type\":\"FeatureCollection\",\"features\":[";
  bool first = true;
  for (const auto& [id, track] : GroupTracks(points)) {
    out += first ? "\n" : ",\n";
    first = false;
    out += "{\"type\":\"Feature\",\"id\":";
    text::AppendUint(out, id);
    out += ",\"geometry\":{\"type\":";
    if (track.size() >= 2) {
      out += "\"LineString\",\"coordinates\":[";
      for (std::size_t i = 0; i < track.size(); ++i) {
        if (i > 0) out += ',';
        AppendGeoJsonPosition(out, track[i]);
      }
      out += ']';
    } else {
      out += "\"Point\",\"coordinates\":";
      AppendGeoJsonPosition(out, track.front());
    }
    out += "},\"properties\":{\"track_id\":";
    text::AppendUint(out, id);
    out += ",\"start\":";
    text::AppendJsonString(out, IsoUtc(track.front().unix_time_ns));
    out += ",\"end\":";
    text::AppendJsonString(out, IsoUtc(track.back().unix_time_ns));
    out += ",\"points\":";
    text::AppendUint(out, track.size());
    if (const std::optional<double> sigma = MaxSigma(track)) {
      out += ",\"max_horizontal_sigma_m\":";
      text::AppendFixed(out, *sigma, kSigmaDecimals);
    }
    out += "}}";
  }
  out += first ? "]}\n" : "\n]}\n";
  return out;
}

}  // namespace stevi::client
