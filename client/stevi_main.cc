// stevi: the command-line client of stevi-server.
#include <algorithm>
#include <pthread.h>

#include <atomic>
#include <cctype>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <mutex>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <google/protobuf/text_format.h>
#include <google/protobuf/util/json_util.h>

#include "client/avoid.h"
#include "client/client.h"
#include "client/config_edit.h"
#include "client/export.h"

namespace {

using stevi::client::Client;
using stevi::client::ClientOptions;
namespace v1 = stevi::v1;

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
  calibration list [--json]    stored calibrations and the active one
  calibration get ID [--yaml]  one calibration: report, or its YAML file
  calibration activate ID      switch the running server to it (between two frames)

--server defaults to 127.0.0.1:50051; --timeout (seconds, default 5) bounds each call.
Exit status: 0 on success, 1 when the server fails or cannot be reached, 2 on bad usage.
)";

int Usage(const std::string& problem) {
  std::cerr << "stevi: " << problem << " (see stevi --help)\n";
  return 2;
}

int RpcFailed(const Client& client, const std::string& what, const grpc::Status& status) {
  std::string message = status.error_message();
  std::replace(message.begin(), message.end(), '\n', ' ');
  if (status.error_code() == grpc::StatusCode::UNAVAILABLE ||
      status.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED) {
    std::cerr << "stevi: " << what << ": cannot reach the server at " << client.options().address
              << " (" << stevi::client::StatusCodeName(status.error_code()) << ": " << message
              << ")\n";
  } else {
    std::cerr << "stevi: " << what << ": " << stevi::client::StatusCodeName(status.error_code())
              << ": " << message << "\n";
  }
  return 1;
}

std::string Json(const google::protobuf::Message& message) {
  google::protobuf::util::JsonPrintOptions options;
  options.preserve_proto_field_names = true;
  options.always_print_primitive_fields = true;
  std::string out;
  (void)google::protobuf::util::MessageToJsonString(message, &out, options);
  return out;
}

std::string ShortEnum(const std::string& name, const std::string& prefix) {
  std::string out = name.rfind(prefix, 0) == 0 ? name.substr(prefix.size()) : name;
  std::transform(out.begin(), out.end(), out.begin(), [](unsigned char c) { return std::tolower(c); });
  return out;
}

void PrintFrameTable(const v1::TrackFrame& f) {
  std::ostringstream out;
  out << std::fixed << std::setprecision(3);
  out << "frame " << f.frame_id() << "  t=" << f.capture_time_ns() / 1e9 << "s  "
      << ShortEnum(v1::Algorithm_Name(f.algorithm()), "ALGORITHM_") << "  " << f.tracks_size()
      << (f.tracks_size() == 1 ? " obstacle" : " obstacles");
  if (f.dropped_frames() > 0) out << "  (dropped " << f.dropped_frames() << ")";
  const bool geo = f.geo_status() == v1::GEO_STATUS_OK;
  if (f.geo_status() != v1::GEO_STATUS_UNSPECIFIED && !geo) out << "  no geodetic: " << f.geo_message();
  out << "\n";
  if (f.tracks_size() > 0) {
    out << "    id  state       age        box (x,y wxh)   depth m   range m  sigma m   disp px"
           "  rate m/s     ttc s   miss m"
        << (geo ? "       lat deg      lon deg    alt m  sigma h/v m" : "") << "\n";
  }
  out << std::setprecision(2);
  for (const v1::Track& t : f.tracks()) {
    std::ostringstream box;
    box << t.bbox().x() << "," << t.bbox().y() << " " << t.bbox().width() << "x"
        << t.bbox().height();
    const auto optional = [](bool has, double value) {
      std::ostringstream s;
      if (has) {
        s << std::fixed << std::setprecision(1) << value;
      } else {
        s << "-";
      }
      return s.str();
    };
    out << std::setw(6) << t.track_id() << "  " << std::left << std::setw(10)
        << ShortEnum(v1::TrackState_Name(t.state()), "TRACK_STATE_") << std::right
        << std::setw(5) << t.age_frames() << std::setw(21) << box.str() << std::setw(10)
        << t.depth_m() << std::setw(10) << t.range_m() << std::setw(9) << t.range_sigma_m()
        << std::setw(10) << t.disparity_px() << std::setw(10) << t.range_rate_mps()
        << std::setw(10) << optional(t.has_time_to_collision_s(), t.time_to_collision_s())
        << std::setw(9) << optional(t.has_closest_approach_m(), t.closest_approach_m());
    if (geo && t.has_geodetic()) {
      out << std::setprecision(7) << std::setw(14) << t.geodetic().lat_deg() << std::setw(13)
          << t.geodetic().lon_deg() << std::setprecision(1) << std::setw(9) << t.geodetic().alt_m()
          << std::setw(7) << t.position_sigma_m().horizontal_m() << "/"
          << t.position_sigma_m().vertical_m() << std::setprecision(2);
    }
    out << "\n";
  }
  std::cout << out.str() << std::flush;
}

