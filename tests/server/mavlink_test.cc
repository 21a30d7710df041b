// `stevi mavlink` between a real stevi-server (the synthetic rig) and a test autopilot on loopback
// UDP: the autopilot's poses georeference the server's frames, OBSTACLE_DISTANCE reads the
// synthetic obstacles' true ranges, ADSB_VEHICLE carries the tracks, and the messages stop within
// 500 ms of the server stopping.
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <map>
#include <mutex>
#include <regex>
#include <set>
#include <thread>
#include <vector>

#include "client/lib/client.h"
#include "client/mavlink/translate.h"
#include "client/mavlink/codec.h"
#include "client/mavlink/messages.h"
#include "core/geo/georeferencer.h"
#include "drivers/synthetic/scenarios.h"
#include "drivers/synthetic/synthetic_source.h"
#include "tests/server/server_process.h"
#include "tests/server/truth_check.h"
#include "tests/testing/sanitized.h"
#include "tests/testing/subprocess.h"
#include "tests/testing/test_autopilot.h"
#include "tests/testing/truth_match.h"

namespace stevi {
namespace {

namespace ml = client::mavlink;
using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;
using testing::BinaryPath;
using ::testing::HasSubstr;
using testing::Subprocess;

// The camera rate. Under a sanitizer the instrumented pipeline falls behind 10 fps, and the
// frames it drops leave the tracks of moving drones to predictions that lag the truth.
constexpr double kFps = testing::kSanitized ? 5 : 10;
using testing::TestAutopilot;
constexpr uint8_t kAutopilotSystem = TestAutopilot::kSystem;
constexpr double kUndulationM = TestAutopilot::kUndulationM;
constexpr double kHorizontalAccuracyM = TestAutopilot::kHorizontalAccuracyM;

template <class T>
std::vector<std::pair<T, Clock::time_point>> All(
    const std::vector<TestAutopilot::Received>& received) {
  std::vector<std::pair<T, Clock::time_point>> out;
  for (const TestAutopilot::Received& r : received) {
    if (std::optional<T> m = ml::Decode<T>(r.frame)) out.emplace_back(*m, r.at);
  }
  return out;
}

size_t Count(const std::vector<TestAutopilot::Received>& received, uint32_t id) {
  return static_cast<size_t>(std::count_if(
      received.begin(), received.end(), [id](const auto& r) { return r.frame.message_id == id; }));
}

// The true nearest horizontal range per bridge sector (body frame = the level camera's: forward
// z, right x) of what stands out in a frame: every obstacle pixel and terrain more than 0.3 m
// above the ground plane; the k-th nearest pixel of a sector, so that a few edge pixels do not
// decide it.
std::map<int, double> TrueSectorRanges(const drivers::FrameTruth& truth,
                                       const drivers::SyntheticOptions& o, size_t k = 20) {
  std::map<int, std::vector<double>> ranges;
  const double cx = o.width / 2.0, cy = o.height / 2.0;  // the renderer's principal point
  const double h = o.scene.camera_height_m;
  for (int v = 0; v < truth.disparity_px.rows; ++v) {
    for (int u = 0; u < truth.disparity_px.cols; ++u) {
      const double d = truth.disparity_px(v, u);
      const int id = truth.object_id(v, u);
      if (d <= 0 || id < 0) continue;
      const double z = o.f_px * o.baseline_m / d;
      const double x = (u - cx) * z / o.f_px, y = (v - cy) * z / o.f_px;
      if (id == 0 && y > h - 0.3) continue;  // the ground
      v1::PointBody p;
      p.set_x_m(z);
      p.set_y_m(x);
      ranges[ml::SectorOf(ml::BodyBearingDeg(p))].push_back(std::hypot(x, z));
    }
  }
  std::map<int, double> out;
  for (auto& [sector, r] : ranges) {
    if (r.size() < k) continue;
    std::nth_element(r.begin(), r.begin() + static_cast<std::ptrdiff_t>(k - 1), r.end());
    out[sector] = r[k - 1];
  }
  return out;
}

// One message field by field, as the closing notes and the README show them.
void PrintObstacleDistance(const ml::ObstacleDistance& m, const ml::Frame& frame) {
  std::printf("OBSTACLE_DISTANCE (330) from system %u component %u, seq %u:\n", frame.system_id,
              frame.component_id, frame.sequence);
  std::printf(
      "  time_usec %llu\n  sensor_type %u\n  increment %u\n  min_distance %u cm\n"
      "  max_distance %u cm\n  increment_f %.1f deg\n  angle_offset %.1f deg\n"
      "  frame %u (MAV_FRAME_BODY_FRD)\n  distances (cm, sector: centre):",
      static_cast<unsigned long long>(m.time_usec), m.sensor_type, m.increment, m.min_distance,
      m.max_distance, m.increment_f, m.angle_offset, m.frame);
  for (int i = 0; i < ml::kSectors; ++i) {
    if (i % 6 == 0) std::printf("\n   ");
    std::printf(" %2d:%3d=%5u", i, i * 5, m.distances[static_cast<size_t>(i)]);
  }
  std::printf("\n");
}

void PrintAdsbVehicle(const ml::AdsbVehicle& a, const ml::Frame& frame) {
  std::printf("ADSB_VEHICLE (246) from system %u component %u, seq %u:\n", frame.system_id,
              frame.component_id, frame.sequence);
  std::printf(
      "  ICAO_address 0x%06X\n  lat %d (%.7f deg)\n  lon %d (%.7f deg)\n"
      "  altitude_type %u\n  altitude %d mm\n  heading %u cdeg\n  hor_velocity %u cm/s\n"
      "  ver_velocity %d cm/s\n  callsign \"%s\"\n  emitter_type %u\n  tslc %u s\n"
      "  flags 0x%04X\n  squawk %u\n",
      a.icao_address, a.lat, a.lat * 1e-7, a.lon, a.lon * 1e-7, a.altitude_type, a.altitude,
      a.heading, a.hor_velocity, a.ver_velocity, a.callsign.data(), a.emitter_type, a.tslc, a.flags,
      a.squawk);
}

class MavlinkBridgeTest : public ::testing::Test {
 protected:
  void SetUp() override {
    std::vector<std::string> args = {"--fps", std::to_string(static_cast<int>(kFps))};
    if (testing::kSanitized) {
      // Instrumented, the autopilot's states take longer than the default 0.1 s to reach the
      // server through the bridge, so frames would find them too old. The autopilot hovers:
      // the wider bounds change no pose.
      const std::string config = testing::MakeTempDir("stevi-mavlink-config") + "/server.textproto";
      std::ofstream(config) << "geo { max_extrapolation_s: 2 max_age_s: 5 }\n";
      args.insert(args.end(), {"--config", config});
    }
    ASSERT_NO_FATAL_FAILURE(server_.Start(args));
    pose_ = *drivers::SceneRigPose("airfield");
    autopilot_ = std::make_unique<TestAutopilot>(pose_);
    ASSERT_EQ(autopilot_->error(), "");
    bridge_ = std::make_unique<Subprocess>(std::vector<std::string>{
        BinaryPath("stevi"), "--server", server_.address(), "--timeout", "5", "mavlink", "--link",
        "udp://127.0.0.1:" + std::to_string(autopilot_->port()), "--adsb", "--status-every", "1"});
  }

