// A flight controller on 127.0.0.1 for the tests and the soak of `stevi mavlink`: a UDP socket
// that answers whoever sent to it (as PX4 and ArduPilot do on their companion links). Once the
// bridge has written to it, it sends its heartbeat, GPS_RAW_INT and SYSTEM_TIME at 1 Hz and the
// vehicle's pose (ATTITUDE, GLOBAL_POSITION_INT) at 20 Hz; each stream other than the heartbeat
// only after the bridge asked for it (SET_MESSAGE_INTERVAL), so that a test sees the bridge ask.
#pragma once

#include <netinet/in.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "client/mavlink/codec.h"
#include "core/geo/vehicle_state.h"

namespace stevi::testing {

class TestAutopilot {
 public:
  using Clock = std::chrono::steady_clock;
  static constexpr uint8_t kSystem = 7;         // not 1: the bridge must take it from the heartbeat
  static constexpr double kUndulationM = 47.5;  // the geoid at Pisa, about
  static constexpr double kHorizontalAccuracyM = 0.35;
  static constexpr double kVerticalAccuracyM = 0.6;

  struct Received {
    client::mavlink::Frame frame;
    Clock::time_point at;
  };

  // keep_frames: keep every frame received (a test reads them back); without it only the count
  // per message id is kept, so that a soak's memory stays flat. error() tells when the socket
  // could not be made (the autopilot is then silent).
  explicit TestAutopilot(geo::VehicleState pose, bool keep_frames = true);
  ~TestAutopilot();
  TestAutopilot(const TestAutopilot&) = delete;
  TestAutopilot& operator=(const TestAutopilot&) = delete;

  const std::string& error() const { return error_; }
  int port() const { return port_; }
  // Silent: keeps receiving but sends nothing (a lost autopilot).
  void set_silent(bool silent) { silent_ = silent; }

  // Waits until `done` holds over the frames received (bounded).
  template <class Pred>
  bool WaitFor(Pred done, std::chrono::milliseconds timeout) {
    std::unique_lock lock(mu_);
    return cv_.wait_for(lock, timeout, [&] { return done(received_); });
  }
  std::vector<Received> received();
  // How many frames of message `id` arrived.
  uint64_t count(uint32_t id);

 private:
  template <class T>
  void Send(const T& m);
  bool Asked(uint32_t id);
  void SendPose(uint32_t boot_ms);
  void SendSlowMessages(uint32_t boot_ms);
  void Receive();
  void Loop();

  const geo::VehicleState pose_;
  const bool keep_frames_;
  std::string error_;
  int fd_ = -1;
  int port_ = 0;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> silent_{false};
  std::atomic<bool> has_peer_{false};
  sockaddr_in peer_{};
  uint8_t sequence_ = 0;
  std::mutex mu_;
  std::condition_variable cv_;
  client::mavlink::Parser parser_;
  std::vector<Received> received_;
  std::map<uint32_t, uint64_t> counts_;  // by message id
  std::set<uint32_t> asked_;             // message ids the bridge asked for
};

}  // namespace stevi::testing
