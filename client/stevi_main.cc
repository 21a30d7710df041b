// stevi: the command-line client of stevi-server.
#include <algorithm>
#include <pthread.h>

#include <csignal>
#include <cstdio>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <google/protobuf/text_format.h>
#include <google/protobuf/util/json_util.h>

#include "client/client.h"
#include "client/config_edit.h"

namespace {

using stevi::client::Client;
using stevi::client::ClientOptions;
namespace v1 = stevi::v1;

constexpr char kUsage[] = R"(usage: stevi [--server HOST:PORT] [--timeout SECONDS] COMMAND [ARGS]

Commands:
  watch [--count N] [--json] [--confirmed] [--min-score S]
                               live tracks: a table, or one TrackFrame JSON per line;
                               --confirmed hides tentative tracks, --min-score S (0..1)
                               those whose detection scored below S
  status [--json]              source state, frame rates, drops, stage timings, subscribers
  config get [--json]          the active pipeline configuration
  config set KEY=VALUE...      change it while running, e.g. algorithm=canonical,
                               matcher.kind=semi_global, canonical.threshold_range_m=60
  snapshot --out PREFIX        write PREFIX_disparity16.png, PREFIX_disparity_colour.png,
                               PREFIX_left.png, PREFIX_annotated.png (boxes, ids, ranges)
                               and PREFIX_meta.json

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
  out << "\n";
  if (f.tracks_size() > 0) {
    out << "    id  state       age        box (x,y wxh)   depth m   range m  sigma m   disp px"
           "  rate m/s     ttc s   miss m\n";
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
        << std::setw(9) << optional(t.has_closest_approach_m(), t.closest_approach_m()) << "\n";
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
            << "rate         " << s.fps_in() << " fps in, " << s.fps_out() << " fps out\n";
  std::cout << std::setprecision(2) << "timings      ";
  for (int i = 0; i < s.timings_size(); ++i) {
    std::cout << (i ? ", " : "") << s.timings(i).stage() << " " << s.timings(i).ms() << " ms";
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

}  // namespace

int main(int argc, char** argv) {
  ClientOptions options;
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
    } else {
      return Usage("unknown option '" + args[i] + "'");
    }
  }
  if (i >= args.size()) return Usage("expected a command (watch, status, config, snapshot)");
  const std::string command = args[i];
  const std::vector<std::string> rest(args.begin() + static_cast<long>(i) + 1, args.end());
  Client client(options);
  if (command == "watch") return Watch(client, rest);
  if (command == "status") return PrintStatus(client, rest);
  if (command == "config") return Config(client, rest);
  if (command == "snapshot") return Snapshot(client, rest);
  return Usage("unknown command '" + command + "'");
}
