// The real binaries: stevi-server with `stevi` commands against it, and stevi-process.
#include <signal.h>

#include <gmock/gmock.h>
#include <google/protobuf/util/json_util.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "core/calibration/chessboard_render.h"
#include "core/geometry/calibration_io.h"
#include "stevi/v1/calibration_service.pb.h"
#include "drivers/synthetic/synthetic_source.h"
#include "stevi/v1/truth.pb.h"
#include "tests/server/server_process.h"
#include "tests/testing/sanitized.h"
#include "tests/server/truth_check.h"
#include "tests/testing/data.h"
#include "tests/testing/subprocess.h"
#include "tests/testing/synthetic_calibration.h"

namespace stevi {
namespace {

using testing::BinaryPath;
using ::testing::HasSubstr;
using testing::Subprocess;
using namespace std::chrono_literals;

using testing::kCommandTimeout;
using testing::ParseJsonLines;

int CountLines(const std::string& text) {
  return static_cast<int>(std::count(text.begin(), text.end(), '\n'));
}

class ServerProcessTest : public ::testing::Test {
 protected:
  // The camera rate. Under a sanitizer the instrumented pipeline falls behind 20 fps, and the
  // frames it drops turn the tracks of approaching drones into predictions between
  // measurements, which lag the truth; 5 fps it keeps up with.
  static constexpr double kFps = testing::kSanitized ? 5 : 20;

  void SetUp() override { StartServer({}); }

  void StartServer(std::vector<std::string> extra) {
    extra.insert(extra.begin(), {"--fps", std::to_string(static_cast<int>(kFps))});
    ASSERT_NO_FATAL_FAILURE(server_.Start(extra));
    address_ = server_.address();
  }

  testing::RunResult Stevi(std::vector<std::string> args,
                           std::chrono::milliseconds timeout = kCommandTimeout) {
    return server_.Stevi(std::move(args), timeout);
  }

  // True once at least `n` StreamTracks subscribers have been sent a frame (GetStatus, asked up
  // to 300 times: each ask is a whole `stevi status` process, so the loop is bounded in time too).
  bool SubscribersStreaming(int n) {
    for (int attempt = 0; attempt < 300; ++attempt) {
      const testing::RunResult status = Stevi({"status", "--json"});
      v1::GetStatusResponse response;
      if (status.exit_code != 0 ||
          !google::protobuf::util::JsonStringToMessage(status.out, &response).ok()) {
        continue;
      }
      const auto sending =
          std::count_if(response.subscribers().begin(), response.subscribers().end(),
                        [](const v1::SubscriberStatus& s) { return s.frames_sent() > 0; });
      if (sending >= n) return true;
    }
    return false;
  }