int Watch(Client& client, const std::vector<std::string>& args) {
  uint64_t count = 0;
  bool json = false;
  stevi::client::StreamOptions options;
  for (size_t i = 0; i < args.size(); ++i) {
    if (args[i] == "--json") {
      json = true;
    } else if (args[i] == "--confirmed") {
      options.confirmed_only = true;
    } else if (args[i] == "--min-score" && i + 1 < args.size()) {
      size_t used = 0;
      double s = -1;
      try {
        s = std::stod(args[++i], &used);
      } catch (const std::exception&) {
        used = 0;
      }
      if (used != args[i].size() || !(s >= 0 && s <= 1)) {
        return Usage("watch --min-score: expected a number in [0, 1], got '" + args[i] + "'");
      }
      options.min_score = s;
    } else if (args[i] == "--count" && i + 1 < args.size()) {
      try {
        size_t used = 0;
        const long long n = std::stoll(args[++i], &used);
        if (used != args[i].size() || n < 1) throw std::invalid_argument("count");
        count = static_cast<uint64_t>(n);
      } catch (const std::exception&) {
        return Usage("watch --count: expected a whole number >= 1, got '" + args[i] + "'");
      }
    } else {
      return Usage("watch: unexpected argument '" + args[i] + "'");
    }
  }
  options.max_frames = count;
  // Ctrl-C or SIGTERM ends the stream cleanly: a thread waits for them (a signal handler may not
  // take the client's lock). It is detached; the process exits when the stream ends.
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGINT);
  sigaddset(&stop_signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);
  std::thread([&client, stop_signals] {
    int signal_number = 0;
    sigwait(&stop_signals, &signal_number);
    client.Cancel();
  }).detach();
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

std::string RecordingLine(const v1::RecordingStatus& r) {
  std::ostringstream out;
  out << (r.active() ? "RECORDING " : "stopped ") << r.dir() << ": " << r.frames_written()
      << " frames, " << std::fixed << std::setprecision(1) << r.bytes_written() / 1048576.0
      << " MiB of " << r.max_bytes() / 1048576.0 << " MiB, " << r.frames_dropped() << " dropped";
  if (!r.stop_reason().empty()) out << " (" << r.stop_reason() << ")";
  return out.str();
}

// stevi record start [--name NAME] [--max-mb MB] | stop
int Record(Client& client, const std::vector<std::string>& args) {
  if (args.empty()) return Usage("record: expected 'start' or 'stop'");
  bool json = false;
  v1::RecordingStatus status;
  if (args[0] == "stop") {
    for (size_t i = 1; i < args.size(); ++i) {
      if (args[i] == "--json") {
        json = true;
      } else {
        return Usage("record stop: unexpected argument '" + args[i] + "'");
      }
    }
    if (grpc::Status s = client.StopRecording(&status); !s.ok()) {
      return RpcFailed(client, "record stop", s);
    }
  } else if (args[0] == "start") {
    v1::StartRecordingRequest request;
    for (size_t i = 1; i < args.size(); ++i) {
      const std::string& a = args[i];
      if (a == "--json") {
        json = true;
      } else if ((a == "--name" || a == "--max-mb") && i + 1 < args.size()) {
        const std::string& v = args[++i];
        if (a == "--name") {
          request.set_name(v);
        } else {
          char* end = nullptr;
          const double mb = std::strtod(v.c_str(), &end);
          if (end == v.c_str() || *end != '\0' || !(mb >= 1 && mb <= 16e6)) {
            return Usage("record start: --max-mb must be a size in MiB, 1..16000000 (got '" + v + "')");
          }
          request.set_max_bytes(static_cast<uint64_t>(mb * 1048576.0));
        }
      } else {
        return Usage("record start: unexpected argument '" + a + "'");
      }
    }
    if (grpc::Status s = client.StartRecording(request, &status); !s.ok()) {
      return RpcFailed(client, "record start", s);
    }
  } else {
    return Usage("record: expected 'start' or 'stop' (got '" + args[0] + "')");
  }
  if (json) {
    std::cout << Json(status) << "\n";
  } else {
    std::cout << RecordingLine(status) << "\n";
  }
  return 0;
}

