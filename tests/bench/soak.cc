// stevi-soak (issue 26): real processes for a long time, with server restarts and camera losses,
// sampling every process's memory, descriptors and threads, and the frames and latency the
// clients see. See tests/bench/README.md ("The soak") for what it runs and what it checks.
//
// Run it inside tests/drivers/fake_camera_netns.sh (the fake GigE cameras need 127.0.0.2 and a
// private GVCP port), e.g.
//   tests/drivers/fake_camera_netns.sh build/bin/stevi-soak --out /tmp/soak
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <regex>
#include <string>
#include <thread>
#include <vector>

#include "client/lib/client.h"
#include "client/mavlink/codec.h"
#include "client/mavlink/messages.h"
#include "core/common/flags.h"
#include "core/geometry/calibration_io.h"
#include "drivers/synthetic/scenarios.h"
#include "tests/bench/bench_flags.h"
#include "tests/bench/soak_process.h"
#include "tests/bench/soak_report.h"
#include "tests/testing/test_autopilot.h"
#include "tests/testing/ws_client.h"

namespace stevi::soak {
namespace {

namespace ml = client::mavlink;
using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

std::atomic<bool> g_stop{false};
void OnSignal(int /*signal*/) { g_stop = true; }

const Clock::time_point g_t0 = Clock::now();
double Now() { return std::chrono::duration<double>(Clock::now() - g_t0).count(); }
int64_t UnixNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// Sleeps `seconds` in short steps; false when the soak is stopping.
bool SleepFor(double seconds) {
  const double until = Now() + seconds;
  while (!g_stop) {
    const double left = until - Now();
    if (left <= 0) return true;
    std::this_thread::sleep_for(std::chrono::duration<double>(std::min(left, 0.1)));
  }
  return false;
}

struct Options {
  double minutes = 30;
  double warmup_minutes = 5;
  double compare_minutes = 5;
  double restart_every_min = 5;
  double camera_loss_every_min = 3;
  double camera_down_s = 15;
  double sample_every_s = 60;
  double outage_margin_s = 2;
  double fps = 15;
  double camera_fps = 10;
  int clients = 16;
  int clients_b = 2;
  int ws_clients = 4;
  int64_t export_points = 20000;
  bool cameras = true;
  std::string out = "soak-out";
  std::string bin = STEVI_SOAK_BINARY_DIR;
  std::string fake_camera = STEVI_SOAK_FAKE_CAMERA;
};

constexpr char kUsage[] = R"(usage: stevi-soak [flags]  (inside tests/drivers/fake_camera_netns.sh)
  --minutes N             how long (30)
  --warmup-minutes N      not judged for memory, descriptors and threads (5)
  --compare-minutes N     the first N minutes after the warm-up are compared with the last N (5)
  --restart-every MIN     SIGTERM and restart of server A (5)
  --camera-loss-every MIN SIGKILL of one fake camera of server B, left and right in turn (3)
  --camera-down-seconds S before the camera is started again (15)
  --sample-every S        a sample and a window (60)
  --outage-margin S       added to each outage window after its first frame (2)
  --fps F                 server A's synthetic rig (15)
  --camera-fps F          server B's cameras (10)
  --clients N             gRPC StreamTracks clients on server A (16)
  --clients-b N           and on server B (2)
  --ws-clients N          WebSocket clients of the station (4)
  --export-points N       the station's --export-points, its export history bound (20000)
  --no-cameras            no server B and no cameras (outside the namespace)
  --out DIR               CSV files, report.txt, soak.png and the children's logs (soak-out)
  --bin DIR               stevi-server and stevi (the build's bin folder)
  --fake-camera PATH      arv-fake-gv-camera-0.8
)";

// The ranges of the numeric flags.
constexpr flags::RealRange kMinutesRange{
    .lo = 0, .hi = bench::kNoUpperBound, .unit = "minutes", .lo_open = true};
constexpr flags::RealRange kSecondsRange{
    .lo = 0, .hi = bench::kNoUpperBound, .unit = "seconds", .lo_open = true};
constexpr flags::RealRange kFpsRange{
    .lo = 0, .hi = bench::kNoUpperBound, .unit = "frames per second", .lo_open = true};
constexpr flags::WholeRange kClientsRange{.lo = 1, .hi = 64, .what = "a whole number of clients"};
constexpr flags::WholeRange kMoreClientsRange{
    .lo = 0, .hi = 64, .what = "a whole number of clients"};
constexpr flags::WholeRange kExportPointsRange{
    .lo = 1, .hi = 10'000'000, .what = "a whole number of points"};

// The flags into `o`; false with the problem in `error`, or with "" after --help.
bool ParseOptions(int argc, char** argv, Options& o, std::string& error) {
  bool help = false;
  flags::FlagSet set("");
  set.Switch("--no-cameras", [&o] { o.cameras = false; })
      .Whole("--export-points", kExportPointsRange, [&o](int64_t n) { o.export_points = n; })
      .Text("--out", &o.out)
      .Text("--bin", &o.bin)
      .Text("--fake-camera", &o.fake_camera)
      .Stop("--help", &help)
      .Stop("-h", &help);
  bench::Real(set, "--minutes", kMinutesRange, &o.minutes);
  bench::Real(set, "--warmup-minutes", kMinutesRange, &o.warmup_minutes);
  bench::Real(set, "--compare-minutes", kMinutesRange, &o.compare_minutes);
  bench::Real(set, "--restart-every", kMinutesRange, &o.restart_every_min);
  bench::Real(set, "--camera-loss-every", kMinutesRange, &o.camera_loss_every_min);
  bench::Real(set, "--camera-down-seconds", kSecondsRange, &o.camera_down_s);
  bench::Real(set, "--sample-every", kSecondsRange, &o.sample_every_s);
  bench::Real(set, "--outage-margin", kSecondsRange, &o.outage_margin_s);
  bench::Real(set, "--fps", kFpsRange, &o.fps);
  bench::Real(set, "--camera-fps", kFpsRange, &o.camera_fps);
  bench::WholeInt(set, "--clients", kClientsRange, &o.clients);
  bench::WholeInt(set, "--clients-b", kMoreClientsRange, &o.clients_b);
  bench::WholeInt(set, "--ws-clients", kMoreClientsRange, &o.ws_clients);
  error = bench::ParseArgs(set, argc, argv);
  if (!error.empty() || help) return false;
  if (o.warmup_minutes + o.compare_minutes > o.minutes) {
    error = "--warmup-minutes + --compare-minutes must not exceed --minutes";
    return false;
  }
  return true;
}

// ---------------------------------------------------------------------------------------------
// Outage windows of one server: from a restart or a camera loss until the first frame any of its
// clients receives after the recovery, plus the margin. Frames are judged as they arrive.

class Outages {
 public:
  explicit Outages(double margin_s) : margin_s_(margin_s) {}
  // Opens a window now; returns its index.
  size_t Open(double t) {
    std::lock_guard lock(mu_);
    windows_.push_back({t, kOpen, false});
    return windows_.size() - 1;
  }
  // The server serves again (or the camera is back): the next frame ends the window.
  void Recovered(size_t i) {
    std::lock_guard lock(mu_);
    windows_[i].recovered = true;
  }
  // Whether a frame arriving at `t` is inside an outage; closes a recovered window.
  bool Classify(double t) {
    std::lock_guard lock(mu_);
    bool inside = false;
    for (auto it = windows_.rbegin(); it != windows_.rend(); ++it) {
      Window& w = *it;
      if (w.end == kOpen && w.start <= t) {
        if (w.recovered) {
          w.first_frame = t;
          w.end = t + margin_s_;
        }
        inside = true;
      } else if (w.start <= t && t <= w.end) {
        inside = true;
      }
      if (w.end != kOpen && w.end + 60 < t) break;  // older windows cannot hold t
    }
    return inside;
  }
  // The first frame after window i's recovery (-1: none yet).
  double FirstFrame(size_t i) {
    std::lock_guard lock(mu_);
    return windows_[i].first_frame;
  }

