// Helpers shared by the server's load, churn, fault and shutdown tests (load_test.cc,
// fault_test.cc, shutdown_test.cc): resident memory, bounded streaming over a raw stub, a stream's
// frames counted across threads, bounded waits on GetStatus, raw TCP sockets, and the "nothing is
// lost" snapshot (active pipeline config + calibration list).
#pragma once

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <gtest/gtest.h>
#include <grpcpp/grpcpp.h>

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <fstream>
#include <functional>
#include <iterator>
#include <memory>
#include <mutex>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "client/lib/client.h"
#include "stevi/v1/calibration_service.grpc.pb.h"
#include "stevi/v1/obstacle_service.grpc.pb.h"

namespace stevi::testing {

using Clock = std::chrono::steady_clock;

// VmRSS of /proc/<pid>/status in KiB ("self" for this process); -1 when unreadable.
inline long ResidentKiB(const std::string& pid = "self") {
  std::ifstream in("/proc/" + pid + "/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("VmRSS:", 0) == 0) {
      std::istringstream fields(line.substr(6));
      long kib = -1;
      fields >> kib;
      return kib;
    }
  }
  return -1;
}

// CPU time (user + system) this process used so far, seconds; -1 when unreadable.
inline double ProcessCpuSeconds() {
  std::ifstream in("/proc/self/stat");
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const size_t paren = text.rfind(')');
  if (paren == std::string::npos) return -1;
  std::istringstream fields(text.substr(paren + 2));
  std::string skip;
  for (int i = 3; i <= 13; ++i) fields >> skip;  // state .. cmajflt
  unsigned long long utime = 0, stime = 0;
  if (!(fields >> utime >> stime)) return -1;
  return static_cast<double>(utime + stime) / static_cast<double>(::sysconf(_SC_CLK_TCK));
}

inline double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

// A client of the library with a generous unary deadline.
inline std::unique_ptr<client::Client> MakeClient(
    const std::string& address, std::chrono::milliseconds timeout = std::chrono::seconds(20)) {
  client::ClientOptions options;
  options.address = address;
  options.timeout = timeout;
  return std::make_unique<client::Client>(options);
}

// The frames a stream delivered, counted on the thread reading it and awaited on others, and its
// final status once it ended.
class StreamCount {
 public:
  // A frame came.
  void Add() {
    {
      std::lock_guard lock(mu_);
      ++frames_;
    }
    cv_.notify_all();
  }
  // The stream ended with `status`.
  void End(const grpc::Status& status = grpc::Status::OK) {
    {
      std::lock_guard lock(mu_);
      status_ = status;
      ended_ = true;
    }
    cv_.notify_all();
  }
  // Waits at most `timeout` for `k` frames or the end; returns the frames counted by then.
  uint64_t WaitFor(uint64_t k, std::chrono::milliseconds timeout) {
    std::unique_lock lock(mu_);
    cv_.wait_for(lock, timeout, [&] { return frames_ >= k || ended_; });
    return frames_;
  }
  // The frames counted so far.
  uint64_t frames() {
    std::lock_guard lock(mu_);
    return frames_;
  }
  // The final status once the stream ended; nullopt when it did not within `timeout`.
  std::optional<grpc::Status> WaitForEnd(std::chrono::milliseconds timeout) {
    std::unique_lock lock(mu_);
    if (!cv_.wait_for(lock, timeout, [&] { return ended_; })) return std::nullopt;
    return status_;
  }

 private:
  std::mutex mu_;
  std::condition_variable cv_;
  uint64_t frames_ = 0;
  bool ended_ = false;
  grpc::Status status_;
};

// A channel of its own (no subchannel shared with other channels of this process): every such
// channel opens its own TCP connection.
inline std::shared_ptr<grpc::Channel> PrivateChannel(const std::string& address) {
  grpc::ChannelArguments args;
  args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
  return grpc::CreateCustomChannel(address, grpc::InsecureChannelCredentials(), args);
}