  // Frames from the server until `n` georeferenced from the autopilot's states (its accuracy
  // tells them from the synthetic rig's own pose) arrived; the first ones that are not are
  // skipped, at most 200.
  std::vector<v1::TrackFrame> PublishedFrames(size_t n) {
    client::ClientOptions options;
    options.address = server_.address();
    client::Client c(options);
    std::vector<v1::TrackFrame> frames;
    int skipped = 0;
    const grpc::Status status = c.StreamTracks([&](const v1::TrackFrame& f) {
      if (std::abs(f.vehicle().position_sigma_horizontal_m() - kHorizontalAccuracyM) < 1e-9) {
        frames.push_back(f);
      } else {
        ++skipped;
      }
      return frames.size() < n && skipped < 200;
    });
    EXPECT_TRUE(status.ok()) << status.error_message();
    return frames;
  }

  testing::ServerProcess server_;
  geo::VehicleState pose_;
  std::unique_ptr<TestAutopilot> autopilot_;
  std::unique_ptr<Subprocess> bridge_;
};

TEST_F(MavlinkBridgeTest, TheAutopilotsPosesGeoreferenceTheFramesAndObstaclesReachIt) {
  ASSERT_TRUE(bridge_->WaitForStderrLine("event=publishing", 60s)) << bridge_->DrainStderr();
  const std::vector<v1::TrackFrame> frames = PublishedFrames(40);
  ASSERT_EQ(frames.size(), 40u) << "frames georeferenced from the autopilot's states";
  const std::vector<TestAutopilot::Received> received = autopilot_->received();

  // The bridge: a heartbeat as an onboard controller with the autopilot's system id, and a
  // request for each stream it needs.
  const auto heartbeats = All<ml::Heartbeat>(received);
  ASSERT_FALSE(heartbeats.empty());
  EXPECT_EQ(heartbeats.back().first.type, ml::kMavTypeOnboardController);
  EXPECT_EQ(heartbeats.back().first.autopilot, ml::kMavAutopilotInvalid);
  const auto bridge_frame = std::find_if(received.rbegin(), received.rend(), [](const auto& r) {
    return r.frame.message_id == ml::Heartbeat::kId;
  });
  EXPECT_EQ(bridge_frame->frame.system_id, kAutopilotSystem);
  EXPECT_EQ(bridge_frame->frame.component_id, ml::kMavCompIdObstacleAvoidance);
  std::set<uint32_t> requested;
  for (const auto& [c, at] : All<ml::CommandLong>(received)) {
    EXPECT_EQ(c.command, ml::kMavCmdSetMessageInterval);
    EXPECT_EQ(c.target_system, kAutopilotSystem);
    EXPECT_EQ(c.target_component, 1);
    requested.insert(static_cast<uint32_t>(c.param1));
  }
  EXPECT_EQ(requested, (std::set<uint32_t>{2, 24, 30, 33}));
  // ... at 1 Hz.
  ASSERT_GE(heartbeats.size(), 3u);
  const double heartbeat_hz =
      (heartbeats.size() - 1) /
      std::chrono::duration<double>(heartbeats.back().second - heartbeats.front().second).count();
  std::cout << "HEARTBEAT: " << heartbeats.size() << " at " << heartbeat_hz << " Hz\n";
  EXPECT_NEAR(heartbeat_hz, 1.0, 0.15);
  // Its status line (logfmt) counts what went out and says the pose flows: the first line whose
  // frame is georeferenced and whose obstacles flow (one printed while the first states arrive may
  // still say that the frame predates them; under TSan one came after the first frame alone,
  // saying obstacles=stopped), within 10 lines at 1 Hz.
  std::optional<std::string> status;
  for (int line = 0; line < 10; ++line) {
    status = bridge_->WaitForStderrLine("event=status", 10s);
    ASSERT_TRUE(status) << bridge_->DrainStderr();
    if (status->find("geo=GEO_STATUS_OK") != std::string::npos &&
        status->find("obstacles=flowing") != std::string::npos) {
      break;
    }
  }
  std::cout << *status << "\n";
  EXPECT_THAT(*status, HasSubstr("autopilot=ok"));
  EXPECT_THAT(*status, HasSubstr("obstacles=flowing"));
  EXPECT_THAT(*status, HasSubstr("pose=ok"));
  EXPECT_THAT(*status, HasSubstr("time_source=autopilot"));
  EXPECT_THAT(*status, HasSubstr("geo=GEO_STATUS_OK"));
  std::smatch sent;
  ASSERT_TRUE(std::regex_search(*status, sent, std::regex("obstacle_distance_sent=(\\d+)")));
  EXPECT_GT(std::stoll(sent[1].str()), 0);

  // The frames: georeferenced from the published states, the vehicle where the autopilot said.
  drivers::SyntheticOptions synthetic;
  synthetic.fps = kFps;
  drivers::SyntheticRenderer renderer(synthetic);
  const geo::Georeferencer georeferencer;
  int tracks_checked = 0;
  double worst_track_m = 0;
  std::map<int64_t, const v1::TrackFrame*> by_time_us;
  for (const v1::TrackFrame& f : frames) {
    by_time_us[f.capture_unix_time_ns() / 1000] = &f;
    ASSERT_EQ(f.geo_status(), v1::GEO_STATUS_OK) << f.geo_message();
    const double north = (f.vehicle().position().lat_deg() - pose_.lat_deg) * 111132.0;
    const double east = (f.vehicle().position().lon_deg() - pose_.lon_deg) * 78000.0;
    EXPECT_LT(std::hypot(north, east), 0.05);
    EXPECT_NEAR(f.vehicle().position().alt_m(), pose_.alt_m, 0.01) << "ellipsoid height";
    EXPECT_NEAR(f.vehicle().yaw_deg(), pose_.yaw_deg, 0.01);
    drivers::FrameTruth truth;
    renderer.Render(f.source_index(), &truth);
    std::vector<cv::Rect> boxes, truth_boxes;
    std::vector<const v1::Track*> tracks;
    std::vector<const drivers::ObstacleTruth*> obstacles;
    for (const v1::Track& t : f.tracks()) {
      if (t.state() != v1::TRACK_STATE_CONFIRMED || t.age_frames() < 20) continue;
      boxes.emplace_back(t.bbox().x(), t.bbox().y(), t.bbox().width(), t.bbox().height());
      tracks.push_back(&t);
    }
    for (const drivers::ObstacleTruth& o : truth.obstacles) {
      // Whole in view (the tower and the hangar are cut by the ground model) and within 50 m.
      if (o.visible_px < 300 || o.range_m > 50 || o.name == "tower" || o.name == "hangar") continue;
      truth_boxes.push_back(o.bbox);
      obstacles.push_back(&o);
    }
    for (const auto& [d, k] : testing::MatchByIoU(boxes, truth_boxes, 0.3)) {
      const Result<geo::GeoPoint> expected =
          testing::TruthGeodetic(georeferencer, pose_, *obstacles[k]);
      ASSERT_TRUE(expected.ok());
      const v1::Geodetic& got = tracks[d]->geodetic();
      const double error = std::hypot((got.lat_deg() - expected->lat_deg) * 111132.0,
                                      (got.lon_deg() - expected->lon_deg) * 111320.0 *
                                          std::cos(expected->lat_deg * M_PI / 180));
      worst_track_m = std::max(worst_track_m, std::hypot(error, got.alt_m() - expected->alt_m));
      ++tracks_checked;
    }
  }
  std::cout << "georeferenced from the autopilot: " << tracks_checked
            << " settled tracks, worst 3-D error " << worst_track_m << " m\n";
  EXPECT_GT(tracks_checked, 20);
  EXPECT_LT(worst_track_m, 1.0);

  // OBSTACLE_DISTANCE: body frame, 72 sectors of 5 degrees, at 10 Hz or more; the nearest
  // sector over each obstacle's bearing reads its true range within 5 %.
  const auto distances = All<ml::ObstacleDistance>(received);
  ASSERT_GE(distances.size(), 20u);
  const double span_s =
      std::chrono::duration<double>(distances.back().second - distances.front().second).count();
  const double rate_hz = (distances.size() - 1) / span_s;
  std::cout << "OBSTACLE_DISTANCE: " << distances.size() << " messages at " << rate_hz << " Hz\n";
  // A rate, so not held under a sanitizer, whose pipeline falls behind the camera.
  if (!testing::kSanitized) {
    EXPECT_GE(rate_hz, 9.5);
  }
  const double fB = synthetic.f_px * synthetic.baseline_m;
  // Per obstacle (visible, within the trusted range of 8 px): the sector of its bearing, against
  // the nearest of what stands out there (the obstacle, or one nearer in front of it). Every
  // occupied sector is scored too, for the record: there a sector that an obstacle only touches
  // may read it nearer (the matcher's borders), which the autopilot takes as a margin.
  int obstacles_checked = 0, within = 0, border = 0, sectors = 0, sectors_within = 0;
  double worst = 0;
  for (const auto& [m, at] : distances) {
    EXPECT_EQ(m.frame, ml::kMavFrameBodyFrd);
    EXPECT_EQ(m.increment_f, 5.0f);
    EXPECT_EQ(m.angle_offset, 0.0f);
    EXPECT_GT(m.max_distance, m.min_distance);
    EXPECT_LE(m.min_distance, std::ceil(fB / 63 * 100));  // the search's largest disparity, 63 px
    const auto f = by_time_us.find(static_cast<int64_t>(m.time_usec));
    if (f == by_time_us.end()) continue;  // a frame before the published ones
    drivers::FrameTruth truth;
    renderer.Render(f->second->source_index(), &truth);
    const std::map<int, double> true_sectors = TrueSectorRanges(truth, synthetic);
    const auto read_m = [&m](int sector) {
      const uint16_t cm = m.distances[static_cast<size_t>(sector)];
      return cm > m.max_distance ? HUGE_VAL : cm / 100.0;
    };
    for (const auto& [sector, true_m] : true_sectors) {
      if (true_m > fB / 8) continue;
      ++sectors;
      sectors_within += std::abs(read_m(sector) - true_m) <= 0.05 * true_m;
    }
    for (const drivers::ObstacleTruth& o : truth.obstacles) {
      if (o.visible_px < 300 || o.median_disparity_px < 8) continue;
      v1::PointBody centre;
      centre.set_x_m(o.position_cam_m[2]);
      centre.set_y_m(o.position_cam_m[0]);
      const int sector = ml::SectorOf(ml::BodyBearingDeg(centre));
      ASSERT_NE(m.distances[static_cast<size_t>(sector)], ml::kObstacleDistanceUnknown)
          << o.name << " is in view";
      const auto t = true_sectors.find(sector);
      if (t == true_sectors.end()) continue;  // fewer than 20 of its pixels there
      const double reading = read_m(sector);
      const double error = std::abs(reading - t->second) / t->second;
      worst = std::max(worst, error);
      ++obstacles_checked;
      if (error <= 0.05) {
        ++within;
        continue;
      }
      // Nearer than the truth, with something at least as near in the next sector: the block
      // matcher's border (a near surface's disparity spreads half a block past its edge). A
      // margin to the autopilot, not a miss; counted, and bounded below. A reading farther than
      // the truth, or nearer than anything around, fails.
      const auto neighbour_reads = [&](int s) {
        const auto n = true_sectors.find((s + ml::kSectors) % ml::kSectors);
        return n != true_sectors.end() && n->second <= 1.05 * reading;
      };
      if (reading < t->second && (neighbour_reads(sector - 1) || neighbour_reads(sector + 1))) {
        ++border;
        continue;
      }
      ADD_FAILURE() << "frame " << f->second->source_index() << " " << o.name << ": sector "
                    << sector << " reads " << reading << " m, truth " << t->second << " m";
    }
  }
  std::cout << "OBSTACLE_DISTANCE against the truth: " << within << " of " << obstacles_checked
            << " obstacles within 5 % in the sector of their bearing, " << border
            << " nearer by a nearer obstacle's border in the next sector (worst " << worst * 100
            << " %); " << sectors_within << " of " << sectors << " occupied sectors within 5 %\n";
  EXPECT_GT(obstacles_checked, 50);
  EXPECT_GE(within, 0.95 * obstacles_checked);

  // ADSB_VEHICLE: one per confirmed georeferenced track, where the frame put it. The bridge sends a
  // frame's ADSB_VEHICLEs right after its OBSTACLE_DISTANCE, which names the frame (time_usec).
  const auto adsb = All<ml::AdsbVehicle>(received);
  ASSERT_FALSE(adsb.empty());
  int adsb_matched = 0;
  const v1::TrackFrame* current = nullptr;
  for (const TestAutopilot::Received& r : received) {
    if (const std::optional<ml::ObstacleDistance> m = ml::Decode<ml::ObstacleDistance>(r.frame)) {
      const auto f = by_time_us.find(static_cast<int64_t>(m->time_usec));
      current = f == by_time_us.end() ? nullptr : f->second;
    }
    const std::optional<ml::AdsbVehicle> a = ml::Decode<ml::AdsbVehicle>(r.frame);
    if (!a) continue;
    EXPECT_EQ(std::string(a->callsign.data(), 3), "STV");
    EXPECT_EQ(a->flags & ml::kAdsbFlagsValidCoords, ml::kAdsbFlagsValidCoords);
    EXPECT_EQ(a->flags & ml::kAdsbFlagsSimulated, ml::kAdsbFlagsSimulated) << "a synthetic rig";
    // Before the published frames the geoid undulation may not be known yet (no GPS_RAW_INT).
    if (current == nullptr) continue;
    EXPECT_EQ(a->flags & ml::kAdsbFlagsValidAltitude, ml::kAdsbFlagsValidAltitude);
    const auto t = std::find_if(
        current->tracks().begin(), current->tracks().end(), [&](const v1::Track& track) {
          return ml::IcaoAddressOf(track.track_id(), 0xF00000) == a->icao_address;
        });
    ASSERT_NE(t, current->tracks().end())
        << "ICAO " << a->icao_address << " is no track of frame " << current->source_index();
    EXPECT_NE(t->state(), v1::TRACK_STATE_TENTATIVE);
    if (t->state() == v1::TRACK_STATE_CONFIRMED) {
      EXPECT_EQ(a->tslc, 0) << "detected in its frame";
    }
    EXPECT_EQ(a->callsign, ml::CallsignOf(t->track_id()));
    EXPECT_EQ(a->lat, std::lround(t->geodetic().lat_deg() * 1e7));
    EXPECT_EQ(a->lon, std::lround(t->geodetic().lon_deg() * 1e7));
    EXPECT_NEAR(a->altitude, (t->geodetic().alt_m() - kUndulationM) * 1000, 1.0) << "MSL, mm";
    ++adsb_matched;
  }
  // One of each, field by field, from the frame with the most tracks.
  for (auto r = received.rbegin(); r != received.rend(); ++r) {
    if (r->frame.message_id != ml::AdsbVehicle::kId) continue;
    PrintAdsbVehicle(*ml::Decode<ml::AdsbVehicle>(r->frame), r->frame);
    for (auto o = r; o != received.rend(); ++o) {
      if (o->frame.message_id != ml::ObstacleDistance::kId) continue;
      PrintObstacleDistance(*ml::Decode<ml::ObstacleDistance>(o->frame), o->frame);
      break;
    }
    break;
  }
  std::cout << "ADSB_VEHICLE: " << adsb.size() << " messages, " << adsb_matched
            << " matched to a streamed track\n";
  EXPECT_GT(adsb_matched, 0);
}

TEST_F(MavlinkBridgeTest, SilenceOnEitherSideStopsWhatDependsOnIt) {
  ASSERT_TRUE(bridge_->WaitForStderrLine("event=publishing", 60s)) << bridge_->DrainStderr();
  ASSERT_TRUE(autopilot_->WaitFor(
      [](const auto& r) { return Count(r, ml::ObstacleDistance::kId) >= 5; }, 30s));

  // The autopilot goes silent: the bridge says so, publishes nothing more, and the server's
  // georeferencing reports the states stale.
  autopilot_->set_silent(true);
  ASSERT_TRUE(bridge_->WaitForStderrLine("event=autopilot_silent", 10s)) << bridge_->DrainStderr();
  client::ClientOptions options;
  options.address = server_.address();
  client::Client c(options);
  v1::TrackFrame stale;
  int frames = 0;
  ASSERT_TRUE(c.StreamTracks([&](const v1::TrackFrame& f) {
                 stale = f;
                 return f.geo_status() == v1::GEO_STATUS_OK && ++frames < 100;
               }).ok());
  EXPECT_EQ(stale.geo_status(), v1::GEO_STATUS_POSE_TOO_OLD) << stale.geo_message();
  std::cout << "autopilot silent: " << v1::GeoStatus_Name(stale.geo_status()) << " \""
            << stale.geo_message() << "\"\n";
  autopilot_->set_silent(false);

  // The server stops: OBSTACLE_DISTANCE stops within 500 ms (no data, never a clear sky).
  const size_t before = Count(autopilot_->received(), ml::ObstacleDistance::kId);
  ASSERT_TRUE(autopilot_->WaitFor(
      [before](const auto& r) { return Count(r, ml::ObstacleDistance::kId) >= before + 3; }, 10s));
  const auto stopped_at = Clock::now();
  server_.process()->Signal(SIGTERM);
  ASSERT_EQ(server_.process()->Wait(10s), 0);
  ASSERT_TRUE(bridge_->WaitForStderrLine("event=obstacles_stopped", 10s)) << bridge_->DrainStderr();
  // One period more for a message already on its way.
  const auto distances = All<ml::ObstacleDistance>(autopilot_->received());
  const auto last = distances.back().second;
  const double after_ms = std::chrono::duration<double, std::milli>(last - stopped_at).count();
  std::cout << "the last OBSTACLE_DISTANCE came " << after_ms << " ms after SIGTERM\n";
  if (!testing::kSanitized) {  // a latency: not held under a sanitizer
    EXPECT_LE(after_ms, 500);
  }

  // The server comes back: the bridge reconnects and the obstacles flow again.
  const size_t at_restart = distances.size();
  ASSERT_NO_FATAL_FAILURE(server_.Restart());
  EXPECT_TRUE(autopilot_->WaitFor(
      [at_restart](const auto& r) { return Count(r, ml::ObstacleDistance::kId) >= at_restart + 5; },
      30s));
  EXPECT_TRUE(bridge_->WaitForStderrLine("event=stream_back", 10s));
  bridge_->Signal(SIGTERM);
  EXPECT_EQ(bridge_->Wait(10s), 0) << "the bridge ends cleanly on SIGTERM";
}

// Bad flags are refused with the accepted forms named, before anything is opened.
TEST(MavlinkBridgeFlags, BadLinksAndValuesAreRefused) {
  const auto run = [](std::vector<std::string> args) {
    args.insert(args.begin(), {BinaryPath("stevi"), "--server", "127.0.0.1:1", "mavlink"});
    return testing::Run(args, 30s);
  };
  testing::RunResult r = run({});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("--link is required"));
  r = run({"--link", "tcp://127.0.0.1:5760"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("udp://HOST:PORT"));
  r = run({"--link", "udp://127.0.0.1:14540", "--rate", "5"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("--rate"));
  r = run({"--link", "serial:///dev/ttyACM0:12345"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("12345"));
}

}  // namespace
}  // namespace stevi