 private:
  static constexpr double kOpen = std::numeric_limits<double>::infinity();
  struct Window {
    double start, end;
    bool recovered;
    double first_frame = -1;
  };
  const double margin_s_;
  std::mutex mu_;
  std::vector<Window> windows_;
};

// ---------------------------------------------------------------------------------------------
// One stream of frames as one client sees it: delivery, frame_id gaps, dropped_frames, latency.

class Tally {
 public:
  // A stream broke: the next frame starts a new sequence (its frame_id may start again at 1).
  void StreamLost() { fresh_ = true; }
  void OnFrame(uint64_t frame_id, uint64_t dropped_frames, int64_t capture_unix_ns,
               int64_t arrival_unix_ns, bool in_outage) {
    uint64_t gap = 0, dropped = 0;
    if (fresh_ || frame_id <= last_id_) {
      if (!fresh_) ++w_.resets;  // a restarted server, seen without a stream event
      fresh_ = false;
      dropped = dropped_frames;
    } else {
      gap = frame_id - last_id_ - 1;
      dropped = dropped_frames >= last_dropped_ ? dropped_frames - last_dropped_ : dropped_frames;
    }
    last_id_ = frame_id;
    last_dropped_ = dropped_frames;
    if (in_outage) {
      ++w_.delivered_in_outage;
      w_.lost_in_outage += gap;
      w_.dropped_in_outage += dropped;
    } else {
      ++w_.delivered;
      w_.lost += gap;
      w_.dropped += dropped;
      w_.latency.Add(static_cast<double>(arrival_unix_ns - capture_unix_ns) * 1e-6);
    }
  }
  void OnImage() { ++w_.images; }
  // Moves the window's figures into `into` and starts the next window.
  void Flush(StreamWindow& into) {
    StreamWindow one = w_;
    one.clients = 1;
    one.min_client_delivered = w_.delivered;
    into.Merge(one);
    w_.Clear();
  }