int PrintStatus(Client& client, const std::vector<std::string>& args) {
  const bool json = args.size() == 1 && args[0] == "--json";
  if (!args.empty() && !json) return Usage("status: unexpected argument '" + args[0] + "'");
  v1::GetStatusResponse s;
  if (grpc::Status status = client.GetStatus(&s); !status.ok()) {
    return RpcFailed(client, "status", status);
  }
  if (json) {
    std::cout << Json(s) << "\n";
    return 0;
  }
  std::cout << std::fixed << std::setprecision(1);
  std::cout << "source       " << s.source() << " ("
            << ShortEnum(v1::SourceState_Name(s.source_state()), "SOURCE_STATE_") << ")\n";
  if (!s.source_error().empty()) std::cout << "last error   " << s.source_error() << "\n";
  std::cout << "algorithm    " << ShortEnum(v1::Algorithm_Name(s.algorithm()), "ALGORITHM_") << "\n"
            << "calibration  " << s.calibration_id() << "\n"
            << "uptime       " << s.uptime_s() << " s\n"
            << "frames       " << s.frames_captured() << " captured, " << s.frames_processed()
            << " processed, " << s.frames_dropped_capture() << " dropped at capture, "
            << s.frames_failed() << " failed\n"
            << "rate         " << s.fps_in() << " fps in, " << s.fps_out() << " fps out\n"
            << "workers      " << s.pipeline_workers() << " (frames at once), OpenCV threads "
            << s.opencv_threads() << "\n";
  if (s.image_width() > 0) {
    std::cout << "images       " << s.image_width() << "x" << s.image_height();
    if (s.binning() > 1) {
      std::cout << ", processed at " << s.processed_width() << "x" << s.processed_height()
                << " (binned " << s.binning() << "x" << s.binning()
                << ": pipeline.max_width_px; boxes are in these pixels)";
    }
    std::cout << "\n";
  }
  std::cout << std::setprecision(2) << "timings      ";
  for (int i = 0; i < s.timings_size(); ++i) {
    std::cout << (i ? ", " : "") << s.timings(i).stage() << " " << s.timings(i).ms() << " ms";
  }
  const v1::PairingStatus& p = s.pairing();
  if (p.pairs() > 0 || p.unpaired_dropped() > 0 || p.incomplete_dropped() > 0 || p.reconnects() > 0) {
    std::cout << "\npairing      " << p.pairs() << " pairs, " << p.unpaired_dropped()
              << " unpaired dropped, " << p.incomplete_dropped() << " incomplete dropped, "
              << p.reconnects() << " reconnects; skew last " << p.last_skew_ns() * 1e-6
              << " ms, mean |skew| " << p.mean_abs_skew_ns() * 1e-6 << " ms, max "
              << p.max_abs_skew_ns() * 1e-6 << " ms";
  }
  if (!s.recording().dir().empty()) {
    std::cout << "\nrecording    " << RecordingLine(s.recording());
  }
  std::cout << "\nsubscribers  " << s.subscribers_size() << "\n";
  for (const v1::SubscriberStatus& sub : s.subscribers()) {
    std::cout << "  #" << sub.subscriber_id() << " " << sub.peer() << ": " << sub.frames_sent()
              << " sent, " << sub.frames_dropped() << " dropped\n";
  }
  return 0;
}

int Config(Client& client, const std::vector<std::string>& args) {
  if (args.empty()) return Usage("config: expected 'get' or 'set'");
  if (args[0] == "get") {
    const bool json = args.size() == 2 && args[1] == "--json";
    if (args.size() > 1 && !json) return Usage("config get: unexpected argument '" + args[1] + "'");
    v1::PipelineConfig config;
    if (grpc::Status status = client.GetPipelineConfig(&config); !status.ok()) {
      return RpcFailed(client, "config get", status);
    }
    if (json) {
      std::cout << Json(config) << "\n";
    } else {
      std::string text;
      google::protobuf::TextFormat::PrintToString(config, &text);
      std::cout << text;
    }
    return 0;
  }
  if (args[0] == "set") {
    if (args.size() < 2) return Usage("config set: expected KEY=VALUE...");
    v1::PipelineConfig update;
    for (size_t i = 1; i < args.size(); ++i) {
      const size_t eq = args[i].find('=');
      if (eq == std::string::npos || eq == 0) {
        return Usage("config set: expected KEY=VALUE, got '" + args[i] + "'");
      }
      const std::string problem =
          stevi::client::SetFieldByPath(update, args[i].substr(0, eq), args[i].substr(eq + 1));
      if (!problem.empty()) return Usage("config set: " + problem);
    }
    v1::PipelineConfig active;
    if (grpc::Status status = client.SetPipelineConfig(update, &active); !status.ok()) {
      return RpcFailed(client, "config set", status);
    }
    std::cout << "applied; algorithm "
              << ShortEnum(v1::Algorithm_Name(active.algorithm()), "ALGORITHM_") << ", matcher "
              << ShortEnum(v1::MatcherKind_Name(active.matcher().kind()), "MATCHER_KIND_") << "\n";
    return 0;
  }
  return Usage("config: unknown subcommand '" + args[0] + "' (get or set)");
}

