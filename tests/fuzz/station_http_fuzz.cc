// Fuzz target: the ground station's HTTP API as `stevi station` serves it, from the request
// civetweb has read (method, URL-decoded path, query, headers, body) through
// FoxgloveServer::HandleHttp (the access token, the handler of the longest path prefix) into the
// station's handlers: the page, Leaflet's files and the API under /api/ (the rigs, config,
// snapshot, calibrations and their activation, the exports, the site overlay); and the site
// overlay's check, CheckSiteGeoJson, on the body.
//
// Two stations serve: one plain, one with an access token and a site overlay. Each has one rig,
// whose server is 127.0.0.1:1, where nobody listens: the calls that reach the rig fail at once
// (UNAVAILABLE), without traffic beyond loopback.
//
// Input: byte 0 picks the method (low three bits: GET, POST, PUT, DELETE, HEAD, OPTIONS, PATCH, or
// the first line's first word), the station (bit 3) and whether the path is URL-decoded as
// civetweb does (bit 4). Then text lines: the request target (PATH[?QUERY]), header lines
// "Name: value" up to an empty line, and the body (the rest). Names, values, the method and the
// path end at a NUL, as civetweb's C strings do.
// Checked besides the sanitizers:
//   - nothing throws out of HandleHttp, and no handler throws (no 500);
//   - the status is one the API documents (200, 400, 401, 403, 404, 405, 409, 429, 501, 502,
//     503);
//   - an error (4xx, 5xx) is a JSON object with a "code" and a non-empty "message";
//   - a JSON response is valid JSON, and no extra header has a line break;
//   - nothing stored changes: /api/rigs and /api/site.geojson answer the same after each input;
//   - CheckSiteGeoJson accepts only a JSON object with a known GeoJSON "type".
#include <civetweb.h>

#include <cctype>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <exception>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>

#include "client/station/station.h"
#include "tests/fuzz/require.h"

namespace st = stevi::station;

namespace {

constexpr char kToken[] = "fuzz-station-access-token-0123";
constexpr char kSite[] =
    R"({"type":"FeatureCollection","features":[{"type":"Feature","properties":{"name":"pad"},)"
    R"("geometry":{"type":"Point","coordinates":[10.4,43.7]}}]})";

using stevi::fuzz::Require;

struct Stations {
  std::unique_ptr<st::Station> plain, guarded;
  std::string rigs_plain, rigs_guarded;  // GET /api/rigs at the start

  Stations() {
    plain = Start("");
    guarded = Start(kSite);
    rigs_plain = Get(*plain, "/api/rigs").body;
    rigs_guarded = Get(*guarded, "/api/rigs").body;
  }
  ~Stations() {
    plain->Stop();
    guarded->Stop();
  }
  Stations(const Stations&) = delete;
  Stations& operator=(const Stations&) = delete;