 private:
  StreamWindow w_;
  uint64_t last_id_ = 0, last_dropped_ = 0;
  bool fresh_ = true;
};

// A gRPC StreamTracks client that reconnects for ever.
class GrpcClient {
 public:
  GrpcClient(const std::string& address, int index, Outages* outages) : outages_(outages) {
    client::ClientOptions options;
    options.address = address;
    // Distinct channel arguments: a TCP connection of its own, as separate programs would have.
    options.max_message_bytes = (64 << 20) + index;
    client_ = std::make_unique<client::Client>(options);
    thread_ = std::thread([this] { Run(); });
  }
  ~GrpcClient() { Stop(); }
  void Stop() {
    stopping_ = true;
    client_->Cancel();
    if (thread_.joinable()) thread_.join();
  }
  bool got_frames() const { return got_frames_; }
  void Flush(StreamWindow& into) {
    std::lock_guard lock(mu_);
    tally_.Flush(into);
  }

 private:
  void Run() {
    client::StreamOptions options;
    options.reconnect = true;
    options.persist_once_streaming = true;
    options.max_reconnect_attempts = 0;  // never give up
    options.on_event = [this](const client::StreamEvent& e) {
      if (e.kind == client::StreamEvent::Kind::kLost) {
        std::lock_guard lock(mu_);
        tally_.StreamLost();
      }
    };
    while (!stopping_) {
      (void)client_->StreamTracks(
          [this](const v1::TrackFrame& f) {
            const int64_t arrival = UnixNowNs();
            const bool in_outage = outages_->Classify(Now());
            std::lock_guard lock(mu_);
            tally_.OnFrame(f.frame_id(), f.dropped_frames(), f.capture_unix_time_ns(), arrival,
                           in_outage);
            got_frames_ = true;
            return !stopping_;
          },
          options);
      {
        std::lock_guard lock(mu_);
        tally_.StreamLost();
      }
      for (int i = 0; i < 10 && !stopping_; ++i) std::this_thread::sleep_for(100ms);
    }
  }

  Outages* outages_;
  std::unique_ptr<client::Client> client_;
  std::mutex mu_;
  Tally tally_;
  std::atomic<bool> stopping_{false};
  std::atomic<bool> got_frames_{false};
  std::thread thread_;
};

// A Foxglove WebSocket client of the station: every rig's tracks, annotated and disparity images.
class WsClient {
 public:
  WsClient(int port, int rigs, std::vector<Outages*> outages)
      : port_(port), rigs_(rigs), outages_(std::move(outages)), tallies_(rigs) {
    thread_ = std::thread([this] { Run(); });
  }
  ~WsClient() { Stop(); }
  void Stop() {
    stopping_ = true;
    if (thread_.joinable()) thread_.join();
  }
  bool got_frames() const { return got_frames_; }
  uint64_t reconnects() const { return reconnects_; }
  void Flush(int rig, StreamWindow& into) {
    std::lock_guard lock(mu_);
    tallies_[static_cast<size_t>(rig)].Flush(into);
  }

 private:
  struct Sub {
    int rig;
    bool tracks;
  };

  void Run() {
    while (!stopping_) {
      Session();
      if (stopping_) break;
      ++reconnects_;
      {
        std::lock_guard lock(mu_);
        for (Tally& t : tallies_) t.StreamLost();
      }
      for (int i = 0; i < 10 && !stopping_; ++i) std::this_thread::sleep_for(100ms);
    }
  }

