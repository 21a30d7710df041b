// What the soak (tests/bench/soak.cc) measured, and its report: CSV files, the tables, the issue's
// done-when checks (PASS/FAIL with the figures) and a PNG plot.
#pragma once

#include <sys/types.h>

#include <cstdint>
#include <string>
#include <vector>

#include "tests/bench/soak_process.h"

namespace stevi::soak {

// Latencies in log-spaced bins (1 % wide, 0.05 ms to about 150 s): a fixed size, so that keeping
// every window's distribution costs no memory while the soak runs.
class LatencyHist {
 public:
  static constexpr int kBins = 1500;
  LatencyHist() : bins_(kBins, 0) {}
  void Add(double ms);
  void Merge(const LatencyHist& other);
  void Clear();
  uint64_t count() const { return n_; }
  double max_ms() const { return max_ms_; }
  // The q-quantile (0..1): the upper edge of its bin, within 1 %; 0 when empty.
  double Quantile(double q) const;

 private:
  std::vector<uint32_t> bins_;
  uint64_t n_ = 0;
  double max_ms_ = 0;
};

// One group of streams (the gRPC clients of one server, or the WebSocket clients' frames of one
// rig) in one window. "Outside" = outside every outage window of its server.
struct StreamWindow {
  int clients = 0;
  uint64_t delivered = 0;            // frames, outside outages, all clients
  uint64_t delivered_in_outage = 0;  // inside
  uint64_t min_client_delivered = 0;
  uint64_t lost = 0;  // frame_id gaps outside outages
  uint64_t lost_in_outage = 0;
  uint64_t dropped = 0;  // growth of TrackFrame.dropped_frames outside outages
  uint64_t dropped_in_outage = 0;
  uint64_t resets = 0;  // a frame_id sequence started again (a restarted server)
  uint64_t images = 0;  // WebSocket preview images (their rig's group)
  LatencyHist latency;  // outside outages
  void Merge(const StreamWindow& other);
  void Clear() { *this = StreamWindow(); }
};

// What was measured at one sample time, and in the window that ended then.
struct Sample {
  double t_s = 0;
  std::vector<ProcSample> procs;  // by process index
  std::vector<pid_t> pids;
  int64_t export_points = -1;   // the station's rig1 export history (-1: not read)
  std::vector<double> fps_out;  // by server (GetStatus; -1 when unreachable)
  std::vector<std::string> source_state;
  uint64_t obstacle_distance = 0;     // OBSTACLE_DISTANCE the test autopilot received in the window
  std::vector<StreamWindow> streams;  // by group
};

// A restart or a camera loss and its outage window (from the event until the first frame after
// the recovery, plus the margin).
struct Event {
  double t_s = 0;
  std::string what;           // "restart server-A", "camera-L lost"
  int server = 0;             // whose clients it interrupts
  double stop_ms = 0;         // restart: SIGTERM to exit
  double recovered_s = 0;     // the server serving again, or the camera started again
  double first_frame_s = -1;  // -1: frames never resumed
};

// The soak's own process among process_names: sampled and plotted, not judged (it is the load).
inline constexpr char kHarnessName[] = "soak";

struct SoakResult {
  double minutes = 30, warmup_minutes = 5, compare_minutes = 5, sample_every_s = 60;
  double outage_margin_s = 2;
  int64_t export_points_bound = 0;
  double fps = 0, camera_fps = 0;
  std::vector<std::string> process_names;
  std::vector<std::string> server_names;
  std::vector<std::string> group_names;
  std::vector<int> group_server;  // which server each group's frames come from
  std::vector<Sample> samples;    // samples[0] at t = 0, then one per window
  std::vector<Event> events;
  std::vector<std::string> shutdown;  // "station: exit 0", ...
  std::string command_line;
};

// Writes samples.csv, windows.csv, events.csv, report.txt and soak.png into `out_dir`, prints the
// tables and the checks to stdout. Returns true when every check passes.
bool Report(const SoakResult& result, const std::string& out_dir);

}  // namespace stevi::soak
