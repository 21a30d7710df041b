#include "client/advisory/export.h"

#include <cctype>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <optional>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/client/json_check.h"

namespace stevi::client {
namespace {

using ::testing::ElementsAre;
using ::testing::HasSubstr;
using ::testing::IsEmpty;
using ::testing::IsSupersetOf;
using testing::Json;
using testing::JsonParser;
using ::testing::Not;
using ::testing::SizeIs;

// --- A small XML well-formedness check, enough for what the exporter writes: an optional
// declaration, elements with quoted attributes, text, comments, the five predefined entities and
// character references. It returns "" for a well-formed document, else the first problem.

bool IsAlpha(char c) { return std::isalpha(static_cast<unsigned char>(c)) != 0; }
bool IsDigit(char c) { return std::isdigit(static_cast<unsigned char>(c)) != 0; }
bool IsHexDigit(char c) { return std::isxdigit(static_cast<unsigned char>(c)) != 0; }
bool IsNameStart(char c) { return IsAlpha(c) || c == '_' || c == ':'; }
bool IsNameChar(char c) { return IsNameStart(c) || IsDigit(c) || c == '-' || c == '.'; }

// Checks the entity reference at xml[i] == '&' and returns the index after its ';', or npos.
std::size_t SkipEntity(std::string_view xml, std::size_t i) {
  const std::size_t semi = xml.find(';', i);
  if (semi == std::string_view::npos || semi - i > 10) return std::string_view::npos;
  const std::string_view name = xml.substr(i + 1, semi - i - 1);
  if (name == "amp" || name == "lt" || name == "gt" || name == "quot" || name == "apos") {
    return semi + 1;
  }
  if (name.size() >= 2 && name[0] == '#') {
    const bool hex = name[1] == 'x';
    const std::string_view digits = name.substr(hex ? 2 : 1);
    if (digits.empty()) return std::string_view::npos;
    for (char c : digits) {
      if (!(hex ? IsHexDigit(c) : IsDigit(c))) {
        return std::string_view::npos;
      }
    }
    return semi + 1;
  }
  return std::string_view::npos;
}

std::string XmlProblem(std::string_view xml) {
  std::vector<std::string> open;
  bool root_seen = false;
  std::size_t i = 0;
  const std::size_t n = xml.size();
  auto at = [&](std::size_t pos) { return " at offset " + std::to_string(pos); };
  while (i < n) {
    const char c = xml[i];
    if (c == '&') {
      const std::size_t next = SkipEntity(xml, i);
      if (next == std::string_view::npos) return "bad entity reference" + at(i);
      if (open.empty()) return "text outside the root element" + at(i);
      i = next;
      continue;
    }
    if (c == '>') return "raw '>' in text" + at(i);  // allowed by XML, but the exporter escapes it
    if (c != '<') {
      if (open.empty() && !std::isspace(static_cast<unsigned char>(c))) {
        return "text outside the root element" + at(i);
      }
      if (static_cast<unsigned char>(c) < 0x20 && c != '\t' && c != '\n' && c != '\r') {
        return "control character" + at(i);
      }
      ++i;
      continue;
    }
    // Markup.
    if (xml.substr(i, 4) == "<!--") {
      const std::size_t end = xml.find("-->", i + 4);
      if (end == std::string_view::npos) return "unterminated comment" + at(i);
      i = end + 3;
      continue;
    }
    if (xml.substr(i, 2) == "<?") {
      if (i != 0 && xml.substr(i, 5) == "<?xml") return "misplaced XML declaration" + at(i);
      const std::size_t end = xml.find("?>", i + 2);
      if (end == std::string_view::npos) return "unterminated declaration" + at(i);
      i = end + 2;
      continue;
    }
    const bool closing = i + 1 < n && xml[i + 1] == '/';
    std::size_t j = i + (closing ? 2 : 1);
    if (j >= n || !IsNameStart(xml[j])) return "bad tag name" + at(i);
    const std::size_t name_start = j;
    while (j < n && IsNameChar(xml[j])) ++j;
    const std::string name(xml.substr(name_start, j - name_start));
    bool self_closing = false;
    // Attributes: name="value" or name='value', separated by white space.
    while (true) {
      const std::size_t before_space = j;
      while (j < n && std::isspace(static_cast<unsigned char>(xml[j]))) ++j;
      if (j >= n) return "unterminated tag <" + name + at(i);
      if (xml[j] == '>') break;
      if (!closing && xml[j] == '/' && j + 1 < n && xml[j + 1] == '>') {
        self_closing = true;
        ++j;
        break;
      }
      if (closing || j == before_space || !IsNameStart(xml[j])) {
        return "bad attribute in <" + name + at(j);
      }
      while (j < n && IsNameChar(xml[j])) ++j;
      if (j >= n || xml[j] != '=') return "attribute without = in <" + name + at(j);
      ++j;
      if (j >= n || (xml[j] != '"' && xml[j] != '\'')) return "unquoted attribute" + at(j);
      const char quote = xml[j++];
      while (j < n && xml[j] != quote) {
        if (xml[j] == '<') return "'<' in an attribute value" + at(j);
        if (xml[j] == '&') {
          const std::size_t next = SkipEntity(xml, j);
          if (next == std::string_view::npos) return "bad entity reference" + at(j);
          j = next;
        } else {
          ++j;
        }
      }
      if (j >= n) return "unterminated attribute value" + at(j);
      ++j;
    }
    if (closing) {
      if (open.empty() || open.back() != name) {
        const std::string what = open.empty() ? "anything" : "<" + open.back() + ">";
        return "</" + name + "> does not close " + what + at(i);
      }
      open.pop_back();
    } else {
      if (open.empty() && root_seen) return "a second root element <" + name + ">" + at(i);
      root_seen = true;
      if (!self_closing) open.push_back(name);
    }
    i = j + 1;
  }
  if (!open.empty()) return "<" + open.back() + "> is not closed";
  if (!root_seen) return "no root element";
  return "";
}

// The text of every <tag>...</tag>, entities decoded.
std::vector<std::string> ElementTexts(const std::string& xml, const std::string& tag) {
  std::vector<std::string> texts;
  const std::string open = "<" + tag + ">", close = "</" + tag + ">";
  for (std::size_t i = xml.find(open); i != std::string::npos; i = xml.find(open, i)) {
    i += open.size();
    const std::size_t end = xml.find(close, i);
    if (end == std::string::npos) break;
    std::string text;
    for (std::size_t k = i; k < end; ++k) {
      static const std::pair<std::string_view, char> kEntities[] = {
          {"&amp;", '&'}, {"&lt;", '<'}, {"&gt;", '>'}, {"&quot;", '"'}, {"&apos;", '\''}};
      bool decoded = false;
      for (const auto& [entity, ch] : kEntities) {
        if (std::string_view(xml).substr(k, entity.size()) == entity) {
          text += ch;
          k += entity.size() - 1;
          decoded = true;
          break;
        }
      }
      if (!decoded) text += xml[k];
    }
    texts.push_back(text);
  }
  return texts;
}

// "lon,lat,alt lon,lat,alt" as rows of numbers.
std::vector<std::vector<double>> ParseKmlCoordinates(const std::string& text) {
  std::vector<std::vector<double>> tuples;
  std::istringstream in(text);
  std::string tuple;
  while (in >> tuple) {
    std::vector<double> values;
    std::istringstream fields(tuple);
    std::string field;
    while (std::getline(fields, field, ',')) values.push_back(std::stod(field));
    tuples.push_back(values);
  }
  return tuples;
}

// Two tracks, three points, given out of order: track 7 backwards in time, and track 3 (one
// point, south and east: negative latitude) between them.
std::vector<TrackPoint> TwoTracks() {
  const std::int64_t t0 = 1'700'000'000'000'000'000;  // 2023-11-14T22:13:20Z
  return {
      {.track_id = 7,
       .unix_time_ns = t0 + 500'000'000,
       .lat_deg = 43.68395,
       .lon_deg = 10.39262,
       .alt_m = 96.25,
       .horizontal_sigma_m = 2.25},
      {.track_id = 3,
       .unix_time_ns = t0 + 250'000'000,
       .lat_deg = -33.8688197,
       .lon_deg = 151.2092955,
       .alt_m = -12.3456,
       .horizontal_sigma_m = std::nullopt},
      {.track_id = 7,
       .unix_time_ns = t0,
       .lat_deg = 43.6839,
       .lon_deg = 10.3925,
       .alt_m = 95,
       .horizontal_sigma_m = 1.5},
  };
}

// A circling track of `n` points, 1 s apart, centred near Pisa, given in a shuffled order.
std::vector<TrackPoint> Circle(std::uint64_t id, int n) {
  std::vector<TrackPoint> points;
  for (int k = 0; k < n; ++k) {
    const int i = (k * 7) % n;  // n not a multiple of 7: a permutation
    const double a = 2 * std::numbers::pi * i / n;
    points.push_back({.track_id = id,
                      .unix_time_ns = 1'700'000'000'000'000'000 + std::int64_t{i} * 1'000'000'000,
                      .lat_deg = 43.7 + 0.001 * std::sin(a),
                      .lon_deg = 10.4 + 0.0013 * std::cos(a),
                      .alt_m = 150 + i * 0.125,
                      .horizontal_sigma_m = std::nullopt});
  }
  return points;
}

TEST(XmlProblem, CatchesBrokenDocuments) {
  EXPECT_EQ(XmlProblem("<?xml version=\"1.0\"?>\n<a x=\"1\"><b/><c>t &amp; u</c></a>\n"), "");
  EXPECT_THAT(XmlProblem("<a><b></a></b>"), HasSubstr("does not close"));
  EXPECT_THAT(XmlProblem("<a><b></b>"), HasSubstr("not closed"));
  EXPECT_THAT(XmlProblem("<a>x & y</a>"), HasSubstr("entity"));
  EXPECT_THAT(XmlProblem("<a>x < y</a>"), HasSubstr("tag name"));
  EXPECT_THAT(XmlProblem("<a></a><b></b>"), HasSubstr("second root"));
  EXPECT_THAT(XmlProblem("<a n=\"x\"y\"></a>"), HasSubstr("attribute"));
  EXPECT_THAT(XmlProblem(""), HasSubstr("no root"));
}

TEST(IsoUtc, KnownInstants) {
  EXPECT_EQ(IsoUtc(0), "1970-01-01T00:00:00.000Z");
  EXPECT_EQ(IsoUtc(1'700'000'000'123'456'789), "2023-11-14T22:13:20.123Z");
  EXPECT_EQ(IsoUtc(1'709'210'096'789'000'000), "2024-02-29T12:34:56.789Z");
  EXPECT_EQ(IsoUtc(-1), "1969-12-31T23:59:59.999Z") << "rounded down, also before 1970";
  EXPECT_EQ(IsoUtc(-2'208'988'800'000'000'000), "1900-01-01T00:00:00.000Z");
  EXPECT_EQ(IsoUtc(std::numeric_limits<std::int64_t>::max()), "2262-04-11T23:47:16.854Z");
  EXPECT_EQ(IsoUtc(std::numeric_limits<std::int64_t>::min()), "1677-09-21T00:12:43.145Z");
}

TEST(ToKml, ExactDocumentForTwoTracks) {
  const std::string expected = R"(<?xml version="1.0" encoding="UTF-8"?>
<kml xmlns="http://www.opengis.net/kml/2.2">
  <Document>
    <name>stevi tracks</name>
    <Style id="track"><LineStyle><color>ff0000ff</color><width>2</width></LineStyle></Style>
    <Placemark>
      <name>track 3</name>
      <TimeSpan>
        <begin>2023-11-14T22:13:20.250Z</begin>
        <end>2023-11-14T22:13:20.250Z</end>
      </TimeSpan>
      <styleUrl>#track</styleUrl>
      <ExtendedData>
        <Data name="track_id"><value>3</value></Data>
        <Data name="points"><value>1</value></Data>
      </ExtendedData>
      <MultiGeometry>
        <Point>
          <altitudeMode>absolute</altitudeMode>
          <coordinates>151.2092955,-33.8688197,-12.346</coordinates>
        </Point>
      </MultiGeometry>
    </Placemark>
    <Placemark>
      <name>track 7</name>
      <TimeSpan>
        <begin>2023-11-14T22:13:20.000Z</begin>
        <end>2023-11-14T22:13:20.500Z</end>
      </TimeSpan>
      <styleUrl>#track</styleUrl>
      <ExtendedData>
        <Data name="track_id"><value>7</value></Data>
        <Data name="points"><value>2</value></Data>
        <Data name="max_horizontal_sigma_m"><value>2.25</value></Data>
      </ExtendedData>
      <MultiGeometry>
        <LineString>
          <altitudeMode>absolute</altitudeMode>
          <coordinates>10.3925000,43.6839000,95.000 10.3926200,43.6839500,96.250</coordinates>
        </LineString>
        <Point>
          <altitudeMode>absolute</altitudeMode>
          <coordinates>10.3926200,43.6839500,96.250</coordinates>
        </Point>
      </MultiGeometry>
    </Placemark>
  </Document>
</kml>
)";
  const std::string kml = ToKml(TwoTracks());
  EXPECT_EQ(kml, expected);
  EXPECT_EQ(XmlProblem(kml), "");
}

TEST(ToKml, WellFormedWithLonLatAltCoordinatesInTimeOrder) {
  std::vector<TrackPoint> points = Circle(11, 60);
  const std::vector<TrackPoint> two = TwoTracks();
  points.insert(points.begin() + 20, two.begin(), two.end());
  const std::string kml = ToKml(points);
  ASSERT_EQ(XmlProblem(kml), "");
  EXPECT_THAT(ElementTexts(kml, "name"),
              ElementsAre("stevi tracks", "track 3", "track 7", "track 11"));

  // Placemarks 3, 7, 11: Point; LineString, Point; LineString, Point.
  const std::vector<std::string> coordinates = ElementTexts(kml, "coordinates");
  ASSERT_THAT(coordinates, SizeIs(5));
  const std::vector<std::vector<double>> line = ParseKmlCoordinates(coordinates[3]);
  const std::vector<TrackPoint> circle = Circle(11, 60);
  ASSERT_THAT(line, SizeIs(60));
  for (const TrackPoint& p : circle) {
    const std::int64_t i = (p.unix_time_ns - circle[0].unix_time_ns) / 1'000'000'000;
    ASSERT_THAT(line[i], SizeIs(3));
    EXPECT_NEAR(line[i][0], p.lon_deg, 0.5e-7) << "longitude first, point " << i;
    EXPECT_NEAR(line[i][1], p.lat_deg, 0.5e-7) << "then latitude, point " << i;
    EXPECT_NEAR(line[i][2], p.alt_m, 0.5e-3) << "then altitude, point " << i;
  }
  // The Point is the last position in time.
  EXPECT_EQ(coordinates[4], coordinates[3].substr(coordinates[3].rfind(' ') + 1));
  const std::vector<std::vector<double>> south = ParseKmlCoordinates(coordinates[0]);
  EXPECT_THAT(south, ElementsAre(ElementsAre(151.2092955, -33.8688197, -12.346)));
}

TEST(ToKml, GeoidUndulationGivesHeightAboveSeaLevel) {
  KmlOptions options;
  options.geoid_undulation_m = 47.5;
  EXPECT_THAT(options.Validate(), IsEmpty());
  const std::string kml = ToKml(TwoTracks(), options);
  EXPECT_EQ(XmlProblem(kml), "");
  EXPECT_THAT(ElementTexts(kml, "coordinates"),
              ElementsAre("151.2092955,-33.8688197,-59.846",
                          "10.3925000,43.6839000,47.500 10.3926200,43.6839500,48.750",
                          "10.3926200,43.6839500,48.750"));
}

TEST(KmlOptions, ValidateNamesTheGeoidUndulation) {
  EXPECT_THAT(KmlOptions{}.Validate(), IsEmpty());
  KmlOptions bad;
  bad.geoid_undulation_m = 150;
  EXPECT_THAT(bad.Validate(), ElementsAre(HasSubstr("geoid_undulation_m: must be in [-120, 100]")));
  bad.geoid_undulation_m = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THAT(bad.Validate(), ElementsAre(HasSubstr("geoid_undulation_m")));
}

TEST(ToKml, EmptyInputIsAValidEmptyDocument) {
  const std::string kml = ToKml({});
  EXPECT_EQ(XmlProblem(kml), "");
  EXPECT_THAT(kml, HasSubstr("<Document>"));
  EXPECT_THAT(kml, Not(HasSubstr("<Placemark>")));
  EXPECT_THAT(ElementTexts(kml, "name"), ElementsAre("stevi tracks"));
}

TEST(ToKml, EscapesSpecialCharactersInNames) {
  KmlOptions options;
  options.document_name = "Pisa <approach> & \"R04\" 'test'";
  options.track_name_prefix = "obstacle</name>#";
  const std::string kml = ToKml(TwoTracks(), options);
  ASSERT_EQ(XmlProblem(kml), "");
  EXPECT_THAT(kml, HasSubstr("<name>Pisa &lt;approach&gt; &amp; &quot;R04&quot; "
                             "&apos;test&apos;</name>"));
  EXPECT_THAT(ElementTexts(kml, "name"),
              ElementsAre(options.document_name, "obstacle</name>#3", "obstacle</name>#7"));
  // A control character, which XML 1.0 cannot carry at all, becomes a space.
  options.document_name = std::string("bell\x07") + "tab\t";
  const std::string bell = ToKml({}, options);
  EXPECT_EQ(XmlProblem(bell), "");
  EXPECT_THAT(ElementTexts(bell, "name"), ElementsAre("bell tab\t"));
}

TEST(ToKml, InvalidPointsAreLeftOutAndNamed) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::vector<TrackPoint> points = TwoTracks();
  points.push_back({.track_id = 7,
                    .unix_time_ns = 0,
                    .lat_deg = 91,
                    .lon_deg = 0,
                    .alt_m = 0,
                    .horizontal_sigma_m = std::nullopt});
  points.push_back({.track_id = 9,
                    .unix_time_ns = 0,
                    .lat_deg = 0,
                    .lon_deg = nan,
                    .alt_m = 0,
                    .horizontal_sigma_m = std::nullopt});
  points.push_back({.track_id = 9,
                    .unix_time_ns = 0,
                    .lat_deg = 0,
                    .lon_deg = 0,
                    .alt_m = std::numeric_limits<double>::infinity(),
                    .horizontal_sigma_m = -1.0});
  EXPECT_THAT(ValidateTrackPoints(points),
              ElementsAre(HasSubstr("points[3].lat_deg"), HasSubstr("points[4].lon_deg"),
                          HasSubstr("points[5].alt_m"), HasSubstr("points[5].horizontal_sigma_m")));
  EXPECT_THAT(ValidateTrackPoints(TwoTracks()), IsEmpty());
  EXPECT_EQ(ToKml(points), ToKml(TwoTracks())) << "as if the invalid points were not there";
  EXPECT_EQ(ToGeoJson(points), ToGeoJson(TwoTracks()));
}