  void Session() {
    std::string error;
    testing::WsOptions options;
    options.subprotocols = {"foxglove.sdk.v1", "foxglove.websocket.v1"};
    std::unique_ptr<testing::WsClient> ws =
        testing::WsClient::Connect("127.0.0.1", port_, options, error);
    if (!ws || !ws->open()) return;
    std::map<std::string, uint64_t> channels;  // topic -> channel id
    std::map<uint32_t, Sub> subs;
    std::vector<std::string> wanted;
    for (int k = 1; k <= rigs_; ++k) {
      const std::string rig = "/rig" + std::to_string(k);
      wanted.push_back(rig + "/tracks");
      wanted.push_back(rig + "/image/annotated");
      wanted.push_back(rig + "/image/disparity");
    }
    bool subscribed = false;
    const double connect_deadline = Now() + 20;
    while (!stopping_) {
      const std::optional<testing::WsMessage> m = ws->Receive(250ms);
      if (!subscribed && Now() > connect_deadline) return;
      if (!m) continue;
      if (m->opcode == testing::WsMessage::kEnd || m->opcode == testing::WsMessage::kClose) return;
      if (m->opcode == testing::WsMessage::kText) {
        const nlohmann::json j = nlohmann::json::parse(m->payload, nullptr, false);
        if (j.is_discarded() || !j.contains("op") || j["op"] != "advertise") continue;
        for (const auto& c : j["channels"]) {
          channels[c["topic"].get<std::string>()] = c["id"].get<uint64_t>();
        }
        if (subscribed) continue;
        if (!std::all_of(wanted.begin(), wanted.end(),
                         [&](const std::string& t) { return channels.count(t) > 0; })) {
          continue;
        }
        nlohmann::json list = nlohmann::json::array();
        uint32_t id = 1;
        for (const std::string& topic : wanted) {
          list.push_back({{"id", id}, {"channelId", channels[topic]}});
          subs[id] = Sub{std::stoi(topic.substr(4, topic.find('/', 1) - 4)) - 1,
                         topic.find("/tracks") != std::string::npos};
          ++id;
        }
        if (!ws->SendText(nlohmann::json{{"op", "subscribe"}, {"subscriptions", list}}.dump())) {
          return;
        }
        subscribed = true;
        continue;
      }
      if (m->opcode != testing::WsMessage::kBinary || m->payload.size() < 13 ||
          m->payload[0] != 0x01) {
        continue;
      }
      uint32_t id = 0;
      for (int i = 0; i < 4; ++i) {
        id |= static_cast<uint32_t>(static_cast<uint8_t>(m->payload[static_cast<size_t>(1 + i)]))
              << (8 * i);
      }
      const auto it = subs.find(id);
      if (it == subs.end()) continue;
      const int rig = it->second.rig;
      if (!it->second.tracks) {
        std::lock_guard lock(mu_);
        tallies_[static_cast<size_t>(rig)].OnImage();
        continue;
      }
      const int64_t arrival = UnixNowNs();
      v1::TrackFrame frame;
      if (!frame.ParseFromArray(m->payload.data() + 13, static_cast<int>(m->payload.size() - 13))) {
        continue;
      }
      const bool in_outage = outages_[static_cast<size_t>(rig)]->Classify(Now());
      std::lock_guard lock(mu_);
      tallies_[static_cast<size_t>(rig)].OnFrame(frame.frame_id(), frame.dropped_frames(),
                                                 frame.capture_unix_time_ns(), arrival, in_outage);
      got_frames_ = true;
    }
  }

  const int port_;
  const int rigs_;
  const std::vector<Outages*> outages_;
  std::mutex mu_;
  std::vector<Tally> tallies_;  // by rig
  std::atomic<bool> stopping_{false};
  std::atomic<bool> got_frames_{false};
  std::atomic<uint64_t> reconnects_{0};
  std::thread thread_;
};

// ---------------------------------------------------------------------------------------------

// The station's rig1 export history: the sum of the features' "points" (-1 when unreadable).
int64_t ExportPoints(int station_port) {
  std::string error;
  const std::optional<testing::HttpReply> r =
      testing::HttpRequestOnce("127.0.0.1", station_port, "GET", "/api/rigs/rig1/export.geojson",
                               {}, "", error, std::chrono::seconds(10));
  if (!r || r->status != 200) return -1;
  const nlohmann::json j = nlohmann::json::parse(r->body, nullptr, false);
  if (j.is_discarded() || !j.contains("features")) return -1;
  int64_t points = 0;
  for (const auto& f : j["features"]) points += f["properties"]["points"].get<int64_t>();
  return points;
}

std::string StateName(v1::SourceState s) {
  switch (s) {
    case v1::SOURCE_STATE_STARTING: return "STARTING";
    case v1::SOURCE_STATE_RUNNING: return "RUNNING";
    case v1::SOURCE_STATE_DOWN: return "DOWN";
    case v1::SOURCE_STATE_ENDED: return "ENDED";
    default: return "?";
  }
}

// The children, and everything that talks to them.
class Soak {
 public:
  explicit Soak(Options o) : o_(std::move(o)) {}
  ~Soak() { Shutdown(); }
  int Run(const std::string& command_line);

 private:
  enum Proc { kServerA, kServerB, kStation, kMavlink, kCameraL, kCameraR };
  bool StartAll(std::string& error);
  bool StartServerA(bool first, std::string& error);
  bool StartServerB(std::string& error);
  void TakeSample(Sample& s, double t_rel);
  void RestartServerA();
  void LoseCamera(int which);
  void CameraBack(int which, size_t outage);
  void Shutdown();
  std::string Log(const std::string& name) const { return o_.out + "/logs/" + name + ".log"; }
  double Rel() const { return Now() - run_start_; }

