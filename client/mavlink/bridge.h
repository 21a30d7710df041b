// The autopilot bridge that `stevi mavlink` runs: stevi's obstacles go to the flight controller as
// OBSTACLE_DISTANCE (and ADSB_VEHICLE), the vehicle's pose comes back from it and goes to the
// server as VehicleStates. Never stale: nothing older than 400 ms is sent, and when the stream
// stops so do the obstacles, so that the autopilot sees no data rather than a clear sky.
//
// Threads: the stream (frames in), the link reader (the autopilot's messages in), the publisher
// (states out to the server), and the ticker on the calling thread (heartbeats, obstacle
// messages, message-interval requests, status lines, logfmt on stderr). What the messages say is
// translate.h's; this class moves them, keeps the link open and reports.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "client/lib/client.h"
#include "client/mavlink/codec.h"
#include "client/mavlink/link.h"
#include "client/mavlink/messages.h"
#include "client/mavlink/translate.h"

namespace stevi::client::mavlink {

// What `stevi mavlink`'s flags set.
struct BridgeOptions {
  LinkUrl link;
  bool adsb = false;
  std::optional<double> geoid_undulation_m;
  int component_id = kMavCompIdObstacleAvoidance;
  std::optional<int> system_id;  // default: the autopilot's
  bool publish_poses = true;
  double rate_hz = 10;  // OBSTACLE_DISTANCE
  double status_every_s = 5;
  uint32_t icao_base = 0xF00000;
};

// The running bridge between one stevi-server (through `client`) and one autopilot (through the
// link in the options). Run() on one thread, Stop() from any other.
class Bridge {
 public:
  using Clock = std::chrono::steady_clock;

  Bridge(Client& client, BridgeOptions options)
      : client_(client),
        args_(std::move(options)),
        joiner_({.geoid_undulation_m = args_.geoid_undulation_m}),
        adsb_({.icao_base = args_.icao_base, .geoid_undulation_m = args_.geoid_undulation_m}) {}

  // Runs the bridge until Stop(): opens the link, starts the stream, link and publisher threads
  // and ticks on the calling thread. Returns the exit status, 0.
  int Run();
  // Ends Run() from any thread (a signal handler's): cancels the stream, interrupts the link.
  void Stop();

 private:
  // The link, reopened when it fails (a serial device unplugged): senders take a reference.
  std::shared_ptr<Link> CurrentLink() {
    std::lock_guard lock(link_mu_);
    return link_;
  }
  bool OpenLinkNow();
  template <class T>
  void Send(const T& message);
  void OnFrame(const v1::TrackFrame& frame);
  void StreamLoop();
  void LinkLoop();
  void OnMessage(const Frame& frame);
  void PublishLoop();
  void Tick(Clock::time_point now);
  void SendObstacles(Clock::time_point now);
  void RequestStreams(Clock::time_point now);
  void LogStatus();
  // Waits `delay` or until Stop(); false when stopping.
  bool Wait(std::chrono::milliseconds delay) {
    std::unique_lock lock(mu_);
    return !cv_.wait_for(lock, delay, [this] { return stop_; });
  }

  Client& client_;
  const BridgeOptions args_;
  std::atomic<bool> stopping_{false};

  std::mutex link_mu_;
  std::shared_ptr<Link> link_;
  std::mutex send_mu_;  // the sequence number and the counters below
  uint8_t sequence_ = 0;

  std::mutex mu_;  // everything below
  std::condition_variable cv_;
  bool stop_ = false;
  // The newest frame's obstacle messages and when it arrived.
  std::optional<ObstacleDistance> obstacles_;
  std::vector<AdsbVehicle> adsb_batch_;
  bool adsb_pending_ = false;
  Clock::time_point frame_arrived_{};
  bool obstacles_flowing_ = false;  // sent in the last tick: for the stop/resume log lines
  std::string no_obstacles_why_;
  v1::GeoStatus geo_status_ = v1::GEO_STATUS_UNSPECIFIED;
  std::string geo_message_;
  // The autopilot.
  std::optional<std::pair<uint8_t, uint8_t>> autopilot_;  // system, component
  Clock::time_point autopilot_heard_{};
  bool autopilot_silent_ = true;
  PoseJoiner joiner_;
  AdsbTracks adsb_;
  std::deque<v1::VehicleState> states_;  // to publish, oldest first (bounded)
  std::unordered_map<uint32_t, Clock::time_point> last_received_;  // by message id
  Clock::time_point last_request_{};
  // Counters for the status line.
  uint64_t frames_in_ = 0, obstacle_sent_ = 0, adsb_sent_ = 0, heartbeats_sent_ = 0;
  uint64_t messages_in_ = 0, states_made_ = 0, states_published_ = 0, states_dropped_ = 0;
  uint64_t send_errors_ = 0, link_reopens_ = 0, stream_gaps_ = 0;
  std::string last_send_error_;
  bool publishing_ = false;  // the last write reached the server: for the lost/back log lines
  Parser::Stats parser_stats_;
};

}  // namespace stevi::client::mavlink
