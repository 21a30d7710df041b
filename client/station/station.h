// `stevi station`: a ground-station gateway to one or more stevi-servers. It serves a web page and
// a WebSocket in the Foxglove WebSocket protocol (the page is a client of that socket too), and
// passes the page's control calls on to the servers.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "client/lib/client.h"
#include "client/station/foxglove_server.h"
#include "client/station/rig_link.h"

namespace stevi::station {

struct StationOptions {
  std::vector<std::string> servers;  // HOST:PORT of each stevi-server, rig1, rig2, ...
  client::ClientOptions client;      // TLS, token and timeout of the reading calls
  FoxgloveServerOptions web;         // --listen, the limits, the station's access token
  PreviewSettings previews;
  // Each rig's export history: the newest this many georeferenced track points.
  size_t export_points = RigLink::kMaxTrackPoints;
  std::string site_geojson;  // a GeoJSON overlay of the site ("" = none), already checked
  std::string leaflet_dir = "/usr/share/javascript/leaflet";
};

// Every problem of a GeoJSON overlay's text, "" when it is a GeoJSON object the page can draw.
std::string CheckSiteGeoJson(const std::string& text);

class Station {
 public:
  // Starts serving and connecting; nullptr and `error` when the address cannot be served.
  static std::unique_ptr<Station> Start(StationOptions options, std::string* error);
  ~Station();
  Station(const Station&) = delete;
  Station& operator=(const Station&) = delete;

  int port() const;
  void Stop();

  // One HTTP request as civetweb's handler passes it on (FoxgloveServer::HandleHttp): the access
  // token, the page, Leaflet and the API. For tests and the fuzz target, which have no socket.
  HttpResponse HandleHttp(const HttpRequest& request) const;

  struct Rig;  // a RigLink and its channels (station.cc)

 private:
  explicit Station(StationOptions options);
  // rig<i+1>: its channels, and a RigLink that publishes to them.
  std::unique_ptr<Rig> MakeRig(size_t i);
  void Route(uint32_t channel, bool subscribed);
  // The page's calls under /api/ (see the README's station section).
  HttpResponse Api(const HttpRequest& request);

  StationOptions options_;
  std::unique_ptr<FoxgloveServer> server_;
  std::vector<std::unique_ptr<Rig>> rigs_;
};

}  // namespace stevi::station
