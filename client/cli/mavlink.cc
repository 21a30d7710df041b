// stevi mavlink --link URL [--adsb] ...: the autopilot bridge. This file reads the flags into
// BridgeOptions and runs client/mavlink/bridge.h's Bridge (its threads, link and status lines)
// until Ctrl-C or SIGTERM.
#include <cstdint>
#include <string>

#include "client/cli/commands.h"
#include "client/mavlink/bridge.h"
#include "client/mavlink/link.h"
#include "core/common/flags.h"

namespace stevi::client::commands {
namespace {

namespace ml = stevi::client::mavlink;

std::string ParseBridgeOptions(const Args& args, ml::BridgeOptions& a) {
  bool no_pose = false;
  std::string problem =
      flags::FlagSet("mavlink")
          .Value("--link", [&a](const std::string& url) { return ml::ParseLinkUrl(url, a.link); })
          .Switch("--adsb", &a.adsb)
          .Switch("--no-pose", &no_pose)
          .Real("--geoid-undulation", {.lo = -120, .hi = 120, .unit = "metres"},
                [&a](double n) { a.geoid_undulation_m = n; })
          .Whole("--component-id", {.lo = 1, .hi = 255},
                 [&a](std::int64_t n) { a.component_id = static_cast<int>(n); })
          .Whole("--system-id", {.lo = 1, .hi = 255},
                 [&a](std::int64_t n) { a.system_id = static_cast<int>(n); })
          .Real("--rate", {.lo = 10, .hi = 50, .unit = "Hz"}, [&a](double hz) { a.rate_hz = hz; })
          .Real("--status-every", {.lo = 0.1, .hi = 3600, .unit = "seconds"},
                [&a](double s) { a.status_every_s = s; })
          .Whole("--icao-base", {.lo = 0, .hi = 0xFFFFFF - (1 << 20) + 1},
                 [&a](std::int64_t n) { a.icao_base = static_cast<uint32_t>(n); })
          .Parse(args);
  if (!problem.empty()) return problem;
  if (a.link.text.empty()) {
    return "mavlink: --link is required (udp://HOST:PORT, udpin://ADDR:PORT or "
           "serial://DEVICE:BAUD)";
  }
  a.publish_poses = !no_pose;
  return "";
}

}  // namespace

int Mavlink(Client& client, const Args& args) {
  ml::BridgeOptions a;
  if (std::string problem = ParseBridgeOptions(args, a); !problem.empty()) return Usage(problem);
  ml::Bridge bridge(client, a);
  OnStopSignal([&bridge] { bridge.Stop(); });  // Ctrl-C or SIGTERM: end cleanly
  const int code = bridge.Run();
  OnStopSignal(nullptr);
  return code;
}

const CommandSpec kMavlinkCommand = {
    "mavlink", "the autopilot bridge (MAVLink 2): obstacles out, the vehicle's pose in",
    R"(usage: stevi mavlink --link URL [--adsb] [--geoid-undulation M] [--no-pose] [--rate HZ]
                     [--component-id N] [--system-id N] [--icao-base N] [--status-every S]

OBSTACLE_DISTANCE at --rate (10 Hz) from the range scan and the tracks, with --adsb an
ADSB_VEHICLE per georeferenced confirmed or coasting track; the autopilot's pose back to the server as
VehicleStates (not with --no-pose). URL: udp://HOST:PORT (send there), udpin://ADDR:PORT
(listen; answer whoever spoke last), serial://DEVICE:BAUD. Nothing older than 400 ms is sent;
status lines (logfmt) on stderr.
)",
    &Mavlink};

}  // namespace stevi::client::commands