  Options o_;
  SoakResult result_;
  double run_start_ = 0;
  std::vector<std::unique_ptr<ChildProcess>> procs_;  // by Proc (null when not run)
  std::string address_a_, address_b_;
  int station_port_ = 0;
  std::unique_ptr<Outages> outages_a_, outages_b_;
  std::unique_ptr<testing::TestAutopilot> autopilot_;
  std::vector<std::unique_ptr<GrpcClient>> grpc_a_, grpc_b_;
  std::vector<std::unique_ptr<WsClient>> ws_;
  std::unique_ptr<client::Client> status_a_, status_b_;
  uint64_t last_obstacle_distance_ = 0;
  bool shut_down_ = false;
  // Each event's outage window, for its first frame at the end.
  struct Pending {
    size_t event, outage;
    int server;
  };
  std::vector<Pending> pending_;
};

bool Soak::StartServerA(bool first, std::string& error) {
  ChildProcess& a = *procs_[kServerA];
  if (!a.Start(&error)) return false;
  const std::optional<std::string> line = a.WaitForLogLine("event=serving", 60s);
  if (!line) {
    error = "server-A did not start: " + a.LogTail();
    return false;
  }
  if (first) {
    std::smatch m;
    if (!std::regex_search(*line, m, std::regex("127\\.0\\.0\\.1:(\\d+)"))) {
      error = "server-A: no address in " + *line;
      return false;
    }
    address_a_ = "127.0.0.1:" + m[1].str();
    a.SetArgument(2, address_a_);  // restarts listen on the same port, as systemd's would
  }
  return true;
}

bool Soak::StartServerB(std::string& error) {
  ChildProcess& b = *procs_[kServerB];
  // The cameras take a moment to answer Aravis's discovery: an unknown camera is a start error,
  // so the server is started again until it serves (at most 30 tries, a second apart).
  for (int attempt = 0; attempt < 30 && !g_stop; ++attempt) {
    if (!b.Start(&error)) return false;
    const std::optional<std::string> line = b.WaitForLogLine("event=serving", 60s);
    if (line) {
      std::smatch m;
      if (!std::regex_search(*line, m, std::regex("127\\.0\\.0\\.1:(\\d+)"))) {
        error = "server-B: no address in " + *line;
        return false;
      }
      address_b_ = "127.0.0.1:" + m[1].str();
      b.SetArgument(2, address_b_);
      return true;
    }
    b.Terminate(5s);
    SleepFor(1);
  }
  error = "server-B did not start on the fake cameras: " + b.LogTail();
  return false;
}

bool Soak::StartAll(std::string& error) {
  std::filesystem::create_directories(o_.out + "/logs");
  std::filesystem::create_directories(o_.out + "/data-A");
  std::filesystem::create_directories(o_.out + "/data-B");
  procs_.resize(6);
  const std::string server = o_.bin + "/stevi-server", stevi = o_.bin + "/stevi";
  auto fps_text = [](double f) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%g", f);
    return std::string(buf);
  };
  procs_[kServerA] = std::make_unique<ChildProcess>(
      "server-A",
      std::vector<std::string>{server, "--listen", "127.0.0.1:0", "--source", "synthetic", "--fps",
                               fps_text(o_.fps), "--data-dir", o_.out + "/data-A"},
      Log("server-A"));
  if (o_.cameras) {
    procs_[kCameraL] = std::make_unique<ChildProcess>(
        "camera-L", std::vector<std::string>{o_.fake_camera, "-i", "127.0.0.1", "-s", "GV01"},
        Log("camera-L"));
    procs_[kCameraR] = std::make_unique<ChildProcess>(
        "camera-R", std::vector<std::string>{o_.fake_camera, "-i", "127.0.0.2", "-s", "GV02"},
        Log("camera-R"));
    if (!procs_[kCameraL]->Start(&error) || !procs_[kCameraR]->Start(&error)) return false;
    // An ideal 640x480 rig for the cameras' region of interest (they see a test pattern, not a
    // scene: server B is about frames, pairing and faults).
    const std::string calibration = o_.out + "/rig-B.yaml";
    if (!geometry::SaveCalibrationYaml(
             geometry::IdealCalibration(cv::Size(640, 480), 600, 0.12, 320, 240), calibration)
             .ok()) {
      error = "cannot write " + calibration;
      return false;
    }
    procs_[kServerB] = std::make_unique<ChildProcess>(
        "server-B",
        std::vector<std::string>{server, "--listen", "127.0.0.1:0", "--source", "aravis", "--left",
                                 "GV01", "--right", "127.0.0.2", "--calibration", calibration,
                                 "--fps", fps_text(o_.camera_fps), "--exposure-us", "10000",
                                 "--gain-db", "0", "--data-dir", o_.out + "/data-B"},
        Log("server-B"));
    if (!StartServerB(error)) return false;
  }
  if (!StartServerA(true, error)) return false;

  geo::VehicleState pose;
  if (const std::optional<geo::VehicleState> p = drivers::SceneRigPose("airfield")) pose = *p;
  autopilot_ = std::make_unique<testing::TestAutopilot>(pose, /*keep_frames=*/false);
  if (!autopilot_->error().empty()) {
    error = autopilot_->error();
    return false;
  }
  procs_[kMavlink] = std::make_unique<ChildProcess>(
      "mavlink",
      std::vector<std::string>{stevi, "--server", address_a_, "mavlink", "--link",
                               "udp://127.0.0.1:" + std::to_string(autopilot_->port()), "--adsb",
                               "--status-every", "10"},
      Log("mavlink"));
  if (!procs_[kMavlink]->Start(&error)) return false;

