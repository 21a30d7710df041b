// stevi: the command-line client of stevi-server. This file holds the usage text and the table of
// commands; each command lives in client/commands/, over the flags of client/flags.h.
#include <malloc.h>

#include <cstdlib>
#include <iostream>
#include <string>
#include <string_view>

#include "client/client.h"
#include "client/commands/commands.h"

namespace {

namespace commands = stevi::client::commands;

constexpr char kUsage[] = R"(usage: stevi [--server HOST:PORT] [--timeout SECONDS] [--tls-ca PEM]
             [--tls-cert PEM --tls-key PEM] [--token-file FILE] COMMAND [ARGS]

  --tls-ca PEM       connect with TLS, trusting this CA (the server's certificate must name the
                     host given in --server)
  --tls-cert, --tls-key PEM
                     this client's certificate and key, for a server with mutual TLS
  --token-file FILE  send the bearer token on its first line (the server's control calls need
                     it when it has auth.token_file)

Commands:
  watch [--count N] [--json] [--confirmed] [--min-score S]
                               live tracks: a table, or one TrackFrame JSON per line;
                               --confirmed hides tentative tracks, --min-score S (0..1)
                               those whose detection scored below S
  status [--json]              source state, frame rates, drops, stage timings, camera pairing
                               (skew, unpaired and incomplete frames, reconnects), recording,
                               subscribers
  record start [--name NAME] [--max-mb MB] [--json]
                               record the raw stereo pairs, timestamps, vehicle states and
                               calibration id on the server, in DATA_DIR/recordings/NAME
                               (default name from the time; default limit 4096 MiB), for
                               stevi-server --source replay and stevi-process --replay
  record stop [--json]         stop it and print what was written
  config get [--json]          the active pipeline configuration
  config set KEY=VALUE...      change it while running, e.g. algorithm=canonical,
                               matcher.kind=semi_global, canonical.threshold_range_m=60
  snapshot --out PREFIX        write PREFIX_disparity16.png, PREFIX_disparity_colour.png,
                               PREFIX_left.png, PREFIX_annotated.png (boxes, ids, ranges)
                               and PREFIX_meta.json

  calibrate --board COLSxROWS --square-mm MM [--apply] [--json]
            [--min-pairs N] [--max-rms PX] [--max-epipolar PX] [--alpha A]
            (--left PATTERN --right PATTERN | --capture N [--interval S])
                               stereo calibration from chessboard pairs: uploaded image files
                               (printf patterns with one integer, e.g. dir/left%02d.jpg; indices
                               0..9999, gaps skipped) or N pairs the server grabs from its own
                               source every S seconds (default 0.5) while the board moves.
                               Prints the quality report; --apply activates the result if every
                               gate passes. The board counts inner corners (e.g. 9x6).
  avoid [--count N] [--protected-radius M]
                               the autopilot example: one advisory per frame as a JSON line,
                               CLEAR, CAUTION, WARNING or AVOID with the worst obstacle's
                               bearing, distance, time and distance of closest approach against
                               the vehicle's own velocity; NO_DATA when no frame came for
                               500 ms or the frame has no vehicle pose. Reconnects on its own.
  export --format kml|geojson --out FILE (--count N | --in FRAMES.jsonl) [--geoid-undulation M]
                               each track's trajectory (confirmed and coasting tracks with a
                               geodetic position) from N live frames or from a file of
                               `stevi watch --json` lines: KML (opens in Google Earth; altitudes
                               are ellipsoid heights minus M, the geoid undulation at the site)
                               or a GeoJSON FeatureCollection (opens in QGIS)
  export --format mcap --out FILE (--count N | --in FRAMES.jsonl | --in DIR) [--image-hz N]
                               the flight for Foxglove (an indexed MCAP file with the station's
                               channels): N live frames, a frames file, or a recording folder
                               (its left images at N per second, default 5, its vehicle states
                               and calibrations; stevi-process --mcap adds the tracks)
  mcap info FILE               what an MCAP flight log holds: channels, counts, rates, and what
                               was lost when it was cut short (a crash, a full disk)
  mcap recover FILE --out FIXED
                               an indexed copy of a file cut short, up to its last whole chunk
  calibration list [--json]    stored calibrations and the active one
  calibration get ID [--yaml]  one calibration: report, or its YAML file
  calibration activate ID      switch the running server to it (between two frames)
  mavlink --link URL [--adsb] [--geoid-undulation M] [--no-pose] [--rate HZ]
          [--component-id N] [--system-id N] [--icao-base N] [--status-every S]
                               the autopilot bridge (MAVLink 2): OBSTACLE_DISTANCE at --rate
                               (10 Hz) from the range scan and the tracks, with --adsb an
                               ADSB_VEHICLE per confirmed georeferenced track; the autopilot's
                               pose back to the server as VehicleStates (not with --no-pose).
                               URL: udp://HOST:PORT (send there), udpin://ADDR:PORT (listen;
                               answer whoever spoke last), serial://DEVICE:BAUD. Nothing older
                               than 400 ms is sent; status lines (logfmt) on stderr
  station [--server A,B] [--listen HOST:PORT] [--token-file FILE | --allow-insecure]
          [--site GEOJSON] [--max-clients N] [--preview-rate HZ] [--preview-width PX]
          [--preview-quality Q] [--export-points N]
                               the ground station for one or more servers (--server after
                               `station` takes a comma-separated list): a web page with each
                               rig's live video, disparity, plan view, map, tracks, status and
                               controls, and a Foxglove WebSocket (Foxglove, Lichtblick), both on
                               --listen (127.0.0.1:8080). Another address needs --token-file
                               (the page asks for that token) or --allow-insecure. The page's
                               control calls carry the operator token typed into the page.
                               --export-points N: each rig's export history keeps the newest
                               N georeferenced track points (200000)