TEST(ToGeoJson, ExactCollectionForTwoTracks) {
  const std::string expected =
      R"({"type":"FeatureCollection","features":[)"
      "\n"
      R"({"type":"Feature","id":3,"geometry":{"type":"Point","coordinates":)"
      R"([151.2092955,-33.8688197,-12.346]},"properties":{"track_id":3,)"
      R"("start":"2023-11-14T22:13:20.250Z","end":"2023-11-14T22:13:20.250Z","points":1}},)"
      "\n"
      R"({"type":"Feature","id":7,"geometry":{"type":"LineString","coordinates":)"
      R"([[10.3925000,43.6839000,95.000],[10.3926200,43.6839500,96.250]]},)"
      R"("properties":{"track_id":7,"start":"2023-11-14T22:13:20.000Z",)"
      R"("end":"2023-11-14T22:13:20.500Z","points":2,"max_horizontal_sigma_m":2.25}})"
      "\n]}\n";
  EXPECT_EQ(ToGeoJson(TwoTracks()), expected);
}

TEST(ToGeoJson, ParsesAsAFeatureCollectionWithLonLatAltPositions) {
  std::vector<TrackPoint> points = Circle(11, 60);
  const std::vector<TrackPoint> two = TwoTracks();
  points.insert(points.begin() + 33, two.begin(), two.end());
  const std::string text = ToGeoJson(points);
  std::string error;
  const std::optional<Json> json = JsonParser::Parse(text, &error);
  ASSERT_TRUE(json.has_value()) << error;
  EXPECT_THAT(json->Keys(), ElementsAre("type", "features"));
  EXPECT_EQ(json->Find("type")->string, "FeatureCollection");
  const std::vector<Json>& features = json->Find("features")->items;
  ASSERT_THAT(features, SizeIs(3));
  for (const Json& f : features) {
    EXPECT_THAT(f.Keys(), ElementsAre("type", "id", "geometry", "properties"));
    EXPECT_EQ(f.Find("type")->string, "Feature");
    EXPECT_THAT(f.Find("properties")->Keys(), IsSupersetOf({"track_id", "start", "end", "points"}));
  }
  EXPECT_EQ(features[0].Find("geometry")->Find("type")->string, "Point");
  const std::vector<Json>& south = features[0].Find("geometry")->Find("coordinates")->items;
  ASSERT_THAT(south, SizeIs(3));
  EXPECT_EQ(south[0].number, 151.2092955) << "longitude first";
  EXPECT_EQ(south[1].number, -33.8688197) << "then latitude";
  EXPECT_EQ(south[2].number, -12.346) << "then altitude";

  const Json& circle_feature = features[2];
  EXPECT_EQ(circle_feature.Find("id")->number, 11);
  const Json* properties = circle_feature.Find("properties");
  EXPECT_EQ(properties->Find("track_id")->number, 11);
  EXPECT_EQ(properties->Find("points")->number, 60);
  EXPECT_EQ(properties->Find("start")->string, "2023-11-14T22:13:20.000Z");
  EXPECT_EQ(properties->Find("end")->string, "2023-11-14T22:14:19.000Z");
  EXPECT_EQ(properties->Find("max_horizontal_sigma_m"), nullptr) << "no sigma given";
  EXPECT_EQ(circle_feature.Find("geometry")->Find("type")->string, "LineString");
  const std::vector<Json>& line = circle_feature.Find("geometry")->Find("coordinates")->items;
  const std::vector<TrackPoint> circle = Circle(11, 60);
  ASSERT_THAT(line, SizeIs(60));
  for (const TrackPoint& p : circle) {
    const std::int64_t i = (p.unix_time_ns - circle[0].unix_time_ns) / 1'000'000'000;
    const std::vector<Json>& position = line[i].items;
    ASSERT_THAT(position, SizeIs(3));
    EXPECT_NEAR(position[0].number, p.lon_deg, 0.5e-7) << "longitude first, point " << i;
    EXPECT_NEAR(position[1].number, p.lat_deg, 0.5e-7) << "then latitude, point " << i;
    EXPECT_NEAR(position[2].number, p.alt_m, 0.5e-3) << "then altitude, point " << i;
  }
}