// Streams up to `n` frames on a new channel, the whole call bounded by `timeout`. Returns the
// frames received and the call's final status in `status` (OK when n frames arrived: the call is
// then cancelled by us).
inline std::vector<v1::TrackFrame> ReceiveFrames(const std::string& address, size_t n,
                                                 std::chrono::milliseconds timeout,
                                                 grpc::Status* status = nullptr,
                                                 const v1::StreamTracksRequest& request = {}) {
  std::shared_ptr<grpc::Channel> channel = PrivateChannel(address);
  std::unique_ptr<v1::ObstacleService::Stub> stub = v1::ObstacleService::NewStub(channel);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + timeout);
  std::unique_ptr<grpc::ClientReader<v1::TrackFrame>> reader =
      stub->StreamTracks(&context, request);
  std::vector<v1::TrackFrame> frames;
  v1::TrackFrame frame;
  while (frames.size() < n && reader->Read(&frame)) frames.push_back(frame);
  const bool got_all = frames.size() >= n;
  if (got_all) context.TryCancel();
  const grpc::Status finished = reader->Finish();
  if (status != nullptr) *status = got_all ? grpc::Status::OK : finished;
  return frames;
}

// Calls GetStatus until `done(status)` holds or `timeout` passes (a bounded poll on the server's
// own report: there is no event to wait on from outside the process). The last status is in
// `last`. Polls every 20 ms: that pacing is not what the result depends on.
inline bool WaitForStatus(client::Client& c,
                          const std::function<bool(const v1::GetStatusResponse&)>& done,
                          std::chrono::milliseconds timeout,
                          v1::GetStatusResponse* last = nullptr) {
  const auto deadline = Clock::now() + timeout;
  v1::GetStatusResponse status;
  while (true) {
    status.Clear();
    const grpc::Status s = c.GetStatus(&status);
    if (s.ok() && done(status)) {
      if (last != nullptr) *last = status;
      return true;
    }
    if (Clock::now() >= deadline) {
      if (last != nullptr) *last = status;
      return false;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));  // poll pacing
  }
}

// What must survive every fault: the active pipeline config and the stored calibrations.
struct ServerState {
  v1::PipelineConfig config;
  v1::ListCalibrationsResponse calibrations;
};

inline ServerState ReadState(client::Client& c) {
  ServerState state;
  const grpc::Status config = c.GetPipelineConfig(&state.config);
  EXPECT_TRUE(config.ok()) << "GetPipelineConfig: " << config.error_message();
  const grpc::Status list = c.ListCalibrations(&state.calibrations);
  EXPECT_TRUE(list.ok()) << "ListCalibrations: " << list.error_message();
  return state;
}

inline void ExpectSameState(const ServerState& before, const ServerState& after,
                            const std::string& what) {
  EXPECT_EQ(after.config.SerializeAsString(), before.config.SerializeAsString())
      << what << ": the active pipeline config changed:\nbefore "
      << before.config.ShortDebugString() << "\nafter " << after.config.ShortDebugString();
  EXPECT_EQ(after.calibrations.SerializeAsString(), before.calibrations.SerializeAsString())
      << what << ": the calibration list changed:\nbefore "
      << before.calibrations.ShortDebugString() << "\nafter "
      << after.calibrations.ShortDebugString();
}

// A TCP connection to 127.0.0.1:port, or -1. Receives time out after `recv_timeout`.
inline int ConnectTcp(int port, std::chrono::milliseconds recv_timeout = std::chrono::seconds(10)) {
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return -1;
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<uint16_t>(port));
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof addr) != 0) {
    ::close(fd);
    return -1;
  }
  timeval tv{};
  tv.tv_sec = static_cast<time_t>(recv_timeout.count() / 1000);
  tv.tv_usec = static_cast<suseconds_t>((recv_timeout.count() % 1000) * 1000);
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  return fd;
}

// Sends all of `bytes` (stops quietly when the peer has closed: no SIGPIPE).
inline void SendAll(int fd, const std::string& bytes) {
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::send(fd, bytes.data() + done, bytes.size() - done, MSG_NOSIGNAL);
    if (n <= 0) return;
    done += static_cast<size_t>(n);
  }
}

// Reads until the peer closes (true: EOF or reset) or the receive timeout (false). What was read
// is appended to `got` (at most 1 MiB kept).
inline bool ReadUntilClosed(int fd, std::string* got = nullptr) {
  char buf[4096];
  while (true) {
    const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n == 0) return true;
    if (n < 0) return errno == ECONNRESET || errno == EPIPE;
    if (got != nullptr && got->size() < (1u << 20)) got->append(buf, static_cast<size_t>(n));
  }
}

// The port of "127.0.0.1:PORT".
inline int PortOf(const std::string& address) {
  return std::stoi(address.substr(address.rfind(':') + 1));
}

}  // namespace stevi::testing
