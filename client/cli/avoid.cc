// stevi avoid [--count N] [--protected-radius M]: the autopilot example, one advisory per frame
// as a JSON line, and NO_DATA when the frames stop.
#include "client/advisory/avoid.h"

#include <atomic>
#include <chrono>
#include <cstdint>
#include <iostream>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "client/cli/commands.h"
#include "core/common/flags.h"
#include "client/advisory/local_ned.h"
#include "client/lib/thread_name.h"

namespace stevi::client::commands {
namespace {

int64_t SteadyNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

GeoPoint ToGeoPoint(const v1::Geodetic& g) { return {g.lat_deg(), g.lon_deg(), g.alt_m()}; }

Ned ToNed(const v1::VelocityNed& v) { return {v.n_mps(), v.e_mps(), v.d_mps()}; }

// The frame's tracks with a geodetic position, in the local frame at `origin`.
std::vector<Obstacle> ToObstacles(const v1::TrackFrame& frame, const GeoPoint& origin) {
  std::vector<Obstacle> obstacles;
  for (const v1::Track& t : frame.tracks()) {
    if (!t.has_geodetic()) continue;
    Obstacle o;
    o.track_id = t.track_id();
    o.position_m = LocalNed(origin, ToGeoPoint(t.geodetic()));
    o.velocity_mps = ToNed(t.velocity_ned());
    o.sigma_horizontal_m = t.position_sigma_m().horizontal_m();
    o.sigma_vertical_m = t.position_sigma_m().vertical_m();
    o.range_rate_sigma_mps = t.range_rate_sigma_mps();
    o.hits = t.hits();
    o.state = t.state() == v1::TRACK_STATE_TENTATIVE  ? ObstacleState::kTentative
              : t.state() == v1::TRACK_STATE_COASTING ? ObstacleState::kCoasting
                                                      : ObstacleState::kConfirmed;
    o.score = t.score();
    obstacles.push_back(o);
  }
  return obstacles;
}

// The advisory for one frame. The local frame's origin is the vehicle's first position.
Advisory OnFrame(Advisor& advisor, const v1::TrackFrame& frame, std::optional<GeoPoint>& origin,
                 int64_t now) {
  if (frame.geo_status() != v1::GEO_STATUS_OK || !frame.has_vehicle()) {
    Advisory advisory;
    advisory.t_ns = now;
    advisory.level = AdvisoryLevel::kNoData;
    advisory.reason = "no vehicle pose: " + frame.geo_message();
    return advisory;
  }
  if (!origin) origin = ToGeoPoint(frame.vehicle().position());
  OwnVehicle own;
  own.position_m = LocalNed(*origin, ToGeoPoint(frame.vehicle().position()));
  own.velocity_mps = ToNed(frame.vehicle().velocity());
  return advisor.OnFrame(now, own, ToObstacles(frame, *origin));
}

}  // namespace

int Avoid(Client& client, const Args& args) {
  AdvisorOptions options;
  uint64_t count = 0;
  const std::string problem =
      flags::FlagSet("avoid")
          .Whole("--count", {.lo = 1},
                 [&count](std::int64_t n) { count = static_cast<uint64_t>(n); })
          .Real("--protected-radius", {.lo = 0.1, .hi = 10000, .unit = "metres"},
                [&options](double m) { options.avoid.protected_radius_m = m; })
          .Parse(args);
  if (!problem.empty()) return Usage(problem);
  Advisor advisor(options);
  std::mutex mu;  // the advisor and stdout, shared by the stream and the watchdog
  const auto print = [](const Advisory& advisory) {
    std::cout << AdvisoryJson(advisory) << "\n" << std::flush;
  };
  // The watchdog: never silent, never CLEAR on stale data. Once the frames are older than
  // no_data_after_ns it prints NO_DATA at every tick (10 Hz) until they come back.
  std::atomic<bool> done{false};
  std::thread watchdog([&] {
    NameThisThread("stevi-watchdog");
    while (!done) {
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
      std::lock_guard lock(mu);
      const int64_t now = SteadyNowNs();
      const Advisory advisory = advisor.OnTick(now);
      if (advisory.level == AdvisoryLevel::kNoData) print(advisory);
    }
  });
  std::optional<GeoPoint> origin;
  // Live (no --count): never give up. With --count (tests, scripts): give up after 3 attempts
  // when no frame ever came; once frames flowed, a server restart is waited out (NO_DATA).
  StreamOptions stream = LiveStreamOptions("avoid", count > 0 ? 3 : 0);
  stream.max_frames = count;
  OnStopSignal([&client] { client.Cancel(); });  // Ctrl-C or SIGTERM: end cleanly
  const grpc::Status status = client.StreamTracks(
      [&](const v1::TrackFrame& frame) {
        std::lock_guard lock(mu);
        print(OnFrame(advisor, frame, origin, SteadyNowNs()));
        return true;
      },
      stream);
  done = true;
  watchdog.join();
  if (!status.ok()) return RpcFailed(client, "avoid", status);
  return 0;
}

const CommandSpec kAvoidCommand = {"avoid",
                                   "the autopilot example: one collision advisory per frame",
                                   R"(usage: stevi avoid [--count N] [--protected-radius M]

One advisory per frame as a JSON line: CLEAR, CAUTION, WARNING or AVOID with the worst
obstacle's bearing, distance, time and distance of closest approach against the vehicle's own
velocity; NO_DATA when no frame came for 500 ms or the frame has no vehicle pose. Reconnects on
its own.
)",
                                   &Avoid};

}  // namespace stevi::client::commands
