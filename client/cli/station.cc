// stevi station [--server A,B] [--listen HOST:PORT] [--token-file FILE | --allow-insecure]
// [--site GEOJSON] [--max-clients N] [--preview-rate HZ] [--preview-width PX]
// [--preview-quality Q] [--export-points N]: the ground station, a web page and a Foxglove
// WebSocket on one port.
#include "client/station/station.h"

#include <condition_variable>
#include <iostream>
#include <mutex>
#include <sstream>
#include <string>
#include <vector>

#include "client/cli/commands.h"
#include "core/common/flags.h"

namespace stevi::client::commands {
namespace {

struct StationArgs {
  std::string servers, listen = "127.0.0.1:8080", token_file, site_file;
  bool allow_insecure = false;
  station::StationOptions options;
};

std::string ParseArgs(const Args& args, StationArgs& a) {
  return flags::FlagSet("station")
      .Text("--server", &a.servers)
      .Text("--listen", &a.listen)
      .Text("--token-file", &a.token_file)
      .Switch("--allow-insecure", &a.allow_insecure)
      .Text("--site", &a.site_file)
      .Whole("--max-clients", {.lo = 1, .hi = 256},
             [&a](std::int64_t n) { a.options.web.max_clients = static_cast<size_t>(n); })
      .Real("--preview-rate", {.lo = 0, .hi = 30, .unit = "Hz", .lo_open = true},
            [&a](double hz) { a.options.previews.rate_hz = hz; })
      .Whole("--preview-width", {.lo = 64, .hi = 4096},
             [&a](std::int64_t px) { a.options.previews.max_width_px = static_cast<int>(px); })
      .Whole("--preview-quality", {.lo = 10, .hi = 100},
             [&a](std::int64_t q) { a.options.previews.jpeg_quality = static_cast<int>(q); })
      .Whole("--export-points", {.lo = 1, .hi = 10'000'000},
             [&a](std::int64_t n) { a.options.export_points = static_cast<size_t>(n); })
      .Parse(args);
}

// True for 127.0.0.0/8, ::1 and localhost (the host part of HOST:PORT).
bool IsLoopback(const std::string& listen) {
  const size_t colon = listen.rfind(':');
  std::string host = colon == std::string::npos ? listen : listen.substr(0, colon);
  if (host.size() >= 2 && host.front() == '[' && host.back() == ']') {
    host = host.substr(1, host.size() - 2);
  }
  return host == "localhost" || host == "::1" || host.rfind("127.", 0) == 0;
}

std::vector<std::string> SplitServers(const std::string& list) {
  std::vector<std::string> out;
  std::istringstream in(list);
  std::string item;
  while (std::getline(in, item, ',')) {
    if (!item.empty()) out.push_back(item);
  }
  return out;
}

}  // namespace

int Station(Client& client, const Args& args) {
  StationArgs a;
  if (std::string problem = ParseArgs(args, a); !problem.empty()) return Usage(problem);
  a.options.servers = SplitServers(a.servers.empty() ? client.options().address : a.servers);
  if (a.options.servers.empty()) return Usage("station: --server needs at least one HOST:PORT");
  if (a.options.servers.size() > 16) return Usage("station: at most 16 servers");
  a.options.client = client.options();
  a.options.web.listen = a.listen;
  if (!a.token_file.empty()) {
    std::string text;
    if (!ReadFile(a.token_file, text)) {
      return Usage("station --token-file: cannot read '" + a.token_file + "'");
    }
    std::string token = text.substr(0, text.find('\n'));
    while (!token.empty() && (token.back() == '\r' || token.back() == ' ')) token.pop_back();
    if (token.size() < 16) {
      return Usage("station --token-file: '" + a.token_file +
                   "' must hold a token of at least 16 characters on its first line");
    }
    a.options.web.access_token = token;
  }
  if (!IsLoopback(a.listen) && a.token_file.empty() && !a.allow_insecure) {
    return Usage("station: --listen " + a.listen +
                 " is not a loopback address: give --token-file (the page then asks for the "
                 "token) or --allow-insecure");
  }
  if (!a.site_file.empty()) {
    if (!ReadFile(a.site_file, a.options.site_geojson) ||
        a.options.site_geojson.size() > (16u << 20)) {
      return Usage("station --site: cannot read '" + a.site_file + "' (at most 16 MiB)");
    }
    if (std::string problem = station::CheckSiteGeoJson(a.options.site_geojson); !problem.empty()) {
      return Usage("station --site: '" + a.site_file + "': " + problem);
    }
  }
  std::string error;
  std::unique_ptr<station::Station> st = station::Station::Start(a.options, &error);
  if (!st) {
    std::cerr << "stevi: station: " << error << "\n";
    return 1;
  }
  std::string host = a.listen.substr(0, a.listen.rfind(':'));
  if (host.empty() || host == "0.0.0.0" || host == "[::]") host = "127.0.0.1";
  std::cout << "stevi station: serving http://" << host << ":" << st->port()
            << "/ (open it in a browser; Foxglove: open connection, Foxglove WebSocket, ws://"
            << host << ":" << st->port() << ")" << std::endl;
  std::mutex mu;
  std::condition_variable cv;
  bool stop = false;
  OnStopSignal([&] {
    std::lock_guard lock(mu);
    stop = true;
    cv.notify_all();
  });
  {
    std::unique_lock lock(mu);
    cv.wait(lock, [&] { return stop; });
  }
  OnStopSignal(nullptr);
  st->Stop();
  std::cerr << "stevi: station: stopped\n";
  return 0;
}

const CommandSpec kStationCommand = {
    "station", "the ground station: a web page and a Foxglove WebSocket for the rigs",
    R"(usage: stevi station [--server A,B] [--listen HOST:PORT] [--token-file FILE | --allow-insecure]
                     [--site GEOJSON] [--max-clients N] [--preview-rate HZ]
                     [--preview-width PX] [--preview-quality Q] [--export-points N]

The ground station for one or more servers (--server after `station` takes a comma-separated
list): a web page with each rig's live video, disparity, plan view, map, tracks, status and
controls, and a Foxglove WebSocket (Foxglove, Lichtblick), both on --listen (127.0.0.1:8080).
Another address needs --token-file (the page asks for that token) or --allow-insecure. The
page's control calls carry the operator token typed into the page. --export-points N: each rig's
export history keeps the newest N georeferenced track points (200000).
)",
    &Station};

}  // namespace stevi::client::commands