int Snapshot(Client& client, const std::vector<std::string>& args) {
  if (args.size() != 2 || args[0] != "--out" || args[1].empty()) {
    return Usage("snapshot: expected --out PREFIX");
  }
  const std::string& prefix = args[1];
  v1::DisparitySnapshot snapshot;
  if (grpc::Status status = client.GetDisparitySnapshot(&snapshot, /*annotated=*/true);
      !status.ok()) {
    return RpcFailed(client, "snapshot", status);
  }
  const auto write = [](const std::string& path, const std::string& bytes) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    return static_cast<bool>(out);
  };
  v1::DisparitySnapshot meta = snapshot;
  meta.clear_disparity_png16();
  meta.clear_disparity_colour_png();
  meta.clear_left_png();
  meta.clear_annotated_png();
  const std::vector<std::pair<std::string, std::string>> files = {
      {prefix + "_disparity16.png", snapshot.disparity_png16()},
      {prefix + "_disparity_colour.png", snapshot.disparity_colour_png()},
      {prefix + "_left.png", snapshot.left_png()},
      {prefix + "_annotated.png", snapshot.annotated_png()},
      {prefix + "_meta.json", Json(meta) + "\n"}};
  for (const auto& [path, bytes] : files) {
    if (!write(path, bytes)) {
      std::cerr << "stevi: snapshot: cannot write " << path << "\n";
      return 1;
    }
    std::cout << path << "\n";
  }
  return 0;
}

// Reads a whole file as bytes; false when it cannot be read.
bool ReadFile(const std::string& path, std::string& bytes) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return false;
  std::ostringstream out;
  out << in.rdbuf();
  bytes = out.str();
  return static_cast<bool>(in) || in.eof();
}

// Parses "9x6" into columns and rows (2..100 each).
bool ParseBoard(const std::string& text, int& columns, int& rows) {
  const size_t x = text.find('x');
  if (x == std::string::npos) return false;
  try {
    size_t used_c = 0, used_r = 0;
    columns = std::stoi(text.substr(0, x), &used_c);
    rows = std::stoi(text.substr(x + 1), &used_r);
    return used_c == x && used_r == text.size() - x - 1 && columns >= 2 && columns <= 100 &&
           rows >= 2 && rows <= 100;
  } catch (const std::exception&) {
    return false;
  }
}

bool ParseNumber(const std::string& text, double lo, double hi, double& value) {
  try {
    size_t used = 0;
    value = std::stod(text, &used);
    return used == text.size() && value >= lo && value <= hi;
  } catch (const std::exception&) {
    return false;
  }
}

// "dir/left%02d.jpg" with index i; empty when the pattern has no single integer conversion.
std::string FormatPattern(const std::string& pattern, int index) {
  const size_t percent = pattern.find('%');
  if (percent == std::string::npos || pattern.find('%', percent + 1) != std::string::npos) return "";
  size_t end = percent + 1;
  while (end < pattern.size() && std::isdigit(static_cast<unsigned char>(pattern[end]))) ++end;
  if (end >= pattern.size() || pattern[end] != 'd') return "";
  std::vector<char> buffer(pattern.size() + 32);
  std::snprintf(buffer.data(), buffer.size(), pattern.c_str(), index);
  return buffer.data();
}

void PrintReport(const v1::CalibrationReport& report, bool json) {
  if (json) {
    std::cout << Json(report) << "\n";
    return;
  }
  std::cout << report.text();
  if (!report.text().empty() && report.text().back() != '\n') std::cout << "\n";
  std::cout << "calibration " << (report.calibration_id().empty() ? "(not stored)" : report.calibration_id())
            << ": " << (report.passed() ? "passed" : "FAILED") << " its gates"
            << (report.applied() ? "; now active" : "; not applied") << "\n";
}

