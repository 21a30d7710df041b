// stevi export --format kml|geojson --out FILE (--count N | --in FRAMES.jsonl)
// [--geoid-undulation M]: each track's trajectory, from live frames or a `stevi watch --json` file.
#include "client/export.h"

#include <google/protobuf/util/json_util.h>

#include <cstdint>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include "client/commands/commands.h"
#include "client/flags.h"
#include "client/track_points.h"

namespace stevi::client::commands {
namespace {

struct ExportArgs {
  std::string format, out_path, in_path;
  uint64_t count = 0;
  KmlOptions kml;
};

std::string ParseArgs(const Args& args, ExportArgs& a) {
  return flags::FlagSet("export")
      .Value("--format",
             [&a](const std::string& format) {
               if (format != "kml" && format != "geojson") {
                 return flags::Expected("export", "--format", "kml or geojson", format);
               }
               a.format = format;
               return std::string();
             })
      .Text("--out", &a.out_path)
      .Text("--in", &a.in_path)
      .Whole("--count", {.lo = 1}, [&a](std::int64_t n) { a.count = static_cast<uint64_t>(n); })
      .Real("--geoid-undulation", {.lo = -120, .hi = 100, .unit = "metres"},
            [&a](double m) { a.kml.geoid_undulation_m = m; })
      .Parse(args);
}

// The track points of a file of TrackFrame JSON lines; false (after saying so) when it cannot be
// read or a line is not a TrackFrame.
bool ReadFramesFile(const std::string& path, std::vector<TrackPoint>& points) {
  std::ifstream in(path);
  if (!in) {
    std::cerr << "stevi: export: cannot read " << path << "\n";
    return false;
  }
  std::string line;
  int number_of_line = 0;
  while (std::getline(in, line)) {
    ++number_of_line;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    v1::TrackFrame frame;
    google::protobuf::util::JsonParseOptions parse;
    parse.ignore_unknown_fields = true;
    if (!google::protobuf::util::JsonStringToMessage(line, &frame, parse).ok()) {
      std::cerr << "stevi: export: " << path << " line " << number_of_line
                << ": not a TrackFrame JSON line (as `stevi watch --json` writes)\n";
      return false;
    }
    CollectTrackPoints(frame, points);
  }
  return true;
}

}  // namespace

int Export(Client& client, const Args& args) {
  ExportArgs a;
  if (std::string problem = ParseArgs(args, a); !problem.empty()) return Usage(problem);
  if (a.format.empty() || a.out_path.empty())
    return Usage("export: --format and --out are required");
  if (a.in_path.empty() == (a.count == 0))
    return Usage("export: give either --count N or --in FILE");

  std::vector<TrackPoint> points;
  if (!a.in_path.empty()) {
    if (!ReadFramesFile(a.in_path, points)) return 1;
  } else {
    // A server restart while collecting is waited out; a wrong address fails at once.
    StreamOptions stream = LiveStreamOptions("export", 1);
    stream.max_frames = a.count;
    OnStopSignal([&client] { client.Cancel(); });  // Ctrl-C or SIGTERM: end cleanly
    const grpc::Status status = client.StreamTracks(
        [&points](const v1::TrackFrame& frame) {
          CollectTrackPoints(frame, points);
          return true;
        },
        stream);
    if (!status.ok()) return RpcFailed(client, "export", status);
  }
  for (const std::string& problem : ValidateTrackPoints(points)) {
    std::cerr << "stevi: export: left out " << problem << "\n";
  }
  const std::string text = a.format == "kml" ? ToKml(points, a.kml) : ToGeoJson(points);
  if (!WriteFile(a.out_path, text)) {
    std::cerr << "stevi: export: cannot write " << a.out_path << "\n";
    return 1;
  }
  std::cout << a.out_path << ": " << points.size() << " points\n";
  return 0;
}

}  // namespace stevi::client::commands