  testing::ServerProcess server_;
  std::string address_;
};

TEST_F(ServerProcessTest, WatchShowsObstaclesWithDepthWithinTwoPercent) {
  const testing::RunResult watch = Stevi({"watch", "--count", "30", "--json"});
  ASSERT_EQ(watch.exit_code, 0) << watch.err;
  const auto frames = ParseJsonLines<v1::TrackFrame>(watch.out);
  ASSERT_EQ(frames.size(), 30u);

  drivers::SyntheticOptions options;
  options.fps = kFps;
  drivers::SyntheticRenderer renderer(options);
  testing::DepthCheck check;
  for (const v1::TrackFrame& f : frames) {
    drivers::FrameTruth truth;
    renderer.Render(f.source_index(), &truth);
    testing::CheckFrame(f, truth, options.f_px * options.baseline_m, check);
  }
  std::cout << "stevi watch: " << check.matched << "/" << check.expected
            << " obstacles with disparity >= 8 px matched, " << check.within
            << " within 2 % of the true depth, worst " << 100 * check.worst_relative_error
            << " %\n";
  EXPECT_GE(check.recall(), 0.85);
  // The depth is the object's (the median of its visible pixels' disparities), fitted per
  // detection: nearly all within 2 %, none beyond 3 % (a small box seen from below: 2.2 %).
  EXPECT_GE(check.within, 0.99 * check.matched) << ::testing::PrintToString(check.failures);
  EXPECT_LE(check.worst_relative_error, 0.03) << ::testing::PrintToString(check.failures);
  // Tracking through the real server: each obstacle keeps its track id over the 30 frames.
  std::cout << "id consistency " << check.IdConsistency() << "\n";
  EXPECT_GE(check.IdConsistency(), 0.9);
  std::set<uint64_t> seen_this_frame;
  for (const v1::TrackFrame& f : frames) {
    seen_this_frame.clear();
    for (const v1::Track& t : f.tracks()) {
      EXPECT_TRUE(seen_this_frame.insert(t.track_id()).second) << "duplicate id in a frame";
      EXPECT_NE(t.state(), v1::TRACK_STATE_UNSPECIFIED);
      EXPECT_GE(t.hits(), 1u);
    }
  }

  const testing::RunResult table = Stevi({"watch", "--count", "2"});
  ASSERT_EQ(table.exit_code, 0) << table.err;
  EXPECT_THAT(table.out, HasSubstr("depth m"));
  EXPECT_THAT(table.out, HasSubstr("state"));

  // Server-side filters: confirmed only, and a score floor.
  const testing::RunResult confirmed =
      Stevi({"watch", "--count", "5", "--json", "--confirmed", "--min-score", "0.5"});
  ASSERT_EQ(confirmed.exit_code, 0) << confirmed.err;
  int kept = 0;
  for (const v1::TrackFrame& f : ParseJsonLines<v1::TrackFrame>(confirmed.out)) {
    for (const v1::Track& t : f.tracks()) {
      ++kept;
      EXPECT_NE(t.state(), v1::TRACK_STATE_TENTATIVE);
      EXPECT_GE(t.score(), 0.5);
    }
  }
  EXPECT_GT(kept, 0);
  const testing::RunResult bad_score = Stevi({"watch", "--count", "1", "--min-score", "2"});
  EXPECT_EQ(bad_score.exit_code, 2);
  EXPECT_THAT(bad_score.err, HasSubstr("--min-score"));
  EXPECT_THAT(table.out, HasSubstr("canonical"));
}

// `stevi calibrate` uploads chessboard pairs from files, prints the report and, with --apply,
// switches the running server to the new calibration: the stream goes on with it.
TEST_F(ServerProcessTest, CalibrateUploadsPairsAppliesAndTheStreamGoesOn) {
  const std::string dir = testing::MakeTempDir("stevi-calibrate");
  const cv::Size size(640, 480);
  const geometry::StereoCalibration rig = geometry::IdealCalibration(size, 700, 0.6, 320, 240);
  const calibration::BoardSpec board{9, 6, 0.10};
  Result<calibration::ChessboardRenderer> renderer =
      calibration::ChessboardRenderer::Create(rig, board, size);
  ASSERT_TRUE(renderer.ok()) << renderer.error().message;
  Result<std::vector<cv::Affine3d>> poses =
      calibration::GenerateBoardPoses(rig, board, size, 12, 3);
  ASSERT_TRUE(poses.ok()) << poses.error().message;
  for (size_t i = 0; i < poses->size(); ++i) {
    const calibration::RenderedPair pair = renderer->Render((*poses)[i]);
    char name[64];
    std::snprintf(name, sizeof name, "/left%02zu.png", i + 1);
    ASSERT_TRUE(cv::imwrite(dir + name, pair.left));
    std::snprintf(name, sizeof name, "/right%02zu.png", i + 1);
    ASSERT_TRUE(cv::imwrite(dir + name, pair.right));
  }
  const testing::RunResult calibrated =
      Stevi({"calibrate", "--board", "9x6", "--square-mm", "100", "--left", dir + "/left%02d.png",
             "--right", dir + "/right%02d.png", "--apply"});
  ASSERT_EQ(calibrated.exit_code, 0) << calibrated.out << calibrated.err;
  EXPECT_THAT(calibrated.out, HasSubstr("PASSED"));
  EXPECT_THAT(calibrated.out, HasSubstr("cal-000001: passed its gates; now active"));
  const testing::RunResult list = Stevi({"calibration", "list"});
  EXPECT_THAT(list.out, HasSubstr("* cal-000001"));
  const testing::RunResult watch = Stevi({"watch", "--count", "3", "--json"});
  ASSERT_EQ(watch.exit_code, 0) << watch.err;
  for (const v1::TrackFrame& f : ParseJsonLines<v1::TrackFrame>(watch.out)) {
    EXPECT_EQ(f.calibration_id(), "cal-000001") << "the stream goes on with the new calibration";
  }
  const testing::RunResult yaml = Stevi({"calibration", "get", "cal-000001", "--yaml"});
  Result<geometry::StereoCalibration> parsed = geometry::ParseCalibrationYaml(yaml.out);
  ASSERT_TRUE(parsed.ok()) << parsed.error().message;
  EXPECT_NEAR(cv::norm(parsed->T), 0.6, 0.003);

  const testing::RunResult no_board =
      Stevi({"calibrate", "--board", "9x6", "--square-mm", "100", "--left",
             dir + "/nothing%02d.png", "--right", dir + "/none%02d.png"});
  EXPECT_EQ(no_board.exit_code, 1);
  EXPECT_THAT(no_board.err, HasSubstr("no image pair matches"));
  const testing::RunResult bad_board =
      Stevi({"calibrate", "--board", "9", "--square-mm", "100", "--capture", "3"});
  EXPECT_EQ(bad_board.exit_code, 2);
  EXPECT_THAT(bad_board.err, HasSubstr("--board"));
}

// The real XIMEA captures through `stevi calibrate`: the report's figures. The server's source is
// 640x480 and these are 640x512, so the calibration is stored but (rightly) not applied.
TEST_F(ServerProcessTest, CalibrateTheRealXimeaCaptures) {
  const std::optional<std::string> data = testing::DataDir();
  if (!data) GTEST_SKIP() << "reference data not found at " << testing::DataDirWanted();
  const std::string dir = *data + "/calib_ximea_stereo";
  const testing::RunResult r =
      Stevi({"calibrate", "--board", "6x9", "--square-mm", "24", "--left", dir + "/left%02d.jpg",
             "--right", dir + "/right%02d.jpg", "--apply", "--json"},
            // 17 s alone on two cores; several times that when other tests share them.
            std::chrono::minutes(5));
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  const std::vector<v1::CalibrationReport> reports = ParseJsonLines<v1::CalibrationReport>(r.out);
  ASSERT_EQ(reports.size(), 1u) << r.out;
  const v1::CalibrationReport& report = reports[0];
  std::cout << report.text() << "\n";
  EXPECT_TRUE(report.passed());
  EXPECT_EQ(report.pairs_total(), 25);
  EXPECT_EQ(report.pairs_used(), 24);
  EXPECT_LE(report.rms_px(), 0.25);
  EXPECT_NEAR(report.baseline_m(), 0.0925, 0.002);
  EXPECT_TRUE(report.swapped_left_right()) << "the camera named left sits on the right";
  EXPECT_FALSE(report.applied()) << "640x512 does not fit the 640x480 source";
  bool size_warning = false;
  for (const std::string& w : report.warnings())
    size_warning |= w.find("640x512") != std::string::npos;
  EXPECT_TRUE(size_warning) << "the report says why it was not applied";
}

// The levels of `stevi avoid`'s JSON lines (with `frames_only`, without the watchdog's NO_DATA
// lines, which come before the first frame or when frames are late: correct, but not per frame).
std::vector<std::string> AdvisoryLevels(const std::string& out, bool frames_only = false) {
  std::vector<std::string> levels;
  const std::regex level("\"level\":\"([A-Z_]+)\"");
  std::istringstream lines(out);
  std::string line;
  while (std::getline(lines, line)) {
    std::smatch m;
    if (!std::regex_search(line, m, level)) continue;
    if (frames_only && m[1].str() == "NO_DATA") continue;
    levels.push_back(m[1].str());
  }
  return levels;
}

// The autopilot example on the synthetic rig hovering at Pisa: a drone flying at it (head_on,
// missing the camera by 2.4 m) gives AVOID or WARNING; the same drone flying away (departing)
// never does.
TEST_F(ServerProcessTest, AvoidWarnsOfACollisionCourseAndStaysClearOfADivergingObstacle) {
  StartServer({"--scene", "head_on"});
  const testing::RunResult head_on = Stevi({"avoid", "--count", "40"});
  ASSERT_EQ(head_on.exit_code, 0) << head_on.err;
  const std::vector<std::string> levels = AdvisoryLevels(head_on.out, /*frames_only=*/true);
  ASSERT_EQ(levels.size(), 40u) << head_on.out;
  const auto alarms = std::count_if(levels.begin(), levels.end(), [](const std::string& l) {
    return l == "AVOID" || l == "WARNING";
  });
  std::cout << "head_on: " << alarms << " of 40 advisories are WARNING or AVOID\n";
  // The scene loops every 60 frames; 40 frames may include a restart, where the drone is seen anew
  // at 51 m and its track needs AvoidOptions::min_hits_to_extrapolate (5) detections before its
  // velocity counts: 30-36 of 40 measured.
  EXPECT_GE(alarms, 25) << head_on.out;
  EXPECT_THAT(head_on.out, HasSubstr("\"d_cpa_m\""));

  StartServer({"--scene", "departing"});
  const testing::RunResult departing = Stevi({"avoid", "--count", "40"});
  ASSERT_EQ(departing.exit_code, 0) << departing.err;
  const std::vector<std::string> calm = AdvisoryLevels(departing.out, /*frames_only=*/true);
  ASSERT_EQ(calm.size(), 40u);
  EXPECT_EQ(std::count(calm.begin(), calm.end(), "CLEAR"), 40) << departing.out;
}

// Without frames the autopilot example says NO_DATA: it never falls silent and never says CLEAR.
TEST(AvoidWithoutAServer, SaysNoDataAndNeverClear) {
  const testing::RunResult r = testing::Run(
      {BinaryPath("stevi"), "--server", "127.0.0.1:1", "--timeout", "0.5", "avoid", "--count", "5"},
      kCommandTimeout);
  EXPECT_EQ(r.exit_code, 1) << "gives up after 3 reconnection attempts";
  const std::vector<std::string> levels = AdvisoryLevels(r.out);
  ASSERT_GE(levels.size(), 2u) << r.out << r.err;
  EXPECT_EQ(std::count(levels.begin(), levels.end(), "NO_DATA"), static_cast<long>(levels.size()));
}

// The next stdout line of `process` that carries an advisory from a frame (not NO_DATA), within
// `lines` advisories; nullopt when none came.
std::optional<std::string> NextFrameAdvisory(Subprocess& process, int lines) {
  for (int i = 0; i < lines; ++i) {
    const std::optional<std::string> line = process.WaitForStdoutLine("\"level\":\"", 30s);
    if (!line) return std::nullopt;
    if (line->find("NO_DATA") == std::string::npos) return line;
  }
  return std::nullopt;
}

// The t_ns of each advisory line, in order, and whether it is NO_DATA.
std::vector<std::pair<int64_t, bool>> AdvisoryTimes(const std::string& out) {
  std::vector<std::pair<int64_t, bool>> times;
  const std::regex advisory("\"t_ns\":(-?\\d+),\"level\":\"([A-Z_]+)\"");
  std::istringstream lines(out);
  std::string line;
  while (std::getline(lines, line)) {
    std::smatch m;
    if (std::regex_search(line, m, advisory)) {
      times.emplace_back(std::stoll(m[1].str()), m[2].str() == "NO_DATA");
    }
  }
  return times;
}

// A graceful server stop (SIGTERM, as systemd does) and a restart on the same port: every
// streaming consumer waits it out and resumes, and the autopilot example says NO_DATA at 10 Hz in
// between, never anything else and never silent.
TEST_F(ServerProcessTest, StreamingConsumersSurviveAServerRestart) {
  Subprocess avoid({BinaryPath("stevi"), "--server", address_, "--timeout", "5", "avoid"});
  Subprocess watch(
      {BinaryPath("stevi"), "--server", address_, "--timeout", "5", "watch", "--json"});
  const std::string kml = testing::MakeTempDir("stevi-restart") + "/flight.kml";
  // 10 s of frames, so the export is mid-stream when the server stops.
  const std::string count = std::to_string(static_cast<int>(10 * kFps));
  Subprocess exporter({BinaryPath("stevi"), "--server", address_, "--timeout", "5", "export",
                       "--format", "kml", "--count", count, "--out", kml});
  ASSERT_TRUE(NextFrameAdvisory(avoid, 100)) << avoid.DrainStderr();
  ASSERT_TRUE(watch.WaitForStdoutLine("\"frame_id\"", 30s)) << watch.DrainStderr();
  // The export streams too before the server stops: a command that never got a frame gives up at
  // a server shutting down (it may be a wrong address), and a slow start under load would be that.
  ASSERT_TRUE(SubscribersStreaming(3)) << exporter.DrainStderr();

  server_.process()->Signal(SIGTERM);
  ASSERT_EQ(server_.process()->Wait(10s), 0);
  // The consumers see the stream end; the autopilot example then says NO_DATA.
  ASSERT_TRUE(avoid.WaitForStderrLine("stevi: avoid: stream lost", 10s));
  ASSERT_TRUE(watch.WaitForStderrLine("stevi: watch: stream lost", 10s));
  for (int i = 0; i < 5; ++i) ASSERT_TRUE(avoid.WaitForStdoutLine("NO_DATA", 10s));
  ASSERT_NO_FATAL_FAILURE(server_.Restart());

  const std::optional<std::string> back = avoid.WaitForStderrLine("stevi: avoid: stream back", 30s);
  ASSERT_TRUE(back) << avoid.DrainStderr();
  std::cout << *back << "\n";
  ASSERT_TRUE(NextFrameAdvisory(avoid, 100));
  ASSERT_TRUE(watch.WaitForStderrLine("stevi: watch: stream back", 30s));
  ASSERT_TRUE(watch.WaitForStdoutLine("\"frame_id\"", 30s));
  const std::optional<int> exported = exporter.Wait(60s);
  EXPECT_EQ(exported, 0) << exporter.DrainStderr();
  EXPECT_THAT(exporter.DrainStderr(), HasSubstr("stevi: export: stream back"));

  avoid.Signal(SIGTERM);
  watch.Signal(SIGTERM);
  EXPECT_EQ(avoid.Wait(10s), 0) << "avoid ends cleanly on SIGTERM";
  EXPECT_EQ(watch.Wait(10s), 0) << "watch ends cleanly on SIGTERM";
  // From the last frame before the stop to the first after the restart: only NO_DATA, each
  // within 250 ms of the one before (10 Hz, with slack for a busy machine).
  const std::vector<std::pair<int64_t, bool>> times = AdvisoryTimes(avoid.DrainStdout());
  // The restart's run of NO_DATA: the longest one between two frames. (Under a sanitizer the
  // instrumented server's frames can come more than 500 ms apart, so a short run of NO_DATA can
  // show before the stop too.)
  size_t first_no_data = 0, resumed = 0;
  for (size_t i = 1; i < times.size(); ++i) {
    if (!times[i].second || times[i - 1].second) continue;  // not a run's start after a frame
    size_t end = i;
    while (end < times.size() && times[end].second) ++end;
    if (end < times.size() && end - i > resumed - first_no_data) {
      first_no_data = i;
      resumed = end;
    }
  }
  ASSERT_GT(resumed, first_no_data) << "frames before the stop, NO_DATA, then frames resumed";
  const int64_t first_gap_ns = times[first_no_data].first - times[first_no_data - 1].first;
  int64_t longest_gap_ns = 0;  // between NO_DATA advisories
  for (size_t i = first_no_data + 1; i < resumed; ++i) {
    longest_gap_ns = std::max(longest_gap_ns, times[i].first - times[i - 1].first);
  }
  std::cout << "avoid across the restart: " << resumed - first_no_data
            << " NO_DATA advisories, the first " << first_gap_ns / 1'000'000
            << " ms after the last frame, then at most " << longest_gap_ns / 1'000'000
            << " ms apart\n";
  EXPECT_GE(resumed - first_no_data, 5u);  // waited for before the restart
  EXPECT_LE(first_gap_ns, 1'000'000'000) << "NO_DATA comes 500 ms after the last frame";
  EXPECT_LE(longest_gap_ns, 300'000'000) << "NO_DATA at 10 Hz, never silent";
}

// Ground-station exports of the demo flight (the rig hovering at Pisa): KML from the live stream,
// GeoJSON from a file of `stevi watch --json` lines; both hold the tracks where they are.
TEST_F(ServerProcessTest, ExportWritesKmlAndGeoJsonAtTheRightPlace) {
  const std::string dir = testing::MakeTempDir("stevi-export");
  const testing::RunResult kml = Stevi({"export", "--format", "kml", "--count", "20", "--out",
                                        dir + "/demo.kml", "--geoid-undulation", "47.5"});
  ASSERT_EQ(kml.exit_code, 0) << kml.err;
  std::ifstream kml_file(dir + "/demo.kml");
  std::stringstream kml_text;
  kml_text << kml_file.rdbuf();
  EXPECT_THAT(kml_text.str(), HasSubstr("<kml xmlns=\"http://www.opengis.net/kml/2.2\""));
  EXPECT_THAT(kml_text.str(), HasSubstr("<Placemark"));
  // lon,lat,alt near the rig (10.3925 E, 43.6839 N): within ~100 m.
  EXPECT_TRUE(std::regex_search(kml_text.str(), std::regex("10\\.39[0-9]+,43\\.68[0-9]+,")))
      << kml_text.str().substr(0, 2000);

  const testing::RunResult watch = Stevi({"watch", "--json", "--count", "10"});
  ASSERT_EQ(watch.exit_code, 0) << watch.err;
  {
    std::ofstream frames(dir + "/frames.jsonl");
    frames << watch.out;
  }
  const testing::RunResult geojson = Stevi({"export", "--format", "geojson", "--in",
                                            dir + "/frames.jsonl", "--out", dir + "/demo.geojson"});
  ASSERT_EQ(geojson.exit_code, 0) << geojson.err;
  std::ifstream geojson_file(dir + "/demo.geojson");
  std::stringstream geojson_text;
  geojson_text << geojson_file.rdbuf();
  // Read with an independent JSON parser (nlohmann's), not the protobuf one stevi writes with.
  const nlohmann::json parsed = nlohmann::json::parse(geojson_text.str(), nullptr, false);
  ASSERT_FALSE(parsed.is_discarded()) << geojson_text.str().substr(0, 500);
  EXPECT_EQ(parsed.value("type", ""), "FeatureCollection");
  ASSERT_TRUE(parsed.contains("features") && parsed["features"].is_array())
      << geojson_text.str().substr(0, 500);
  const nlohmann::json& features = parsed["features"];
  ASSERT_GE(features.size(), 3u);
  for (const nlohmann::json& feature : features) {
    const nlohmann::json coordinates =
        feature.value("geometry", nlohmann::json::object()).value("coordinates", nlohmann::json());
    ASSERT_TRUE(coordinates.is_array() && !coordinates.empty()) << feature.dump().substr(0, 300);
    // A LineString's first position or a Point: [lon, lat, alt].
    const nlohmann::json& first = coordinates[0].is_array() ? coordinates[0] : coordinates;
    ASSERT_GE(first.size(), 2u);
    EXPECT_NEAR(first[0].get<double>(), 10.3925, 0.002) << "longitude first";
    EXPECT_NEAR(first[1].get<double>(), 43.6839, 0.002);
  }

  const testing::RunResult missing =
      Stevi({"export", "--format", "kml", "--in", dir + "/none.jsonl", "--out", dir + "/x.kml"});
  EXPECT_EQ(missing.exit_code, 1);
  {
    std::ofstream bad(dir + "/bad.jsonl");
    bad << "{\"frame_id\": 1}\nnot json\n";
  }
  const testing::RunResult garbage =
      Stevi({"export", "--format", "kml", "--in", dir + "/bad.jsonl", "--out", dir + "/x.kml"});
  EXPECT_EQ(garbage.exit_code, 1);
  EXPECT_THAT(garbage.err, HasSubstr("line 2"));
}

TEST_F(ServerProcessTest, ConfigStatusSnapshotAndCleanStop) {
  const testing::RunResult bad = Stevi(
      {"config", "set", "canonical.threshold_range_m=-5", "matcher.block_matching.block_size=8"});
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_THAT(bad.err, HasSubstr("INVALID_ARGUMENT"));
  EXPECT_THAT(bad.err, HasSubstr("canonical.threshold_range_m"));
  EXPECT_THAT(bad.err, HasSubstr("matcher.block_matching.block_size"));
  EXPECT_EQ(CountLines(bad.err), 1) << bad.err;

  const testing::RunResult typo = Stevi({"config", "set", "canonical.threshold=5"});
  EXPECT_EQ(typo.exit_code, 2);
  EXPECT_THAT(typo.err, HasSubstr("threshold_range_m"));

  const testing::RunResult good = Stevi({"config", "set", "matcher.kind=semi_global"});
  EXPECT_EQ(good.exit_code, 0) << good.err;
  const testing::RunResult get = Stevi({"config", "get", "--json"});
  ASSERT_EQ(get.exit_code, 0) << get.err;
  EXPECT_THAT(get.out, HasSubstr("MATCHER_KIND_SEMI_GLOBAL"));
  EXPECT_THAT(get.out, HasSubstr("\"threshold_range_m\":0"));

  ASSERT_EQ(Stevi({"watch", "--count", "2", "--json"}).exit_code, 0);

  // The detectors switch while running; their parameters are validated by name.
  for (const char* algorithm : {"stevie", "stevis"}) {
    const testing::RunResult set = Stevi({"config", "set", std::string("algorithm=") + algorithm});
    ASSERT_EQ(set.exit_code, 0) << set.err;
    // Frames already queued may still carry the old algorithm: wait for a new one (bounded).
    const testing::RunResult frames = Stevi({"watch", "--count", "12", "--json"});
    ASSERT_EQ(frames.exit_code, 0) << frames.err;
    const std::string name =
        std::string("ALGORITHM_") + (std::string(algorithm) == "stevie" ? "STEVIE" : "STEVIS");
    EXPECT_THAT(frames.out, HasSubstr(name));
  }
  const testing::RunResult bad_stevis = Stevi({"config", "set", "stevis.saliency_threshold=0"});
  EXPECT_EQ(bad_stevis.exit_code, 1);
  EXPECT_THAT(bad_stevis.err, HasSubstr("stevis.saliency_threshold"));
  const testing::RunResult still = Stevi({"config", "get", "--json"});
  EXPECT_THAT(still.out, HasSubstr("ALGORITHM_STEVIS"))
      << "a refused change leaves the active config";

  const testing::RunResult status = Stevi({"status"});
  ASSERT_EQ(status.exit_code, 0) << status.err;
  EXPECT_THAT(status.out, HasSubstr("(running)"));
  EXPECT_THAT(status.out, HasSubstr("disparity"));

  const std::string prefix = testing::MakeTempDir("stevi-snapshot") + "/snap";
  const testing::RunResult snapshot = Stevi({"snapshot", "--out", prefix});
  ASSERT_EQ(snapshot.exit_code, 0) << snapshot.err;
  for (const char* suffix :
       {"_disparity16.png", "_disparity_colour.png", "_left.png", "_annotated.png", "_meta.json"}) {
    EXPECT_TRUE(std::filesystem::exists(prefix + suffix)) << prefix + suffix;
  }
  std::ifstream meta(prefix + "_meta.json");
  std::stringstream text;
  text << meta.rdbuf();
  EXPECT_THAT(text.str(), HasSubstr("\"f_px\":700"));

  server_.process()->Signal(SIGTERM);
  EXPECT_EQ(server_.process()->Wait(10s), 0) << server_.process()->DrainStderr();
  EXPECT_THAT(server_.process()->DrainStderr(), HasSubstr("stopped"));
}

TEST(Stevi, AnUnreachableServerIsOneClearLine) {
  const testing::RunResult r =
      testing::Run({BinaryPath("stevi"), "--server", "127.0.0.1:1", "--timeout", "2", "status"},
                   kCommandTimeout);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.err, HasSubstr("cannot reach the server at 127.0.0.1:1"));
  EXPECT_EQ(CountLines(r.err), 1) << r.err;

  const testing::RunResult w = testing::Run(
      {BinaryPath("stevi"), "--server", "127.0.0.1:1", "--timeout", "2", "watch"}, kCommandTimeout);
  EXPECT_EQ(w.exit_code, 1);
  EXPECT_EQ(CountLines(w.err), 1) << w.err;

  const testing::RunResult usage = testing::Run({BinaryPath("stevi"), "fly"}, kCommandTimeout);
  EXPECT_EQ(usage.exit_code, 2);
  EXPECT_THAT(usage.err, HasSubstr("unknown command 'fly'"));
}

// `stevi --help` lists every command, each with a summary, and each command has its own usage,
// from `stevi help NAME` and from `stevi NAME --help` alike. The list below is the reference: a
// command added to the binary and not here, or dropped from its table, fails.
TEST(Stevi, HelpListsEveryCommandAndEachHasItsOwnUsage) {
  const std::set<std::string> expected = {"watch",  "status",      "config",  "snapshot",
                                          "record", "calibrate",   "avoid",   "export",
                                          "mcap",   "calibration", "mavlink", "station"};
  const testing::RunResult help = testing::Run({BinaryPath("stevi"), "--help"}, kCommandTimeout);
  ASSERT_EQ(help.exit_code, 0) << help.err;
  const size_t commands_at = help.out.find("\nCommands:\n");
  ASSERT_NE(commands_at, std::string::npos) << help.out;
  std::set<std::string> listed;
  std::istringstream lines(help.out.substr(commands_at + 11));
  for (std::string line; std::getline(lines, line) && !line.empty();) {
    std::istringstream words(line);
    std::string name, first_word_of_summary;
    words >> name >> first_word_of_summary;
    EXPECT_FALSE(first_word_of_summary.empty()) << "no summary: " << line;
    listed.insert(name);
  }
  EXPECT_EQ(listed, expected);
  for (const std::string& name : expected) {
    const testing::RunResult usage =
        testing::Run({BinaryPath("stevi"), "help", name}, kCommandTimeout);
    EXPECT_EQ(usage.exit_code, 0) << name << ": " << usage.err;
    EXPECT_EQ(usage.out.rfind("usage: stevi " + name, 0), 0u) << usage.out;
    const testing::RunResult flag =
        testing::Run({BinaryPath("stevi"), name, "--help"}, kCommandTimeout);
    EXPECT_EQ(flag.exit_code, 0) << name << ": " << flag.err;
    EXPECT_EQ(flag.out, usage.out) << name;
  }
  const testing::RunResult unknown =
      testing::Run({BinaryPath("stevi"), "help", "fly"}, kCommandTimeout);
  EXPECT_EQ(unknown.exit_code, 2);
  EXPECT_THAT(unknown.err, HasSubstr("unknown command 'fly'"));
}

TEST(SteviProcess, SyntheticFramesAndTruthAgree) {
  const std::string dir = testing::MakeTempDir("stevi-process");
  const testing::RunResult r =
      testing::Run({BinaryPath("stevi-process"), "--frames", "12", "--out", dir + "/tracks.jsonl",
                    "--truth", dir + "/truth.jsonl"},
                   kCommandTimeout);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::ifstream tracks_file(dir + "/tracks.jsonl"), truth_file(dir + "/truth.jsonl");
  std::stringstream tracks_text, truth_text;
  tracks_text << tracks_file.rdbuf();
  truth_text << truth_file.rdbuf();
  const auto frames = ParseJsonLines<v1::TrackFrame>(tracks_text.str());
  const auto truths = ParseJsonLines<v1::TruthFrame>(truth_text.str());
  ASSERT_EQ(frames.size(), 12u);
  ASSERT_EQ(truths.size(), 12u);
  for (size_t i = 0; i < frames.size(); ++i) {
    EXPECT_EQ(frames[i].frame_id(), i + 1) << "no frame is dropped";
    EXPECT_EQ(frames[i].source_index(), truths[i].source_index());
  }
  // Depth against the truth file alone (no renderer in this check).
  int matched = 0, expected = 0;
  for (size_t i = 0; i < frames.size(); ++i) {
    std::vector<cv::Rect> boxes, truth_boxes;
    std::vector<double> truth_depths;
    for (const auto& t : frames[i].tracks()) {
      boxes.emplace_back(t.bbox().x(), t.bbox().y(), t.bbox().width(), t.bbox().height());
    }
    for (const auto& o : truths[i].obstacles()) {
      if (o.visible_px() < 300 || 700 * 0.6 / o.depth_m() < 8) continue;
      truth_boxes.emplace_back(o.bbox().x(), o.bbox().y(), o.bbox().width(), o.bbox().height());
      truth_depths.push_back(o.depth_m());
    }
    expected += static_cast<int>(truth_boxes.size());
    for (const auto& [d, t] : testing::MatchByIoU(boxes, truth_boxes, 0.3)) {
      ++matched;
      EXPECT_NEAR(frames[i].tracks(d).depth_m(), truth_depths[t], 0.02 * truth_depths[t]);
    }
  }
  EXPECT_GE(matched, 0.9 * expected) << matched << " of " << expected;

  const testing::RunResult bad =
      testing::Run({BinaryPath("stevi-process"), "--frames", "zero"}, kCommandTimeout);
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_THAT(bad.err, HasSubstr("--frames"));
}

// Fronto-parallel textured targets at 10..40 m, written as an image sequence with a calibration
// file, read back through `stevi-process --source images`.
TEST(SteviProcess, ImageSequenceDepthWithinTwoPercent) {
  const std::string dir = testing::MakeTempDir("stevi-sequence");
  drivers::SyntheticOptions options;
  options.scene.obstacles.clear();
  const std::vector<double> depths = {10, 15, 20, 25, 30, 40};
  for (size_t i = 0; i < depths.size(); ++i) {
    drivers::Obstacle target;
    target.id = static_cast<int>(i) + 1;
    target.name = "target-" + std::to_string(static_cast<int>(depths[i])) + "m";
    // About 90 x 70 px at every depth, one per frame, in front of the sky.
    target.size_m = cv::Vec3d(90 * depths[i] / options.f_px, 70 * depths[i] / options.f_px, 0.5);
    target.path.start = cv::Vec3d(0, -0.15 * depths[i], depths[i] + 0.25);
    // Each target only in its own frame: the others sit far behind the camera.
    options.scene.obstacles.push_back(target);
  }
  std::vector<std::vector<drivers::ObstacleTruth>> truth_per_frame;
  for (size_t k = 0; k < depths.size(); ++k) {
    drivers::SyntheticOptions single = options;
    single.scene.obstacles = {options.scene.obstacles[k]};
    drivers::SyntheticRenderer renderer(single);
    drivers::FrameTruth truth;
    const StereoFrame frame = renderer.Render(0, &truth);
    char name[64];
    std::snprintf(name, sizeof name, "/left_%03zu.png", k);
    ASSERT_TRUE(cv::imwrite(dir + name, frame.left));
    std::snprintf(name, sizeof name, "/right_%03zu.png", k);
    ASSERT_TRUE(cv::imwrite(dir + name, frame.right));
    truth_per_frame.push_back(truth.obstacles);
  }
  ASSERT_TRUE(geometry::SaveCalibrationYaml(testing::SyntheticCalibration(options),
                                            dir + "/calibration.yaml")
                  .ok());

  const testing::RunResult r = testing::Run(
      {BinaryPath("stevi-process"), "--source", "images", "--left", dir + "/left_%03d.png",
       "--right", dir + "/right_%03d.png", "--calibration", dir + "/calibration.yaml"},
      kCommandTimeout);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto frames = ParseJsonLines<v1::TrackFrame>(r.out);
  ASSERT_EQ(frames.size(), depths.size());
  std::cout << "stevi-process over an image sequence:\n  truth m  measured m  error %\n";
  for (size_t k = 0; k < frames.size(); ++k) {
    const drivers::ObstacleTruth& truth = truth_per_frame[k].front();
    // The tracks measured in this frame (the previous frame's target, at another depth in the same
    // place, coasts on its own track: the depth gate keeps them apart).
    std::vector<cv::Rect> boxes;
    std::vector<int> measured_tracks;
    for (int i = 0; i < frames[k].tracks_size(); ++i) {
      const v1::Track& t = frames[k].tracks(i);
      if (t.misses() > 0) continue;
      boxes.emplace_back(t.bbox().x(), t.bbox().y(), t.bbox().width(), t.bbox().height());
      measured_tracks.push_back(i);
    }
    const auto matches = testing::MatchByIoU(boxes, {truth.bbox}, 0.3);
    ASSERT_EQ(matches.size(), 1u) << "target at " << truth.depth_m << " m not found";
    const double measured = frames[k].tracks(measured_tracks[matches[0].first]).depth_m();
    const double error = 100 * (measured - truth.depth_m) / truth.depth_m;
    std::printf("  %7.2f  %10.3f  %+7.3f\n", truth.depth_m, measured, error);
    EXPECT_LE(std::abs(error), 2.0) << "target at " << truth.depth_m << " m";
    // The rule for the rig: within 1 % at disparity >= 16 px, else within the quantisation bound
    // dZ = Z^2 / (f B) * dd for a quarter-pixel disparity error.
    const double fB = options.f_px * options.baseline_m;
    const double allowed_m =
        fB / truth.depth_m >= 16 ? 0.01 * truth.depth_m : truth.depth_m * truth.depth_m / fB * 0.25;
    EXPECT_LE(std::abs(measured - truth.depth_m), allowed_m)
        << "target at " << truth.depth_m << " m";
  }
}

}  // namespace
}  // namespace stevi