--server defaults to 127.0.0.1:50051; --timeout (seconds, default 5) bounds each call.
Exit status: 0 on success, 1 when the server fails or cannot be reached, 2 on bad usage.
)";

struct Command {
  std::string_view name;
  int (*run)(stevi::client::Client& client, const commands::Args& args);
};

constexpr Command kCommands[] = {
    {"watch", commands::Watch},
    {"status", commands::Status},
    {"config", commands::Config},
    {"snapshot", commands::Snapshot},
    {"calibrate", commands::Calibrate},
    {"avoid", commands::Avoid},
    {"record", commands::Record},
    {"export", commands::Export},
    {"calibration", commands::Calibration},
    {"mavlink", commands::Mavlink},
    {"station", commands::Station},
    {"mcap", commands::Mcap},
};

// `stevi station`, `mavlink` and `avoid` run for hours. glibc's malloc gives each thread that
// allocates an arena of its own (up to 8 per core: a station has two dozen civetweb workers and
// gRPC's threads), and raises its mmap threshold to the largest block freed, so that a track
// export of some megabytes is later carved from whichever arena its worker has; each arena then
// keeps its own peak. Measured in a station serving an export every 3 s: 20 MB growing to about
// 46 MB with glibc's defaults, flat at 23 MB with these. Called before any thread starts;
// MALLOC_ARENA_MAX or MALLOC_MMAP_THRESHOLD_ in the environment wins.
void TuneAllocatorForLongRuns() {
  if (std::getenv("MALLOC_ARENA_MAX") == nullptr) mallopt(M_ARENA_MAX, 2);
  // A fixed threshold also stops the dynamic one: blocks above it are mapped and, when freed,
  // returned to the system at once.
  if (std::getenv("MALLOC_MMAP_THRESHOLD_") == nullptr) mallopt(M_MMAP_THRESHOLD, 256 << 10);
}

}  // namespace

int main(int argc, char** argv) {
  TuneAllocatorForLongRuns();
  commands::HandleStopSignals();
  const commands::Args args(argv + 1, argv + argc);
  commands::GlobalOptions global;
  if (std::string problem = commands::ParseGlobalOptions(args, global); !problem.empty()) {
    return commands::Usage(problem);
  }
  if (global.help) {
    std::cout << kUsage;
    return 0;
  }
  if (global.command >= args.size()) {
    return commands::Usage(
        "expected a command (watch, status, config, snapshot, calibrate, calibration)");
  }
  const std::string& name = args[global.command];
  const commands::Args rest(args.begin() + static_cast<long>(global.command) + 1, args.end());
  stevi::client::Client client(global.client);
  for (const Command& command : kCommands) {
    if (command.name != name) continue;
    const int code = command.run(client, rest);
    commands::OnStopSignal(nullptr);  // a stop handler refers to `client`: done with it first
    return code;
  }
  return commands::Usage("unknown command '" + name + "'");
}