  std::string servers = address_a_;
  if (o_.cameras) servers += "," + address_b_;
  procs_[kStation] = std::make_unique<ChildProcess>(
      "station",
      std::vector<std::string>{stevi, "station", "--server", servers, "--listen", "127.0.0.1:0",
                               "--export-points", std::to_string(o_.export_points)},
      Log("station"));
  if (!procs_[kStation]->Start(&error)) return false;
  const std::optional<std::string> line =
      procs_[kStation]->WaitForLogLine("stevi station: serving", 30s);
  std::smatch m;
  if (!line || !std::regex_search(*line, m, std::regex("127\\.0\\.0\\.1:(\\d+)"))) {
    error = "the station did not start: " + procs_[kStation]->LogTail();
    return false;
  }
  station_port_ = std::stoi(m[1].str());

  outages_a_ = std::make_unique<Outages>(o_.outage_margin_s);
  outages_b_ = std::make_unique<Outages>(o_.outage_margin_s);
  for (int i = 0; i < o_.clients; ++i) {
    grpc_a_.push_back(std::make_unique<GrpcClient>(address_a_, i, outages_a_.get()));
  }
  if (o_.cameras) {
    for (int i = 0; i < o_.clients_b; ++i) {
      grpc_b_.push_back(std::make_unique<GrpcClient>(address_b_, 100 + i, outages_b_.get()));
    }
  }
  for (int i = 0; i < o_.ws_clients; ++i) {
    ws_.push_back(
        std::make_unique<WsClient>(station_port_, o_.cameras ? 2 : 1,
                                   std::vector<Outages*>{outages_a_.get(), outages_b_.get()}));
  }
  client::ClientOptions status_options;
  status_options.timeout = 2s;
  status_options.address = address_a_;
  status_a_ = std::make_unique<client::Client>(status_options);
  if (o_.cameras) {
    status_options.address = address_b_;
    status_b_ = std::make_unique<client::Client>(status_options);
  }
  // Every client streaming before the clock starts.
  const double deadline = Now() + 60;
  auto all_streaming = [&] {
    for (const auto& c : grpc_a_) {
      if (!c->got_frames()) return false;
    }
    for (const auto& c : grpc_b_) {
      if (!c->got_frames()) return false;
    }
    for (const auto& c : ws_) {
      if (!c->got_frames()) return false;
    }
    return true;
  };
  while (!all_streaming()) {
    if (Now() > deadline || g_stop) {
      error = "not every client received frames within 60 s";
      return false;
    }
    std::this_thread::sleep_for(100ms);
  }
  return true;
}

void Soak::TakeSample(Sample& s, double t_rel) {
  s.t_s = t_rel;
  const pid_t pids[] = {procs_[kServerA] ? procs_[kServerA]->pid() : -1,
                        procs_[kServerB] ? procs_[kServerB]->pid() : -1,
                        procs_[kStation]->pid(),
                        procs_[kMavlink]->pid(),
                        procs_[kCameraL] ? procs_[kCameraL]->pid() : -1,
                        procs_[kCameraR] ? procs_[kCameraR]->pid() : -1,
                        getpid()};
  for (size_t i = 0; i < s.procs.size(); ++i) {
    s.pids[i] = pids[i];
    s.procs[i] = ReadProc(pids[i]);
  }
  for (auto& c : grpc_a_) c->Flush(s.streams[0]);
  for (auto& c : grpc_b_) c->Flush(s.streams[1]);
  for (auto& c : ws_) {
    c->Flush(0, s.streams[2]);
    if (o_.cameras) c->Flush(1, s.streams[3]);
  }
  const uint64_t od = autopilot_->count(ml::ObstacleDistance::kId);
  s.obstacle_distance = od - last_obstacle_distance_;
  last_obstacle_distance_ = od;
  s.export_points = ExportPoints(station_port_);
  client::Client* status[] = {status_a_.get(), status_b_.get()};
  for (size_t i = 0; i < 2; ++i) {
    v1::GetStatusResponse r;
    if (status[i] != nullptr && status[i]->GetStatus(&r).ok()) {
      s.fps_out[i] = r.fps_out();
      s.source_state[i] = StateName(r.source_state());
    } else {
      s.fps_out[i] = -1;
      s.source_state[i] = status[i] != nullptr ? "unreachable" : "-";
    }
  }
}

void Soak::RestartServerA() {
  Event e;
  e.t_s = Rel();
  e.what = "restart server-A";
  e.server = 0;
  const size_t outage = outages_a_->Open(Now());
  e.stop_ms = static_cast<double>(procs_[kServerA]->Terminate(10s).count());
  std::printf("%7.1f s  server-A stopped (%s) in %.0f ms\n", Rel(),
              procs_[kServerA]->ended_how().c_str(), e.stop_ms);
  std::string error;
  if (!StartServerA(false, error)) {
    std::fprintf(stderr, "stevi-soak: %s\n", error.c_str());
    g_stop = true;
  }
  e.recovered_s = Rel();
  outages_a_->Recovered(outage);
  std::printf("%7.1f s  server-A serving again\n", Rel());
  std::fflush(stdout);
  result_.events.push_back(e);
  pending_.push_back({result_.events.size() - 1, outage, 0});
}

void Soak::LoseCamera(int which) {
  Event e;
  e.t_s = Rel();
  e.what = which == 0 ? "camera-L lost" : "camera-R lost";
  e.server = 1;
  const size_t outage = outages_b_->Open(Now());
  procs_[which == 0 ? kCameraL : kCameraR]->Kill();
  std::printf("%7.1f s  %s (SIGKILL)\n", Rel(), e.what.c_str());
  std::fflush(stdout);
  result_.events.push_back(e);
  pending_.push_back({result_.events.size() - 1, outage, 1});
}

void Soak::CameraBack(int which, size_t event) {
  std::string error;
  ChildProcess& camera = *procs_[which == 0 ? kCameraL : kCameraR];
  if (!camera.Start(&error)) {
    std::fprintf(stderr, "stevi-soak: %s\n", error.c_str());
    g_stop = true;
    return;
  }
  Event& e = result_.events[event];
  e.recovered_s = Rel();
  for (Pending& p : pending_) {
    if (p.event == event) outages_b_->Recovered(p.outage);
  }
  std::printf("%7.1f s  %s started again\n", Rel(), camera.name().c_str());
  std::fflush(stdout);
}

void Soak::Shutdown() {
  if (shut_down_) return;
  shut_down_ = true;
  for (auto& c : grpc_a_) c->Stop();
  for (auto& c : grpc_b_) c->Stop();
  for (auto& c : ws_) c->Stop();
  // The station and the bridge first (their servers going away is not what is measured here),
  // then the servers, then the cameras.
  for (const Proc p : {kStation, kMavlink, kServerA, kServerB, kCameraL, kCameraR}) {
    if (procs_.size() <= static_cast<size_t>(p) || !procs_[p]) continue;
    ChildProcess& c = *procs_[p];
    if (!c.Running()) {
      result_.shutdown.push_back(c.name() + ": not running (" + c.ended_how() + ")");
      continue;
    }
    const auto took = c.Terminate(10s);
    result_.shutdown.push_back(c.name() + ": " + c.ended_how() + " after SIGTERM, " +
                               std::to_string(took.count()) + " ms");
  }
  autopilot_.reset();
}

int Soak::Run(const std::string& command_line) {
  SoakResult& r = result_;
  r.command_line = command_line;
  r.minutes = o_.minutes;
  r.warmup_minutes = o_.warmup_minutes;
  r.compare_minutes = o_.compare_minutes;
  r.sample_every_s = o_.sample_every_s;
  r.outage_margin_s = o_.outage_margin_s;
  r.export_points_bound = o_.export_points;
  r.fps = o_.fps;
  r.camera_fps = o_.cameras ? o_.camera_fps : 0;
  r.process_names = {"server-A", "server-B", "station",   "mavlink",
                     "camera-L", "camera-R", kHarnessName};
  r.server_names = {"server-A", "server-B"};
  r.group_names = {"gRPC A", "gRPC B", "WS rig1 (A)", "WS rig2 (B)"};
  r.group_server = {0, 1, 0, 1};
  std::string error;
  if (!StartAll(error)) {
    std::fprintf(stderr, "stevi-soak: %s\n", error.c_str());
    Shutdown();
    return 1;
  }
  const double total_s = o_.minutes * 60;
  const int windows = static_cast<int>(std::ceil(total_s / o_.sample_every_s - 1e-9));
  // Every sample's storage now, so that the soak's own memory does not grow with the run.
  r.samples.resize(static_cast<size_t>(windows) + 1);
  for (Sample& s : r.samples) {
    s.procs.resize(r.process_names.size());
    s.pids.resize(r.process_names.size(), -1);
    s.fps_out.resize(2, -1);
    s.source_state.resize(2);
    s.streams.resize(r.group_names.size());
  }
  r.events.reserve(static_cast<size_t>(total_s / 60 * 2) + 16);
  pending_.reserve(r.events.capacity());
  std::printf(
      "stevi-soak: server-A %s, server-B %s, station 127.0.0.1:%d; %d + %d gRPC clients, "
      "%d WebSocket clients; logs in %s/logs\n",
      address_a_.c_str(), o_.cameras ? address_b_.c_str() : "(none)", station_port_, o_.clients,
      static_cast<int>(grpc_b_.size()), o_.ws_clients, o_.out.c_str());
  run_start_ = Now();
  TakeSample(r.samples[0], 0);
  // Restarts and camera losses fall half a sample period after the minute marks, so that no
  // sample is taken at the moment a process is replaced.
  const double offset = o_.sample_every_s / 2;
  double next_restart = o_.restart_every_min * 60 + offset;
  double next_loss = o_.camera_loss_every_min * 60 + offset;
  double camera_back = std::numeric_limits<double>::infinity();
  int lost_camera = 0, next_camera = 0;
  size_t lost_event = 0;
  int k = 1;
  while (!g_stop && k <= windows) {
    const double t = Rel();
    const double sample_at = std::min(k * o_.sample_every_s, total_s);
    const double restart_at = next_restart < total_s ? next_restart : 1e300;
    const double loss_at = o_.cameras && next_loss < total_s ? next_loss : 1e300;
    const double next = std::min({sample_at, restart_at, loss_at, camera_back});
    if (t < next) {
      std::this_thread::sleep_for(std::chrono::duration<double>(std::min(next - t, 0.1)));
      continue;
    }
    if (next == sample_at) {
      Sample& s = r.samples[static_cast<size_t>(k)];
      TakeSample(s, Rel());
      const StreamWindow& a = s.streams[0];
      std::printf(
          "%7.1f s  sample %d: RSS A %.1f MB, station %.1f MB, soak %.1f MB; gRPC A %llu frames "
          "(fewest %llu), lost %llu, dropped %llu, p99 %.1f ms; OBSTACLE_DISTANCE %llu; export "
          "%lld points\n",
          s.t_s, k, s.procs[0].rss_kb / 1024.0, s.procs[2].rss_kb / 1024.0,
          s.procs[6].rss_kb / 1024.0, static_cast<unsigned long long>(a.delivered),
          static_cast<unsigned long long>(a.min_client_delivered),
          static_cast<unsigned long long>(a.lost), static_cast<unsigned long long>(a.dropped),
          a.latency.Quantile(0.99), static_cast<unsigned long long>(s.obstacle_distance),
          static_cast<long long>(s.export_points));
      std::fflush(stdout);
      ++k;
    } else if (next == camera_back) {
      camera_back = std::numeric_limits<double>::infinity();
      CameraBack(lost_camera, lost_event);
    } else if (next == restart_at) {
      RestartServerA();
      next_restart += o_.restart_every_min * 60;
    } else {
      if (camera_back == std::numeric_limits<double>::infinity()) {  // one camera down at a time
        lost_camera = next_camera;
        next_camera ^= 1;
        LoseCamera(lost_camera);
        lost_event = r.events.size() - 1;
        camera_back = Rel() + o_.camera_down_s;
      }
      next_loss += o_.camera_loss_every_min * 60;
    }
  }
  if (g_stop) std::printf("stevi-soak: stopped early (signal), after %d windows\n", k - 1);
  r.samples.resize(static_cast<size_t>(k));
  Shutdown();
  for (const Pending& p : pending_) {
    const double first = (p.server == 0 ? outages_a_ : outages_b_)->FirstFrame(p.outage);
    r.events[p.event].first_frame_s = first < 0 ? -1 : first - run_start_;
  }
  return Report(r, o_.out) ? 0 : 3;
}

}  // namespace
}  // namespace stevi::soak