  static std::unique_ptr<st::Station> Start(const std::string& site) {
    st::StationOptions options;
    options.servers = {"127.0.0.1:1"};
    // A call on a fresh channel waits out gRPC's reconnection backoff (the subchannel to the
    // unreachable server is shared): bounded, so that such inputs stay fast.
    options.client.timeout = std::chrono::milliseconds(30);
    options.web.listen = "127.0.0.1:0";
    options.web.max_clients = 1;
    if (!site.empty()) {
      options.web.access_token = kToken;
      options.site_geojson = site;
    }
    std::string error;
    std::unique_ptr<st::Station> station = st::Station::Start(options, &error);
    Require(station != nullptr);
    return station;
  }
  static st::HttpResponse Get(const st::Station& station, const std::string& path) {
    st::HttpRequest request;
    request.method = "GET";
    request.path = path;
    request.headers["authorization"] = std::string("Bearer ") + kToken;
    return station.HandleHttp(request);
  }
};

Stations& TheStations() {
  static Stations stations;
  return stations;
}

// Up to the first NUL (a C string's end).
std::string CString(std::string_view text) { return std::string(text.substr(0, text.find('\0'))); }

// The next line of `rest` (without "\n" or "\r\n"), taken off it.
std::string_view NextLine(std::string_view& rest) {
  const size_t end = rest.find('\n');
  std::string_view line = rest.substr(0, end);
  rest = end == std::string_view::npos ? std::string_view() : rest.substr(end + 1);
  if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
  return line;
}

st::HttpRequest Parse(uint8_t flags, std::string_view rest) {
  static constexpr const char* kMethods[] = {"GET",  "POST",    "PUT",  "DELETE",
                                             "HEAD", "OPTIONS", "PATCH"};
  st::HttpRequest request;
  std::string_view target = NextLine(rest);
  if ((flags & 7) < 7) {
    request.method = kMethods[flags & 7];
  } else {
    const size_t space = target.find(' ');
    request.method = CString(target.substr(0, space));
    target = space == std::string_view::npos ? std::string_view() : target.substr(space + 1);
  }
  const size_t question = target.find('?');
  std::string path = CString(target.substr(0, question));
  if (question != std::string_view::npos) request.query = CString(target.substr(question + 1));
  if ((flags & 0x10) != 0) {  // civetweb's decoding of the path (no '+' for space)
    std::string decoded(path.size() + 1, '\0');
    const int n =
        mg_url_decode(path.c_str(), int(path.size()), decoded.data(), int(decoded.size()), 0);
    path = n >= 0 ? CString(decoded.substr(0, size_t(n))) : "";
  }
  request.path = path;
  for (std::string_view line = NextLine(rest); !line.empty(); line = NextLine(rest)) {
    const size_t colon = line.find(':');
    if (colon == std::string_view::npos) continue;
    std::string name = CString(line.substr(0, colon));
    for (char& c : name) c = char(std::tolower(static_cast<unsigned char>(c)));
    std::string_view value = line.substr(colon + 1);
    while (!value.empty() && (value.front() == ' ' || value.front() == '\t'))
      value.remove_prefix(1);
    auto [it, inserted] = request.headers.emplace(name, CString(value));
    if (!inserted) it->second += ", " + CString(value);
  }
  request.body = std::string(rest);
  request.remote = "127.0.0.1:40000";
  return request;
}

bool DocumentedStatus(int status) {
  for (const int s : {200, 400, 401, 403, 404, 405, 409, 429, 501, 502, 503}) {
    if (status == s) return true;
  }
  return false;
}

void CheckResponse(const st::HttpResponse& response) {
  Require(DocumentedStatus(response.status));
  for (const auto& [name, value] : response.headers) {
    Require(name.find_first_of("\r\n:") == std::string::npos);
    Require(value.find_first_of("\r\n") == std::string::npos);
  }
  if (response.content_type == "application/json" || response.status >= 400) {
    Require(response.content_type == "application/json");
    const nlohmann::json body = nlohmann::json::parse(response.body, nullptr, false);
    Require(!body.is_discarded());
    if (response.status >= 400) {
      Require(body.is_object() && body.contains("code") && body["code"].is_string());
      Require(body.contains("message") && body["message"].is_string() &&
              !body["message"].get<std::string>().empty());
    }
  }
}

void CheckSite(const std::string& text) {
  if (!st::CheckSiteGeoJson(text).empty()) return;
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  Require(j.is_object() && j.contains("type") && j["type"].is_string());
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  Stations& stations = TheStations();
  const st::HttpRequest request =
      Parse(data[0], std::string_view(reinterpret_cast<const char*>(data) + 1, size - 1));
  const bool guarded = (data[0] & 0x08) != 0;
  const st::Station& station = guarded ? *stations.guarded : *stations.plain;
  st::HttpResponse response;
  try {
    response = station.HandleHttp(request);
  } catch (...) {
    std::abort();
  }
  CheckResponse(response);
  try {
    CheckSite(request.body);
  } catch (...) {
    std::abort();
  }
  Require(Stations::Get(*stations.plain, "/api/rigs").body == stations.rigs_plain);
  Require(Stations::Get(*stations.guarded, "/api/rigs").body == stations.rigs_guarded);
  Require(Stations::Get(*stations.guarded, "/api/site.geojson").body == kSite);
  return 0;
}