TEST(ToGeoJson, EmptyInputIsAValidEmptyCollection) {
  const std::string text = ToGeoJson({});
  EXPECT_EQ(text, "{\"type\":\"FeatureCollection\",\"features\":[]}\n");
  const std::optional<Json> json = JsonParser::Parse(text);
  ASSERT_TRUE(json.has_value());
  EXPECT_THAT(json->Find("features")->items, IsEmpty());
  // Only invalid points: the same.
  EXPECT_EQ(ToGeoJson({{.track_id = 1,
                        .unix_time_ns = 0,
                        .lat_deg = 100,
                        .lon_deg = 0,
                        .alt_m = 0,
                        .horizontal_sigma_m = std::nullopt}}),
            text);
}

TEST(JsonParser, RejectsWhatAConsumerWould) {
  EXPECT_TRUE(JsonParser::Parse(R"( {"a":[1,-2.5e3,true,null,"x\"\u0041"]} )").has_value());
  std::string error;
  for (const char* bad : {R"({"a":NaN})", R"({"a":nan})", R"({"a":1,})", R"([1,2)", R"({"a":01})",
                          R"({'a':1})", R"({"a":1}})", R"({"a":1,"a":2})", "{\"a\":\"x\ny\"}",
                          R"({"a":.5})", R"({"a":1.})", R"({"a":Infinity})"}) {
    EXPECT_FALSE(JsonParser::Parse(bad, &error).has_value()) << bad;
  }
}

}  // namespace
}  // namespace stevi::client
