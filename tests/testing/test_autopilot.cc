#include "tests/testing/test_autopilot.h"

#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <optional>
#include <span>

#include "client/mavlink/messages.h"

namespace stevi::testing {
namespace {

namespace ml = client::mavlink;
using namespace std::chrono_literals;

int64_t UnixNowUs() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

int32_t E7(double deg) { return static_cast<int32_t>(std::lround(deg * 1e7)); }

}  // namespace

TestAutopilot::TestAutopilot(geo::VehicleState pose, bool keep_frames)
    : pose_(pose), keep_frames_(keep_frames) {
  fd_ = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t length = sizeof addr;
  if (fd_ < 0 || bind(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 ||
      getsockname(fd_, reinterpret_cast<sockaddr*>(&addr), &length) != 0) {
    error_ = std::string("the test autopilot's UDP socket on 127.0.0.1: ") + std::strerror(errno);
    return;
  }
  port_ = ntohs(addr.sin_port);
  thread_ = std::thread([this] { Loop(); });
}

TestAutopilot::~TestAutopilot() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
  if (fd_ >= 0) close(fd_);
}

std::vector<TestAutopilot::Received> TestAutopilot::received() {
  std::lock_guard lock(mu_);
  return received_;
}

uint64_t TestAutopilot::count(uint32_t id) {
  std::lock_guard lock(mu_);
  const auto it = counts_.find(id);
  return it == counts_.end() ? 0 : it->second;
}

template <class T>
void TestAutopilot::Send(const T& m) {
  const std::vector<uint8_t> bytes = ml::Encode(m, sequence_++, kSystem, 1);
  (void)sendto(fd_, bytes.data(), bytes.size(), MSG_NOSIGNAL,
               reinterpret_cast<const sockaddr*>(&peer_), sizeof peer_);  // UDP: a loss is a loss
}

bool TestAutopilot::Asked(uint32_t id) {
  std::lock_guard lock(mu_);
  return asked_.count(id) > 0;
}

void TestAutopilot::SendPose(uint32_t boot_ms) {
  ml::Attitude a;
  a.time_boot_ms = boot_ms;
  a.roll = static_cast<float>(pose_.roll_deg * M_PI / 180);
  a.pitch = static_cast<float>(pose_.pitch_deg * M_PI / 180);
  a.yaw = static_cast<float>(std::remainder(pose_.yaw_deg, 360.0) * M_PI / 180);
  ml::GlobalPositionInt p;
  p.time_boot_ms = boot_ms;
  p.lat = E7(pose_.lat_deg);
  p.lon = E7(pose_.lon_deg);
  p.alt = static_cast<int32_t>(std::lround((pose_.alt_m - kUndulationM) * 1000));
  p.hdg = static_cast<uint16_t>(std::lround(std::fmod(pose_.yaw_deg + 360, 360) * 100));
  if (Asked(ml::Attitude::kId)) Send(a);
  if (Asked(ml::GlobalPositionInt::kId)) Send(p);
}

void TestAutopilot::SendSlowMessages(uint32_t boot_ms) {
  ml::GpsRawInt g;
  g.time_usec = static_cast<uint64_t>(UnixNowUs());
  g.fix_type = ml::kGpsFixType3dFix;
  g.lat = E7(pose_.lat_deg);
  g.lon = E7(pose_.lon_deg);
  g.alt = static_cast<int32_t>(std::lround((pose_.alt_m - kUndulationM) * 1000));
  g.alt_ellipsoid = static_cast<int32_t>(std::lround(pose_.alt_m * 1000));
  g.h_acc = static_cast<uint32_t>(kHorizontalAccuracyM * 1000);
  g.v_acc = static_cast<uint32_t>(kVerticalAccuracyM * 1000);
  g.satellites_visible = 14;
  if (Asked(ml::GpsRawInt::kId)) Send(g);
  ml::SystemTime t;
  t.time_unix_usec = static_cast<uint64_t>(UnixNowUs());
  t.time_boot_ms = boot_ms;
  if (Asked(ml::SystemTime::kId)) Send(t);
}

void TestAutopilot::Receive() {
  uint8_t buffer[2048];
  sockaddr_in from{};
  socklen_t length = sizeof from;
  const ssize_t n =
      recvfrom(fd_, buffer, sizeof buffer, 0, reinterpret_cast<sockaddr*>(&from), &length);
  if (n <= 0) return;
  const Clock::time_point at = Clock::now();
  std::lock_guard lock(mu_);
  peer_ = from;
  has_peer_ = true;
  parser_.Feed(std::span<const uint8_t>(buffer, static_cast<size_t>(n)), [&](const ml::Frame& f) {
    ++counts_[f.message_id];
    if (keep_frames_) received_.push_back({f, at});
    const std::optional<ml::CommandLong> c = ml::Decode<ml::CommandLong>(f);
    if (c && c->command == ml::kMavCmdSetMessageInterval && c->target_system == kSystem) {
      asked_.insert(static_cast<uint32_t>(c->param1));
    }
  });
  cv_.notify_all();
}

void TestAutopilot::Loop() {
  const Clock::time_point start = Clock::now();
  Clock::time_point next_fast = start, next_slow = start;
  while (!stop_) {
    pollfd fd{fd_, POLLIN, 0};
    if (poll(&fd, 1, 10) > 0) Receive();  // a 10 ms tick paces the sending, below
    const Clock::time_point now = Clock::now();
    const auto boot_ms = static_cast<uint32_t>((now - start) / 1ms) + 1;
    if (!has_peer_ || silent_) continue;
    if (now >= next_slow) {  // 1 Hz: the heartbeat first, so that the bridge knows who we are
      ml::Heartbeat hb;
      hb.type = 2;        // MAV_TYPE_QUADROTOR
      hb.autopilot = 12;  // MAV_AUTOPILOT_PX4
      hb.system_status = ml::kMavStateActive;
      Send(hb);
      SendSlowMessages(boot_ms);
      next_slow += 1s;
    }
    if (now >= next_fast) {
      SendPose(boot_ms);
      next_fast += 50ms;
    }
  }
}

}  // namespace stevi::testing