int Calibrate(Client& client, const std::vector<std::string>& args) {
  v1::CalibrationSettings settings;
  std::string left_pattern, right_pattern;
  int capture = 0;
  double interval_s = 0.5;
  bool json = false, have_board = false, have_square = false;
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    const bool has_value = i + 1 < args.size();
    double number = 0;
    if (a == "--apply") {
      settings.set_apply(true);
    } else if (a == "--json") {
      json = true;
    } else if (a == "--board" && has_value) {
      int columns = 0, rows = 0;
      if (!ParseBoard(args[++i], columns, rows)) {
        return Usage("calibrate --board: expected COLSxROWS inner corners (2..100), got '" +
                     args[i] + "'");
      }
      settings.mutable_board()->set_columns(columns);
      settings.mutable_board()->set_rows(rows);
      have_board = true;
    } else if (a == "--square-mm" && has_value) {
      if (!ParseNumber(args[++i], 0.1, 10000, number)) {
        return Usage("calibrate --square-mm: expected millimetres in [0.1, 10000], got '" +
                     args[i] + "'");
      }
      settings.mutable_board()->set_square_m(number / 1000.0);
      have_square = true;
    } else if (a == "--left" && has_value) {
      left_pattern = args[++i];
    } else if (a == "--right" && has_value) {
      right_pattern = args[++i];
    } else if (a == "--capture" && has_value) {
      if (!ParseNumber(args[++i], 1, 200, number) || number != static_cast<int>(number)) {
        return Usage("calibrate --capture: expected a whole number of pairs in 1..200, got '" +
                     args[i] + "'");
      }
      capture = static_cast<int>(number);
    } else if (a == "--interval" && has_value) {
      if (!ParseNumber(args[++i], 0, 60, interval_s)) {
        return Usage("calibrate --interval: expected seconds in [0, 60], got '" + args[i] + "'");
      }
    } else if (a == "--min-pairs" && has_value) {
      if (!ParseNumber(args[++i], 1, 1000, number) || number != static_cast<int>(number)) {
        return Usage("calibrate --min-pairs: expected a whole number in 1..1000, got '" + args[i] +
                     "'");
      }
      settings.mutable_gates()->set_min_pairs(static_cast<int>(number));
    } else if (a == "--max-rms" && has_value) {
      if (!ParseNumber(args[++i], 0, 100, number)) {
        return Usage("calibrate --max-rms: expected pixels in [0, 100], got '" + args[i] + "'");
      }
      settings.mutable_gates()->set_max_rms_px(number);
    } else if (a == "--max-epipolar" && has_value) {
      if (!ParseNumber(args[++i], 0, 100, number)) {
        return Usage("calibrate --max-epipolar: expected pixels in [0, 100], got '" + args[i] +
                     "'");
      }
      settings.mutable_gates()->set_max_epipolar_px(number);
    } else if (a == "--alpha" && has_value) {
      if (!ParseNumber(args[++i], 0, 1, number)) {
        return Usage("calibrate --alpha: expected a number in [0, 1], got '" + args[i] + "'");
      }
      settings.set_alpha(number);
    } else {
      return Usage("calibrate: unexpected argument '" + a + "'");
    }
  }
  if (!have_board || !have_square) return Usage("calibrate: --board and --square-mm are required");
  const bool upload = !left_pattern.empty() || !right_pattern.empty();
  if (upload == (capture > 0)) {
    return Usage("calibrate: give either --left and --right patterns, or --capture N");
  }

  v1::CalibrationReport report;
  if (capture > 0) {
    v1::CaptureCalibrationRequest request;
    *request.mutable_settings() = settings;
    request.set_pairs(capture);
    request.set_interval_s(interval_s);
    const grpc::Status status = client.CaptureCalibration(request, [&](const v1::CaptureProgress& p) {
      if (p.has_report()) {
        report = p.report();
      } else if (!json) {
        const v1::CapturedPair& c = p.pair();
        std::cerr << "pair " << c.index() << "/" << c.of() << ": board "
                  << (c.board_left() ? "left " : "") << (c.board_right() ? "right" : "")
                  << (!c.board_left() && !c.board_right() ? "not found" : "") << "; coverage "
                  << std::fixed << std::setprecision(0) << 100 * c.coverage_left() << " % / "
                  << 100 * c.coverage_right() << " %\n";
      }
    });
    if (!status.ok()) return RpcFailed(client, "calibrate", status);
    PrintReport(report, json);
    return report.passed() ? 0 : 1;
  }

  if (left_pattern.empty() || right_pattern.empty()) {
    return Usage("calibrate: --left and --right go together");
  }
  if (FormatPattern(left_pattern, 0).empty() || FormatPattern(right_pattern, 0).empty()) {
    return Usage("calibrate: --left and --right must be printf patterns with one integer "
                 "conversion, e.g. dir/left%02d.jpg");
  }
  std::vector<v1::ImagePair> pairs;
  for (int index = 0; index <= 9999; ++index) {
    const std::string left = FormatPattern(left_pattern, index);
    const std::string right = FormatPattern(right_pattern, index);
    v1::ImagePair pair;
    const bool have_left = ReadFile(left, *pair.mutable_left());
    const bool have_right = ReadFile(right, *pair.mutable_right());
    if (!have_left && !have_right) continue;
    if (have_left != have_right) {
      std::cerr << "stevi: calibrate: " << (have_left ? right : left) << " is missing (its pair "
                << (have_left ? left : right) << " exists)\n";
      return 1;
    }
    pair.set_name(left.substr(left.find_last_of('/') + 1));
    pairs.push_back(std::move(pair));
  }
  if (pairs.empty()) {
    std::cerr << "stevi: calibrate: no image pair matches " << left_pattern << " and "
              << right_pattern << "\n";
    return 1;
  }
  if (!json) std::cerr << "uploading " << pairs.size() << " pairs...\n";
  const grpc::Status status = client.Calibrate(settings, pairs, &report);
  if (!status.ok()) return RpcFailed(client, "calibrate", status);
  PrintReport(report, json);
  return report.passed() ? 0 : 1;
}

