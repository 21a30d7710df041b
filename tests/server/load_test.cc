// Load and churn tests of the server: 32 concurrent StreamTracks clients (one of them slow) for
// 60 s, and 1000 rapid connect / open-stream / cancel / disconnect cycles.
//
// The server runs in this process on 127.0.0.1:0, so that its resident memory can be read from
// /proc/self/status (testing::Subprocess does not expose its child's pid). The clients share the
// process: memory is therefore compared between two points at which the same clients are
// connected (after the warm-up and at the end), with every client-side buffer reserved up front.
#include "server/server.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstdio>
#include <mutex>
#include <random>
#include <thread>
#include <vector>

#include "client/lib/client.h"
#include "tests/server/load_helpers.h"
#include "tests/testing/sanitized.h"
#include "tests/testing/data.h"

namespace stevi::server {
namespace {

using namespace std::chrono_literals;
using testing::Clock;
using testing::ResidentKiB;
using testing::Seconds;

// 12 fps: on the 2-core reference machine the pipeline (canonical, block matching, 640x480) and
// 32 streams use well under the two cores, even with ctest running another test beside this one.
// Under a sanitizer (instrumented code runs 2-15 times slower): a rate the machine keeps with 32
// clients there. What this test asserts besides the rate holds at any rate. Resident memory is
// not checked there: AddressSanitizer holds freed memory in its quarantine (up to 256 MB) on
// purpose, to catch a use after free, and LeakSanitizer checks for leaks instead.
using testing::kSanitized;
constexpr double kFps = kSanitized ? 4 : 12;
constexpr int kClients = 32;         // one of them slow
constexpr auto kLoadDuration = 60s;  // all 32 streaming, after the warm-up
// The slow client's time per frame: well over the pipeline's period. Under ThreadSanitizer the
// pipeline managed 3.4 fps of the 4 asked, and a client taking 300 ms kept up with it.
constexpr auto kSlowConsumerDelay = kSanitized ? 1000ms : 300ms;
// Per normal client before the load is measured, and the frames of one rate measurement (5 s at
// 12 fps). Under a sanitizer fewer, and more time for them: in one ThreadSanitizer run
// (2026-11-29) the server gave under 2 fps, and 120 frames did not come within 60 s. The rates
// are not compared there (below), only the streams' flow and their ends.
constexpr uint64_t kWarmupFrames = kSanitized ? 20 : 60;
constexpr uint64_t kRateWindowFrames = kSanitized ? 20 : 60;
constexpr auto kRateTimeout = kSanitized ? 180s : 60s;
constexpr double kRateTolerance = 0.10;       // 32-client rate within 10 % of the 1-client rate
constexpr long kLoadRssBoundKiB = 10 * 1024;  // growth between warm-up and end
constexpr int kChurnCycles = 1000;
constexpr int kChurnWarmupCycles = 100;
constexpr int kChurnThreads = 4;
constexpr long kChurnRssBoundKiB = 5 * 1024;

v1::ServerConfig LoadConfig(const std::string& prefix) {
  v1::ServerConfig config;
  config.set_listen("127.0.0.1:0");
  config.mutable_source()->set_fps(kFps);
  config.set_data_dir(testing::MakeTempDir(prefix));
  return config;
}

int64_t UnixNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

std::unique_ptr<Server> StartServer(const std::string& prefix) {
  Result<std::unique_ptr<Server>> server = Server::Start(LoadConfig(prefix));
  EXPECT_TRUE(server.ok()) << server.error().message;
  return server.ok() ? std::move(server).value() : nullptr;
}

// What one streaming client saw. Written by its streaming thread only; read after it joined,
// except `count` (and `ended`), which the main thread waits on.
struct ClientLog {
  std::vector<uint64_t> frame_ids;
  std::vector<uint64_t> dropped;  // TrackFrame.dropped_frames of each frame received
  std::atomic<uint64_t> count{0};
  std::atomic<uint64_t> last_dropped{0};  // dropped_frames of the latest frame
  std::atomic<uint64_t> last_frame_id{0};
  std::atomic<int64_t> max_age_ns{0};  // oldest a frame was on arrival (capture to callback)
  std::atomic<bool> ended{false};
  grpc::Status status;
};

// Wakes the main thread when any client gets a frame or ends.
struct Events {
  std::mutex mu;
  std::condition_variable cv;
  void Notify() {
    { std::lock_guard lock(mu); }
    cv.notify_all();
  }
  // Waits until `done()` or `deadline`; the result of done() at the end.
  bool WaitUntil(Clock::time_point deadline, const std::function<bool()>& done) {
    std::unique_lock lock(mu);
    return cv.wait_until(lock, deadline, done);
  }
};

// Rate of the pipeline (frames_processed per second of steady clock) over the time `reference`
// takes to receive `frames` more frames. nullopt when that does not happen within `timeout`.
std::optional<double> MeasureRate(client::Client& control, const ClientLog& reference,
                                  Events& events, uint64_t frames, std::chrono::seconds timeout) {
  v1::GetStatusResponse a, b;
  if (!control.GetStatus(&a).ok()) return std::nullopt;
  const Clock::time_point t0 = Clock::now();
  const uint64_t target = reference.count.load() + frames;
  if (!events.WaitUntil(
          t0 + timeout,
          [&] { return reference.count.load() >= target || reference.ended.load(); }) ||
      reference.ended.load()) {
    return std::nullopt;
  }
  if (!control.GetStatus(&b).ok()) return std::nullopt;
  const Clock::time_point t1 = Clock::now();
  return static_cast<double>(b.frames_processed() - a.frames_processed()) / Seconds(t1 - t0);
}

// ---------------------------------------------------------------------------------------------
// 32 clients for 60 s, one of them slow.
// ---------------------------------------------------------------------------------------------
TEST(ServerLoad, ThirtyTwoClientsForAMinuteOneSlow) {
  std::unique_ptr<Server> server = StartServer("stevi-load");
  ASSERT_NE(server, nullptr);
  const std::string address = "127.0.0.1:" + std::to_string(server->port());
  std::unique_ptr<client::Client> control = testing::MakeClient(address);

  std::vector<std::unique_ptr<ClientLog>> logs;
  std::vector<std::unique_ptr<client::Client>> clients;
  for (int i = 0; i < kClients; ++i) {
    logs.push_back(std::make_unique<ClientLog>());
    // Reserved up front, so that what the clients keep does not count as server growth.
    logs.back()->frame_ids.reserve(4096);
    logs.back()->dropped.reserve(4096);
    clients.push_back(testing::MakeClient(address));
  }
  const int slow = kClients - 1;
  Events events;
  std::vector<std::thread> threads;
  const auto start_client = [&](int i) {
    threads.emplace_back([&, i] {
      ClientLog& log = *logs[i];
      log.status = clients[i]->StreamTracks([&](const v1::TrackFrame& f) {
        if (log.frame_ids.size() < log.frame_ids.capacity()) {
          log.frame_ids.push_back(f.frame_id());
          log.dropped.push_back(f.dropped_frames());
        }
        log.last_dropped = f.dropped_frames();
        log.last_frame_id = f.frame_id();
        const int64_t age = UnixNowNs() - f.capture_unix_time_ns();
        if (age > log.max_age_ns.load()) log.max_age_ns = age;
        ++log.count;
        events.Notify();
        // A slow consumer: it takes this long over each frame (simulated work, not a wait).
        if (i == slow) std::this_thread::sleep_for(kSlowConsumerDelay);
        return true;
      });
      log.ended = true;
      events.Notify();
    });
  };
  // Whatever happens below, the streams are cancelled and the threads joined.
  struct Joiner {
    std::vector<std::unique_ptr<client::Client>>& clients;
    std::vector<std::thread>& threads;
    ~Joiner() {
      for (auto& c : clients) c->Cancel();
      for (auto& t : threads) t.join();
    }
  } joiner{clients, threads};

  // 1. One client: the reference rate.
  start_client(0);
  ASSERT_TRUE(events.WaitUntil(Clock::now() + 30s, [&] { return logs[0]->count.load() >= 12; }))
      << "no frames with one client";
  const std::optional<double> rate_one =
      MeasureRate(*control, *logs[0], events, 2 * kRateWindowFrames, kRateTimeout);
  ASSERT_TRUE(rate_one.has_value()) << "the reference client stopped receiving";

  // 2. 31 more, the last one slow; warm-up until every normal client has kWarmupFrames frames and
  // the slow one a few.
  for (int i = 1; i < kClients; ++i) start_client(i);
  const bool warm = events.WaitUntil(Clock::now() + kRateTimeout, [&] {
    for (int i = 0; i < kClients; ++i) {
      if (logs[i]->ended.load()) return true;
      if (logs[i]->count.load() < (i == slow ? 10 : kWarmupFrames)) return false;
    }
    return true;
  });
  for (int i = 0; i < kClients; ++i) {
    ASSERT_FALSE(logs[i]->ended.load())
        << "client " << i << " ended: " << logs[i]->status.error_message();
  }
  ASSERT_TRUE(warm) << "the 32 clients did not all get going within " << kRateTimeout.count()
                    << " s";
  const Clock::time_point warm_at = Clock::now();
  v1::GetStatusResponse status;
  ASSERT_TRUE(control->GetStatus(&status).ok());
  EXPECT_EQ(status.subscribers_size(), kClients);
  const long rss_before = ResidentKiB();
  const double cpu_before = testing::ProcessCpuSeconds();

  // 3. The rate near the start of the load.
  const std::optional<double> rate_start =
      MeasureRate(*control, *logs[0], events, kRateWindowFrames, kRateTimeout);
  ASSERT_TRUE(rate_start.has_value()) << "client 0 stopped receiving under load";

  // 4. The load goes on for kLoadDuration after the warm-up (ending early only if a client's
  // stream ends), the last window measuring the rate near the end.
  const auto any_ended = [&] {
    for (const auto& log : logs) {
      if (log->ended.load()) return true;
    }
    return false;
  };
  const Clock::time_point end_window_at =
      warm_at + kLoadDuration -
      std::chrono::milliseconds(static_cast<int64_t>(1000.0 * kRateWindowFrames / kFps));
  EXPECT_FALSE(events.WaitUntil(end_window_at, any_ended)) << "a stream ended during the load";
  const std::optional<double> rate_end =
      MeasureRate(*control, *logs[0], events, kRateWindowFrames, kRateTimeout);
  ASSERT_TRUE(rate_end.has_value()) << "client 0 stopped receiving under load";
  const double load_s = Seconds(Clock::now() - warm_at);
  const double delivered_fps = kSanitized ? std::min(*rate_start, *rate_end) : kFps;
  const double cores_used = (testing::ProcessCpuSeconds() - cpu_before) / load_s;
  const long rss_after = ResidentKiB();
  const uint64_t slow_told = logs[slow]->last_dropped.load();
  // How far behind the slow client is: the newest frame (client 0's) against its own.
  const uint64_t slow_lag_frames = logs[0]->last_frame_id.load() - logs[slow]->last_frame_id.load();
  ASSERT_TRUE(control->GetStatus(&status).ok());
  EXPECT_EQ(status.subscribers_size(), kClients);
  uint64_t server_max_dropped = 0;
  for (const v1::SubscriberStatus& s : status.subscribers()) {
    server_max_dropped = std::max(server_max_dropped, s.frames_dropped());
  }

  // 5. Stop every stream; each ends with OK (cancelled by us), none by itself.
  EXPECT_FALSE(any_ended()) << "a stream ended during the load";
  for (auto& c : clients) c->Cancel();
  for (auto& t : threads) t.join();
  threads.clear();

  // Every normal client: every frame from its first to its last, in order, nothing dropped.
  uint64_t min_frames = UINT64_MAX, max_frames = 0;
  int64_t normal_max_age_ns = 0;
  for (int i = 0; i < kClients; ++i) {
    const ClientLog& log = *logs[i];
    EXPECT_TRUE(log.status.ok()) << "client " << i << ": " << log.status.error_message();
    EXPECT_LT(log.frame_ids.size(), log.frame_ids.capacity()) << "client " << i << ": log full";
    if (i == slow) continue;
    normal_max_age_ns = std::max<int64_t>(normal_max_age_ns, log.max_age_ns.load());
    min_frames = std::min<uint64_t>(min_frames, log.frame_ids.size());
    max_frames = std::max<uint64_t>(max_frames, log.frame_ids.size());
    int gaps = 0;
    for (size_t k = 1; k < log.frame_ids.size(); ++k) {
      if (log.frame_ids[k] != log.frame_ids[k - 1] + 1) {
        if (++gaps <= 5) {
          ADD_FAILURE() << "client " << i << ": frame " << log.frame_ids[k - 1] << " then "
                        << log.frame_ids[k];
        }
      }
    }
    EXPECT_EQ(gaps, 0) << "client " << i << " missed frames";
    EXPECT_EQ(log.dropped.empty() ? 0 : log.dropped.back(), 0u)
        << "client " << i << " was told it lost frames";
    // The normal clients were all connected for the whole load: at least load_s * fps * 0.9, at
    // the camera's rate; under a sanitizer at the rate the reference client measured (the
    // instrumented server does not keep the camera's: under 2 of 4 fps in one TSan run).
    EXPECT_GE(static_cast<double>(log.frame_ids.size()), 0.9 * load_s * delivered_fps)
        << "client " << i;
  }

  // The slow client: its losses are counted and reported to it, matching its gaps exactly.
  const ClientLog& s = *logs[slow];
  ASSERT_GE(s.frame_ids.size(), 2u);
  uint64_t gap_total = 0;
  int mismatches = 0, backwards = 0;
  for (size_t k = 1; k < s.frame_ids.size(); ++k) {
    if (s.frame_ids[k] <= s.frame_ids[k - 1] || s.dropped[k] < s.dropped[k - 1]) {
      ++backwards;
      continue;
    }
    const uint64_t gap = s.frame_ids[k] - s.frame_ids[k - 1] - 1;
    gap_total += gap;
    if (s.dropped[k] - s.dropped[k - 1] != gap && ++mismatches <= 5) {
      ADD_FAILURE() << "slow client: frame " << s.frame_ids[k - 1] << " then " << s.frame_ids[k]
                    << " (" << gap << " missing) but dropped_frames went from " << s.dropped[k - 1]
                    << " to " << s.dropped[k];
    }
  }
  const double ratio_start = *rate_start / *rate_one;
  const double ratio_end = *rate_end / *rate_one;
  const long growth = rss_after - rss_before;

  // The figures first, then the checks.
  std::printf(
      "load: source %.0f fps; pipeline %.2f fps with 1 client, %.2f fps with 32 near the start "
      "(ratio %.3f), %.2f near the end (ratio %.3f)\n"
      "load: %.1f s with 32 clients, using %.2f cores (server, pipeline and clients); frames per "
      "normal client %llu..%llu; slow client %zu frames, "
      "dropped_frames %llu (gaps %llu); server says %llu dropped\n"
      "load: slow client %llu frames behind the newest at the end; oldest frame on arrival: "
      "%.2f s (slow client), %.2f s (worst normal client)\n"
      "load: VmRSS %ld KiB after warm-up, %ld KiB at the end (%+ld KiB)\n",
      kFps, *rate_one, *rate_start, ratio_start, *rate_end, ratio_end, load_s, cores_used,
      static_cast<unsigned long long>(min_frames), static_cast<unsigned long long>(max_frames),
      s.frame_ids.size(), static_cast<unsigned long long>(s.dropped.back()),
      static_cast<unsigned long long>(gap_total),
      static_cast<unsigned long long>(server_max_dropped),
      static_cast<unsigned long long>(slow_lag_frames), s.max_age_ns.load() * 1e-9,
      normal_max_age_ns * 1e-9, rss_before, rss_after, growth);

  EXPECT_EQ(backwards, 0) << "the slow client's frame_id or dropped_frames went backwards";
  EXPECT_EQ(mismatches, 0);
  EXPECT_EQ(s.dropped.back() - s.dropped.front(), gap_total);
  EXPECT_GT(s.dropped.back(), 0u) << "a client slower than the pipeline must lose frames (it was "
                                  << slow_lag_frames << " frames behind the newest at the end)";
  // GetStatus counts the slow subscriber's drops too: at least what it had told the client before.
  EXPECT_GE(server_max_dropped, slow_told);
  EXPECT_GT(server_max_dropped, 0u);

  // The pipeline's rate is not slowed (nor, as a sanity check, sped up) by the clients. Not held
  // under a sanitizer, where the instrumented server and 32 clients share two cores (measured
  // under TSan: 0.887 near the start, 0.982 near the end); printed above.
  if (!kSanitized) {
    EXPECT_NEAR(ratio_start, 1.0, kRateTolerance);
    EXPECT_NEAR(ratio_end, 1.0, kRateTolerance);
  }
  // Resident memory (server and clients, the same 32 connected at both points).
  if (!kSanitized) {
    EXPECT_LT(growth, kLoadRssBoundKiB) << "resident memory grew by " << growth << " KiB";
  }
}

// ---------------------------------------------------------------------------------------------
// 1000 connect / open-stream / cancel / disconnect cycles.
// ---------------------------------------------------------------------------------------------

enum class Cycle { kConnectOnly, kCancelAtOnce, kCancelAfterFrame, kDeadline, kCount };

struct CycleOutcome {
  int done = 0;
  int by_kind[static_cast<int>(Cycle::kCount)] = {};
  int unexpected = 0;
  std::string first_unexpected;
};

// One cycle on a new channel (its own TCP connection), which is destroyed at the end.
void RunCycle(const std::string& address, Cycle kind, std::mt19937& rng, CycleOutcome& out) {
  std::shared_ptr<grpc::Channel> channel = testing::PrivateChannel(address);
  const auto fail = [&](const std::string& what) {
    if (out.unexpected++ == 0) out.first_unexpected = what;
  };
  if (kind == Cycle::kConnectOnly) {
    if (!channel->WaitForConnected(std::chrono::system_clock::now() + 10s))
      fail("connect timed out");
  } else {
    std::unique_ptr<v1::ObstacleService::Stub> stub = v1::ObstacleService::NewStub(channel);
    grpc::ClientContext context;
    const auto deadline_after =
        kind == Cycle::kDeadline ? std::chrono::milliseconds(50 + rng() % 200) : 20000ms;
    context.set_deadline(std::chrono::system_clock::now() + deadline_after);
    std::unique_ptr<grpc::ClientReader<v1::TrackFrame>> reader =
        stub->StreamTracks(&context, v1::StreamTracksRequest());
    v1::TrackFrame frame;
    grpc::StatusCode expected = grpc::StatusCode::CANCELLED;
    if (kind == Cycle::kCancelAtOnce) {
      context.TryCancel();
    } else if (kind == Cycle::kCancelAfterFrame) {
      if (!reader->Read(&frame)) fail("no frame before the cancel");
      context.TryCancel();
    } else {
      while (reader->Read(&frame)) {
      }
      expected = grpc::StatusCode::DEADLINE_EXCEEDED;
    }
    const grpc::Status status = reader->Finish();
    if (status.error_code() != expected) {
      fail("cycle " + std::to_string(static_cast<int>(kind)) + ": " +
           client::StatusCodeName(status.error_code()) + " " + status.error_message());
    }
  }
  ++out.by_kind[static_cast<int>(kind)];
  ++out.done;
}

// `cycles` cycles over kChurnThreads threads, kinds drawn from a seeded generator per thread.
std::vector<CycleOutcome> Churn(const std::string& address, int cycles, uint32_t seed) {
  std::vector<CycleOutcome> outcomes(kChurnThreads);
  std::vector<std::thread> threads;
  for (int t = 0; t < kChurnThreads; ++t) {
    threads.emplace_back([&, t] {
      std::mt19937 rng(seed + static_cast<uint32_t>(t));
      const int mine = cycles / kChurnThreads + (t < cycles % kChurnThreads ? 1 : 0);
      for (int i = 0; i < mine; ++i) {
        RunCycle(address, static_cast<Cycle>(rng() % static_cast<int>(Cycle::kCount)), rng,
                 outcomes[t]);
      }
    });
  }
  for (auto& t : threads) t.join();
  return outcomes;
}

TEST(ServerLoad, ThousandConnectStreamCancelCyclesLeaveNothingBehind) {
  std::unique_ptr<Server> server = StartServer("stevi-churn");
  ASSERT_NE(server, nullptr);
  const std::string address = "127.0.0.1:" + std::to_string(server->port());
  std::unique_ptr<client::Client> control = testing::MakeClient(address);
  grpc::Status first;
  ASSERT_EQ(testing::ReceiveFrames(address, 1, 30s, &first).size(), 1u) << first.error_message();

  // Warm-up: the threads, their malloc arenas and gRPC's pools exist before the baseline.
  const std::vector<CycleOutcome> warm = Churn(address, kChurnWarmupCycles, 7);
  ASSERT_TRUE(testing::WaitForStatus(
      *control, [](const v1::GetStatusResponse& s) { return s.subscribers_size() == 0; }, 10s));
  const long rss_before = ResidentKiB();
  const Clock::time_point t0 = Clock::now();
  const std::vector<CycleOutcome> outcomes = Churn(address, kChurnCycles, 1000);
  const double churn_s = Seconds(Clock::now() - t0);

  int done = 0, unexpected = 0;
  int by_kind[static_cast<int>(Cycle::kCount)] = {};
  for (const std::vector<CycleOutcome>* set : {&warm, &outcomes}) {
    for (const CycleOutcome& o : *set) {
      EXPECT_EQ(o.unexpected, 0) << o.unexpected
                                 << " unexpected outcomes, the first: " << o.first_unexpected;
      unexpected += o.unexpected;
    }
  }
  for (const CycleOutcome& o : outcomes) {
    done += o.done;
    for (int k = 0; k < static_cast<int>(Cycle::kCount); ++k) by_kind[k] += o.by_kind[k];
  }
  EXPECT_EQ(done, kChurnCycles);

  // Every subscription went away (bounded wait: the server unsubscribes when its side of each
  // call is done, which may come after the client saw the cancel).
  v1::GetStatusResponse status;
  const Clock::time_point drain_start = Clock::now();
  EXPECT_TRUE(testing::WaitForStatus(
      *control, [](const v1::GetStatusResponse& s) { return s.subscribers_size() == 0; }, 10s,
      &status))
      << status.subscribers_size() << " subscribers left after the churn";
  const double drain_s = Seconds(Clock::now() - drain_start);
  const long rss_after = ResidentKiB();

  // The server still streams to a new client, every frame in order.
  grpc::Status streamed;
  const std::vector<v1::TrackFrame> frames = testing::ReceiveFrames(address, 10, 30s, &streamed);
  ASSERT_EQ(frames.size(), 10u) << streamed.error_message();
  for (size_t k = 1; k < frames.size(); ++k) {
    EXPECT_EQ(frames[k].frame_id(), frames[k - 1].frame_id() + 1);
  }
  EXPECT_EQ(frames.back().dropped_frames(), 0u);
  ASSERT_TRUE(control->GetStatus(&status).ok());
  EXPECT_EQ(status.source_state(), v1::SOURCE_STATE_RUNNING);

  const long growth = rss_after - rss_before;
  if (!kSanitized) {
    EXPECT_LT(growth, kChurnRssBoundKiB) << "resident memory grew by " << growth << " KiB";
  }
  std::printf(
      "churn: %d cycles in %.1f s on %d threads (connect only %d, cancel at once %d, cancel "
      "after a frame %d, deadline %d), %d unexpected; 0 subscribers %.2f s after\n"
      "churn: VmRSS %ld KiB before, %ld KiB after (%+ld KiB, bound %ld)\n",
      done, churn_s, kChurnThreads, by_kind[0], by_kind[1], by_kind[2], by_kind[3], unexpected,
      drain_s, rss_before, rss_after, growth, kChurnRssBoundKiB);
}

}  // namespace
}  // namespace stevi::server