int main(int argc, char** argv) {
  using namespace stevi::soak;
  Options o;
  std::string error;
  if (!ParseOptions(argc, argv, o, error)) {
    if (!error.empty()) std::fprintf(stderr, "stevi-soak: %s\n", error.c_str());
    std::fputs(kUsage, error.empty() ? stdout : stderr);
    return error.empty() ? 0 : 2;
  }
  if (o.cameras) {
    const char* netns = std::getenv("STEVI_FAKE_CAMERA_NETNS");
    if (netns == nullptr || std::string(netns) != "inside") {
      std::fprintf(stderr,
                   "stevi-soak: run it inside tests/drivers/fake_camera_netns.sh (the fake cameras "
                   "need 127.0.0.2 and a private GigE Vision port), or give --no-cameras\n");
      return 2;
    }
    if (!std::filesystem::exists(o.fake_camera)) {
      std::fprintf(stderr, "stevi-soak: %s not found (Debian's aravis-tools; --fake-camera)\n",
                   o.fake_camera.c_str());
      return 2;
    }
  }
  for (const char* program : {"stevi-server", "stevi"}) {
    if (!std::filesystem::exists(o.bin + "/" + program)) {
      std::fprintf(stderr, "stevi-soak: %s/%s not found (--bin)\n", o.bin.c_str(), program);
      return 2;
    }
  }
  struct sigaction action {};
  action.sa_handler = OnSignal;
  sigemptyset(&action.sa_mask);
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
  signal(SIGPIPE, SIG_IGN);
  std::string command_line;
  for (int i = 0; i < argc; ++i) command_line += (i ? " " : "") + std::string(argv[i]);
  Soak soak(o);
  return soak.Run(command_line);
}
