// stevi export --format kml|geojson|mcap --out FILE (--count N | --in FRAMES.jsonl | --in DIR)
// [--geoid-undulation M] [--image-hz N]: each track's trajectory (KML, GeoJSON), or the flight
// for Foxglove (MCAP), from live frames, a `stevi watch --json` file or (MCAP) a recording.
#include "client/advisory/export.h"

#include <cstdint>
#include <filesystem>
#include <functional>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include "client/cli/commands.h"
#include "client/advisory/flight_export.h"
#include "core/common/flags.h"
#include "client/advisory/track_points.h"

namespace stevi::client::commands {
namespace {

struct ExportArgs {
  std::string format, out_path, in_path;
  uint64_t count = 0;
  KmlOptions kml;
  double image_hz = 5;  // mcap: images per second
};

std::string ParseArgs(const Args& args, ExportArgs& a) {
  return flags::FlagSet("export")
      .Value("--format",
             [&a](const std::string& format) {
               if (format != "kml" && format != "geojson" && format != "mcap") {
                 return flags::Expected("export", "--format", "kml, geojson or mcap", format);
               }
               a.format = format;
               return std::string();
             })
      .Text("--out", &a.out_path)
      .Text("--in", &a.in_path)
      .Whole("--count", {.lo = 1}, [&a](std::int64_t n) { a.count = static_cast<uint64_t>(n); })
      .Real("--geoid-undulation", {.lo = -120, .hi = 100, .unit = "metres"},
            [&a](double m) { a.kml.geoid_undulation_m = m; })
      .Real("--image-hz", {.lo = 0, .hi = 30, .unit = "images per second"},
            [&a](double hz) { a.image_hz = hz; })
      .Parse(args);
}

// Streams `count` live frames to `each` until it returns false; 0 when done, else the exit code.
int StreamLive(Client& client, uint64_t count,
               const std::function<bool(const v1::TrackFrame&)>& each) {
  // A server restart while collecting is waited out; a wrong address fails at once.
  StreamOptions stream = LiveStreamOptions("export", 1);
  stream.max_frames = count;
  OnStopSignal([&client] { client.Cancel(); });  // Ctrl-C or SIGTERM: end cleanly
  const grpc::Status status = client.StreamTracks(each, stream);
  if (!status.ok()) return RpcFailed(client, "export", status);
  return 0;
}

int Fail(const std::string& message) {
  std::cerr << "stevi: export: " << message << "\n";
  return 1;
}

// --format mcap: live frames, a frames file or a recording folder into a flight log.
int ExportMcap(Client& client, const ExportArgs& a) {
  drivers::FlightLogOptions options;
  options.image_hz = a.image_hz;
  const bool recording = !a.in_path.empty() && std::filesystem::is_directory(a.in_path);
  const std::string from = a.in_path.empty() ? "live frames"
                           : recording       ? "the recording " + a.in_path
                                             : a.in_path;
  Result<std::unique_ptr<drivers::FlightLog>> created = drivers::FlightLog::Create(
      a.out_path, options, {{"source", from}, {"writer", "stevi export --format mcap"}});
  if (!created.ok()) return Fail(created.error().message);
  drivers::FlightLog& log = **created;
  std::string note;
  if (recording) {
    Result<RecordingExport> done = ExportRecording(a.in_path, log);
    if (!done.ok()) return Fail(done.error().message);
    note = done->note;
    std::cout << a.in_path << ": " << done->frames << " frames (" << done->images
              << " left images), " << done->vehicle_states << " vehicle states, "
              << done->calibrations << " calibrations; no tracks (a recording holds the raw "
              << "frames: stevi-process --source replay --replay " << a.in_path
              << " --mcap FILE runs the pipeline over it)\n";
  } else if (!a.in_path.empty()) {
    const stevi::Status read = ForEachFrameLine(
        a.in_path, [&log](const v1::TrackFrame& frame) { return log.AddFrame(frame); });
    if (!read.ok()) return Fail(read.error().message);
  } else {
    stevi::Status written = stevi::Status::Ok();
    if (int code = StreamLive(client, a.count,
                              [&](const v1::TrackFrame& frame) {
                                written = log.AddFrame(frame);
                                return written.ok();
                              });
        code != 0) {
      return code;
    }
    if (!written.ok()) return Fail(written.error().message);
  }
  if (stevi::Status closed = log.Close(); !closed.ok()) return Fail(closed.error().message);
  const drivers::FlightLogCounts c = log.counts();
  std::cout << a.out_path << ": " << c.track_frames << " track frames, " << c.images << " images, "
            << c.vehicle_fixes << " vehicle fixes, " << c.messages << " messages, " << c.bytes
            << " bytes\n";
  if (!note.empty()) std::cerr << "stevi: export: " << note << "\n";
  return 0;
}

}  // namespace

int Export(Client& client, const Args& args) {
  ExportArgs a;
  if (std::string problem = ParseArgs(args, a); !problem.empty()) return Usage(problem);
  if (a.format.empty() || a.out_path.empty())
    return Usage("export: --format and --out are required");
  if (a.in_path.empty() == (a.count == 0))
    return Usage("export: give either --count N or --in FILE");
  if (a.format == "mcap") return ExportMcap(client, a);

  std::vector<TrackPoint> points;
  if (!a.in_path.empty()) {
    const stevi::Status read = ForEachFrameLine(a.in_path, [&points](const v1::TrackFrame& frame) {
      CollectTrackPoints(frame, points);
      return stevi::Status::Ok();
    });
    if (!read.ok()) return Fail(read.error().message);
  } else if (int code = StreamLive(client, a.count,
                                   [&points](const v1::TrackFrame& frame) {
                                     CollectTrackPoints(frame, points);
                                     return true;
                                   });
             code != 0) {
    return code;
  }
  for (const std::string& problem : ValidateTrackPoints(points)) {
    std::cerr << "stevi: export: left out " << problem << "\n";
  }
  const std::string text = a.format == "kml" ? ToKml(points, a.kml) : ToGeoJson(points);
  if (!WriteFile(a.out_path, text)) return Fail("cannot write " + a.out_path);
  std::cout << a.out_path << ": " << points.size() << " points\n";
  return 0;
}

const CommandSpec kExportCommand = {
    "export", "track trajectories as KML or GeoJSON, or the flight as MCAP",
    R"(usage: stevi export --format kml|geojson --out FILE (--count N | --in FRAMES.jsonl)
                    [--geoid-undulation M]
       stevi export --format mcap --out FILE (--count N | --in FRAMES.jsonl | --in DIR)
                    [--image-hz N]

kml, geojson: each track's trajectory (confirmed and coasting tracks with a geodetic position)
from N live frames or from a file of `stevi watch --json` lines: KML (opens in Google Earth;
altitudes are ellipsoid heights minus M, the geoid undulation at the site) or a GeoJSON
FeatureCollection (opens in QGIS).
mcap: the flight for Foxglove (an indexed MCAP file with the station's channels): N live frames,
a frames file, or a recording folder (its left images at N per second, default 5, its vehicle
states and calibrations; stevi-process --mcap adds the tracks).
)",
    &Export};

}  // namespace stevi::client::commands