// WGS84 to a local north-east-down frame at `origin` (flat earth with the ellipsoid's radii of
// curvature there: centimetres over a few kilometres, which is the obstacle picture's extent).
stevi::client::Ned LocalNed(const v1::Geodetic& origin, const v1::Geodetic& point) {
  constexpr double a = 6378137.0, e2 = 6.69437999014e-3, deg = 3.14159265358979323846 / 180;
  const double s = std::sin(origin.lat_deg() * deg);
  const double w = std::sqrt(1 - e2 * s * s);
  const double meridian = a * (1 - e2) / (w * w * w), normal = a / w;
  double dlon = point.lon_deg() - origin.lon_deg();
  if (dlon > 180) dlon -= 360;
  if (dlon < -180) dlon += 360;
  return {(point.lat_deg() - origin.lat_deg()) * deg * (meridian + origin.alt_m()),
          dlon * deg * (normal + origin.alt_m()) * std::cos(origin.lat_deg() * deg),
          origin.alt_m() - point.alt_m()};
}

int64_t SteadyNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

int Avoid(Client& client, const std::vector<std::string>& args) {
  namespace sc = stevi::client;
  sc::AdvisorOptions options;
  uint64_t count = 0;
  for (size_t i = 0; i < args.size(); ++i) {
    double number = 0;
    if (args[i] == "--count" && i + 1 < args.size()) {
      if (!ParseNumber(args[++i], 1, 1e12, number) || number != static_cast<double>(static_cast<int64_t>(number))) {
        return Usage("avoid --count: expected a whole number >= 1, got '" + args[i] + "'");
      }
      count = static_cast<uint64_t>(number);
    } else if (args[i] == "--protected-radius" && i + 1 < args.size()) {
      if (!ParseNumber(args[++i], 0.1, 10000, number)) {
        return Usage("avoid --protected-radius: expected metres in [0.1, 10000], got '" + args[i] + "'");
      }
      options.avoid.protected_radius_m = number;
    } else {
      return Usage("avoid: unexpected argument '" + args[i] + "'");
    }
  }
  sc::Advisor advisor(options);
  std::mutex mu;  // the advisor and stdout, shared by the stream and the watchdog
  int64_t last_no_data_print = 0;
  const auto print = [&](const sc::Advisory& advisory) {
    std::cout << sc::AdvisoryJson(advisory) << "\n" << std::flush;
  };
  // The watchdog: never silent, never CLEAR on stale data.
  std::atomic<bool> done{false};
  std::thread watchdog([&] {
    while (!done) {
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
      std::lock_guard lock(mu);
      const int64_t now = SteadyNowNs();
      const sc::Advisory advisory = advisor.OnTick(now);
      if (advisory.level == sc::AdvisoryLevel::kNoData &&
          now - last_no_data_print >= options.no_data_after_ns) {
        print(advisory);
        last_no_data_print = now;
      }
    }
  });
  std::optional<v1::Geodetic> origin;
  sc::StreamOptions stream;
  stream.max_frames = count;
  stream.reconnect = true;
  // Live (no --count): never give up. With --count (tests, scripts): give up after 3 attempts.
  stream.max_reconnect_attempts = count > 0 ? 3 : 0;
  const grpc::Status status = client.StreamTracks(
      [&](const v1::TrackFrame& frame) {
        std::lock_guard lock(mu);
        const int64_t now = SteadyNowNs();
        if (frame.geo_status() != v1::GEO_STATUS_OK || !frame.has_vehicle()) {
          sc::Advisory advisory;
          advisory.t_ns = now;
          advisory.level = sc::AdvisoryLevel::kNoData;
          advisory.reason = "no vehicle pose: " + frame.geo_message();
          print(advisory);
          return true;
        }
        if (!origin) origin = frame.vehicle().position();
        sc::OwnVehicle own;
        own.position_m = LocalNed(*origin, frame.vehicle().position());
        own.velocity_mps = {frame.vehicle().velocity().n_mps(), frame.vehicle().velocity().e_mps(),
                            frame.vehicle().velocity().d_mps()};
        std::vector<sc::Obstacle> obstacles;
        for (const v1::Track& t : frame.tracks()) {
          if (!t.has_geodetic()) continue;
          sc::Obstacle o;
          o.track_id = t.track_id();
          o.position_m = LocalNed(*origin, t.geodetic());
          o.velocity_mps = {t.velocity_ned().n_mps(), t.velocity_ned().e_mps(), t.velocity_ned().d_mps()};
          o.sigma_horizontal_m = t.position_sigma_m().horizontal_m();
          o.sigma_vertical_m = t.position_sigma_m().vertical_m();
          o.range_rate_sigma_mps = t.range_rate_sigma_mps();
          o.hits = t.hits();
          o.state = t.state() == v1::TRACK_STATE_TENTATIVE ? sc::ObstacleState::kTentative
                    : t.state() == v1::TRACK_STATE_COASTING ? sc::ObstacleState::kCoasting
                                                            : sc::ObstacleState::kConfirmed;
          o.score = t.score();
          obstacles.push_back(o);
        }
        print(advisor.OnFrame(now, own, obstacles));
        return true;
      },
      stream);
  done = true;
  watchdog.join();
  if (!status.ok()) return RpcFailed(client, "avoid", status);
  return 0;
}

