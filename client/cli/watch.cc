// stevi watch [--count N] [--json] [--confirmed] [--min-score S]: the live tracks, as a table or
// one TrackFrame JSON per line.
#include <cstdint>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <string>

#include "client/cli/commands.h"
#include "core/common/flags.h"

namespace stevi::client::commands {
namespace {

// A value with one decimal, or "-" when the track has none.
std::string Optional(bool has, double value) {
  std::ostringstream s;
  if (has) {
    s << std::fixed << std::setprecision(1) << value;
  } else {
    s << "-";
  }
  return s.str();
}

// One row of the table: `out` is fixed with two decimals, and stays so.
void PrintTrackRow(std::ostringstream& out, const v1::Track& t, bool geo) {
  std::ostringstream box;
  box << t.bbox().x() << "," << t.bbox().y() << " " << t.bbox().width() << "x" << t.bbox().height();
  out << std::setw(6) << t.track_id() << "  " << std::left << std::setw(10)
      << ShortEnum(v1::TrackState_Name(t.state()), "TRACK_STATE_") << std::right << std::setw(5)
      << t.age_frames() << std::setw(21) << box.str() << std::setw(10) << t.depth_m()
      << std::setw(10) << t.range_m() << std::setw(9) << t.range_sigma_m() << std::setw(10)
      << t.disparity_px() << std::setw(10) << t.range_rate_mps() << std::setw(10)
      << Optional(t.has_time_to_collision_s(), t.time_to_collision_s()) << std::setw(9)
      << Optional(t.has_closest_approach_m(), t.closest_approach_m());
  if (geo && t.has_geodetic()) {
    out << std::setprecision(7) << std::setw(14) << t.geodetic().lat_deg() << std::setw(13)
        << t.geodetic().lon_deg() << std::setprecision(1) << std::setw(9) << t.geodetic().alt_m()
        << std::setw(7) << t.position_sigma_m().horizontal_m() << "/"
        << t.position_sigma_m().vertical_m() << std::setprecision(2);
  }
  out << "\n";
}

void PrintFrameTable(const v1::TrackFrame& f) {
  std::ostringstream out;
  out << std::fixed << std::setprecision(3);
  out << "frame " << f.frame_id() << "  t=" << f.capture_time_ns() / 1e9 << "s  "
      << ShortEnum(v1::Algorithm_Name(f.algorithm()), "ALGORITHM_") << "  " << f.tracks_size()
      << (f.tracks_size() == 1 ? " obstacle" : " obstacles");
  if (f.dropped_frames() > 0) out << "  (dropped " << f.dropped_frames() << ")";
  const bool geo = f.geo_status() == v1::GEO_STATUS_OK;
  if (f.geo_status() != v1::GEO_STATUS_UNSPECIFIED && !geo)
    out << "  no geodetic: " << f.geo_message();
  out << "\n";
  if (f.tracks_size() > 0) {
    out << "    id  state       age        box (x,y wxh)   depth m   range m  sigma m   disp px"
           "  rate m/s     ttc s   miss m"
        << (geo ? "       lat deg      lon deg    alt m  sigma h/v m" : "") << "\n";
  }
  out << std::setprecision(2);
  for (const v1::Track& t : f.tracks()) PrintTrackRow(out, t, geo);
  std::cout << out.str() << std::flush;
}

}  // namespace

int Watch(Client& client, const Args& args) {
  bool json = false;
  // A wrong address fails at once; a server that goes away after frames flowed is waited for.
  StreamOptions options = LiveStreamOptions("watch", 1);
  const std::string problem =
      flags::FlagSet("watch")
          .Switch("--json", &json)
          .Switch("--confirmed", &options.confirmed_only)
          .Real("--min-score", {.lo = 0, .hi = 1, .unit = "a number"},
                [&options](double score) { options.min_score = score; })
          .Whole("--count", {.lo = 1},
                 [&options](std::int64_t n) { options.max_frames = static_cast<uint64_t>(n); })
          .Parse(args);
  if (!problem.empty()) return Usage(problem);
  OnStopSignal([&client] { client.Cancel(); });  // Ctrl-C or SIGTERM: end cleanly
  const grpc::Status status = client.StreamTracks(
      [&](const v1::TrackFrame& frame) {
        if (json) {
          std::cout << Json(frame) << "\n" << std::flush;
        } else {
          PrintFrameTable(frame);
        }
        return true;
      },
      options);
  if (!status.ok()) return RpcFailed(client, "watch", status);
  return 0;
}

const CommandSpec kWatchCommand = {
    "watch", "live tracks, as a table or JSON lines",
    R"(usage: stevi watch [--count N] [--json] [--confirmed] [--min-score S]

Live tracks: a table, or one TrackFrame JSON per line (--json). --confirmed hides tentative
tracks; --min-score S (0..1) hides those whose detection scored below S. --count N stops after N
frames.
)",
    &Watch};

}  // namespace stevi::client::commands