// The track points of one frame: tracks that are not tentative and have a geodetic position.
void CollectTrackPoints(const v1::TrackFrame& frame, std::vector<stevi::client::TrackPoint>& points) {
  for (const v1::Track& t : frame.tracks()) {
    if (!t.has_geodetic() || t.state() == v1::TRACK_STATE_TENTATIVE) continue;
    stevi::client::TrackPoint p;
    p.track_id = t.track_id();
    p.unix_time_ns = frame.capture_unix_time_ns();
    p.lat_deg = t.geodetic().lat_deg();
    p.lon_deg = t.geodetic().lon_deg();
    p.alt_m = t.geodetic().alt_m();
    if (t.has_position_sigma_m()) p.horizontal_sigma_m = t.position_sigma_m().horizontal_m();
    points.push_back(p);
  }
}

int Export(Client& client, const std::vector<std::string>& args) {
  std::string format, out_path, in_path;
  uint64_t count = 0;
  stevi::client::KmlOptions kml;
  for (size_t i = 0; i < args.size(); ++i) {
    const bool has_value = i + 1 < args.size();
    double number = 0;
    if (args[i] == "--format" && has_value) {
      format = args[++i];
      if (format != "kml" && format != "geojson") {
        return Usage("export --format: expected kml or geojson, got '" + format + "'");
      }
    } else if (args[i] == "--out" && has_value) {
      out_path = args[++i];
    } else if (args[i] == "--in" && has_value) {
      in_path = args[++i];
    } else if (args[i] == "--count" && has_value) {
      if (!ParseNumber(args[++i], 1, 1e9, number) || number != static_cast<double>(static_cast<int64_t>(number))) {
        return Usage("export --count: expected a whole number >= 1, got '" + args[i] + "'");
      }
      count = static_cast<uint64_t>(number);
    } else if (args[i] == "--geoid-undulation" && has_value) {
      if (!ParseNumber(args[++i], -120, 100, number)) {
        return Usage("export --geoid-undulation: expected metres in [-120, 100], got '" + args[i] + "'");
      }
      kml.geoid_undulation_m = number;
    } else {
      return Usage("export: unexpected argument '" + args[i] + "'");
    }
  }
  if (format.empty() || out_path.empty()) return Usage("export: --format and --out are required");
  if (in_path.empty() == (count == 0)) return Usage("export: give either --count N or --in FILE");

  std::vector<stevi::client::TrackPoint> points;
  if (!in_path.empty()) {
    std::ifstream in(in_path);
    if (!in) {
      std::cerr << "stevi: export: cannot read " << in_path << "\n";
      return 1;
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
        std::cerr << "stevi: export: " << in_path << " line " << number_of_line
                  << ": not a TrackFrame JSON line (as `stevi watch --json` writes)\n";
        return 1;
      }
      CollectTrackPoints(frame, points);
    }
  } else {
    stevi::client::StreamOptions stream;
    stream.max_frames = count;
    const grpc::Status status = client.StreamTracks(
        [&](const v1::TrackFrame& frame) {
          CollectTrackPoints(frame, points);
          return true;
        },
        stream);
    if (!status.ok()) return RpcFailed(client, "export", status);
  }
  for (const std::string& problem : stevi::client::ValidateTrackPoints(points)) {
    std::cerr << "stevi: export: left out " << problem << "\n";
  }
  const std::string text =
      format == "kml" ? stevi::client::ToKml(points, kml) : stevi::client::ToGeoJson(points);
  std::ofstream out(out_path, std::ios::binary | std::ios::trunc);
  out << text;
  if (!out) {
    std::cerr << "stevi: export: cannot write " << out_path << "\n";
    return 1;
  }
  std::cout << out_path << ": " << points.size() << " points\n";
  return 0;
}

int Calibration(Client& client, const std::vector<std::string>& args) {
  if (args.empty()) return Usage("calibration: expected list, get ID or activate ID");
  if (args[0] == "list") {
    const bool json = args.size() == 2 && args[1] == "--json";
    if (args.size() > 1 && !json) return Usage("calibration list: unexpected argument '" + args[1] + "'");
    v1::ListCalibrationsResponse list;
    if (grpc::Status status = client.ListCalibrations(&list); !status.ok()) {
      return RpcFailed(client, "calibration list", status);
    }
    if (json) {
      std::cout << Json(list) << "\n";
      return 0;
    }
    std::cout << "  id            size        rms px  baseline m  gates\n";
    for (const v1::CalibrationSummary& c : list.calibrations()) {
      std::ostringstream size;
      size << c.width() << "x" << c.height();
      std::cout << (c.active() ? "* " : "  ") << std::left << std::setw(14) << c.calibration_id()
                << std::setw(12) << size.str() << std::right << std::fixed << std::setprecision(3)
                << std::setw(6) << c.rms_px() << std::setprecision(4) << std::setw(12)
                << c.baseline_m() << "  " << (c.passed() ? "passed" : "FAILED") << "\n";
    }
    if (list.calibrations_size() == 0) std::cout << "  (none stored)\n";
    std::cout << "active: " << (list.active_id().empty() ? "(the source's own)" : list.active_id())
              << "\n";
    for (const std::string& problem : list.store_problems()) std::cout << "problem: " << problem << "\n";
    return 0;
  }
  if ((args[0] == "get" || args[0] == "activate") && args.size() >= 2) {
    v1::CalibrationRecord record;
    const bool activate = args[0] == "activate";
    if (activate && args.size() != 2) return Usage("calibration activate: expected one ID");
    const bool yaml = !activate && args.size() == 3 && args[2] == "--yaml";
    if (!activate && args.size() > 2 && !yaml) {
      return Usage("calibration get: unexpected argument '" + args[2] + "'");
    }
    const grpc::Status status = activate ? client.ActivateCalibration(args[1], &record)
                                         : client.GetCalibration(args[1], &record);
    if (!status.ok()) return RpcFailed(client, "calibration " + args[0], status);
    if (yaml) {
      std::cout << record.yaml();
    } else if (activate) {
      std::cout << "active: " << record.summary().calibration_id() << "\n";
    } else {
      PrintReport(record.report(), false);
    }
    return 0;
  }
  return Usage("calibration: expected list, get ID or activate ID");
}

}  // namespace

int main(int argc, char** argv) {
  ClientOptions options;
  grpc::SslCredentialsOptions tls;
  bool use_tls = false;
  std::vector<std::string> args(argv + 1, argv + argc);
  size_t i = 0;
  for (; i < args.size() && args[i].rfind("--", 0) == 0; ++i) {
    if (args[i] == "--help") {
      std::cout << kUsage;
      return 0;
    }
    if (args[i] == "--server" && i + 1 < args.size()) {
      options.address = args[++i];
    } else if (args[i] == "--timeout" && i + 1 < args.size()) {
      try {
        size_t used = 0;
        const double seconds = std::stod(args[++i], &used);
        if (used != args[i].size() || !(seconds > 0 && seconds <= 3600)) throw std::invalid_argument("t");
        options.timeout = std::chrono::milliseconds(static_cast<int64_t>(seconds * 1000));
      } catch (const std::exception&) {
        return Usage("--timeout: expected seconds in (0, 3600], got '" + args[i] + "'");
      }
    } else if ((args[i] == "--tls-ca" || args[i] == "--tls-cert" || args[i] == "--tls-key" ||
                args[i] == "--token-file") &&
               i + 1 < args.size()) {
      const std::string flag = args[i];
      const std::string path = args[++i];
      std::ifstream in(path, std::ios::binary);
      std::ostringstream text;
      text << in.rdbuf();
      if (!in || text.str().empty()) return Usage(flag + ": cannot read '" + path + "'");
      if (flag == "--tls-ca") tls.pem_root_certs = text.str();
      if (flag == "--tls-cert") tls.pem_cert_chain = text.str();
      if (flag == "--tls-key") tls.pem_private_key = text.str();
      if (flag == "--token-file") {
        std::string token = text.str().substr(0, text.str().find('\n'));
        while (!token.empty() && (token.back() == '\r' || token.back() == ' ')) token.pop_back();
        options.bearer_token = token;
      }
      use_tls |= flag != "--token-file";
    } else {
      return Usage("unknown option '" + args[i] + "'");
    }
  }
  if (tls.pem_cert_chain.empty() != tls.pem_private_key.empty()) {
    return Usage("--tls-cert and --tls-key go together");
  }
  if (use_tls) options.credentials = grpc::SslCredentials(tls);
  if (i >= args.size()) {
    return Usage("expected a command (watch, status, config, snapshot, calibrate, calibration)");
  }
  const std::string command = args[i];
  const std::vector<std::string> rest(args.begin() + static_cast<long>(i) + 1, args.end());
  Client client(options);
  if (command == "watch") return Watch(client, rest);
  if (command == "status") return PrintStatus(client, rest);
  if (command == "config") return Config(client, rest);
  if (command == "snapshot") return Snapshot(client, rest);
  if (command == "calibrate") return Calibrate(client, rest);
  if (command == "avoid") return Avoid(client, rest);
  if (command == "record") return Record(client, rest);
  if (command == "export") return Export(client, rest);
  if (command == "calibration") return Calibration(client, rest);
  return Usage("unknown command '" + command + "'");
}
