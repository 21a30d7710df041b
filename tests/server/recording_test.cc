// Recording and replay through the real binaries: stevi-server --record and `stevi record`, then
// stevi-process --source replay and stevi-server --source replay.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "stevi/v1/obstacle_service.pb.h"
#include "tests/server/server_process.h"
#include "tests/testing/sanitized.h"

namespace stevi {
namespace {

using testing::BinaryPath;
using ::testing::HasSubstr;
using testing::kCommandTimeout;
using testing::ParseJsonLines;

std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

v1::RecordingStatus ParseRecordingStatus(const testing::RunResult& r) {
  const std::vector<v1::RecordingStatus> statuses = ParseJsonLines<v1::RecordingStatus>(r.out);
  EXPECT_EQ(statuses.size(), 1u) << r.out << r.err;
  return statuses.empty() ? v1::RecordingStatus() : statuses[0];
}

v1::GetStatusResponse Status(const testing::ServerProcess& server) {
  const testing::RunResult r = server.Stevi({"status", "--json"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  const std::vector<v1::GetStatusResponse> s = ParseJsonLines<v1::GetStatusResponse>(r.out);
  return s.empty() ? v1::GetStatusResponse() : s[0];
}

// stevi-process over a recording: its stdout (JSON lines) and exit code.
testing::RunResult ProcessReplay(const std::string& dir,
                                 const std::vector<std::string>& extra = {}) {
  std::vector<std::string> args{BinaryPath("stevi-process"), "--source", "replay", "--replay", dir};
  args.insert(args.end(), extra.begin(), extra.end());
  return testing::Run(args, kCommandTimeout);
}

// The tracks of a frame without what only a pose gives (a replay carries the recorded poses; the
// synthetic source run offline has none), for comparing detections and tracking.
// The tracks as the detections and the association made them, without what the vehicle's pose
// shapes: the geodetic fields, and the Kalman state, which the tracker carries through the
// ego-motion between the poses (the replay's come through the pose buffer from the recorded
// states, the live ones straight from the synthetic flight, so they differ in the last bits).
std::string TracksWithoutGeo(const v1::TrackFrame& frame) {
  std::string out;
  for (v1::Track t : frame.tracks()) {
    t.clear_geodetic();
    t.clear_velocity_ned();
    t.clear_position_sigma_m();
    t.clear_position_cam();
    t.clear_position_body();
    t.clear_position_sigma_cam();
    t.clear_velocity_cam();
    t.clear_velocity_sigma_cam();
    t.clear_range_rate_mps();
    t.clear_range_rate_sigma_mps();
    t.clear_time_to_collision_s();
    t.clear_closest_approach_m();
    t.clear_smoothed_range_m();
    out += t.SerializeAsString();
  }
  return out;
}

// The acceptance: 100 frames of the synthetic source recorded by the server, replayed twice
// through stevi-process, give byte-identical output; and the replay reproduces what the same
// synthetic frames give when generated offline (the recording is lossless and keeps the timing).
// Under a sanitizer, 30 frames: the same code paths, at a third of the cost of the three offline
// runs of the instrumented pipeline (about 140 s under AddressSanitizer with 100).
TEST(Recording, HundredSyntheticFramesReplayTwiceByteIdenticalAndAsLive) {
  constexpr int kFrames = testing::kSanitized ? 30 : 100;
  const std::string frames = std::to_string(kFrames);
  const std::string dir = testing::MakeTempDir("stevi-record") + "/airfield";
  testing::ServerProcess server;
  // 10 fps and a deep writer queue: the recorder (PNG level 1, ~18 ms a frame on one core) keeps
  // up even while other tests load both cores, so that no frame is dropped and the replay can be
  // compared with the source frame for frame.
  const std::string config = testing::MakeTempDir("stevi-record-config") + "/server.textproto";
  std::ofstream(config) << "record { dir: \"" << dir << "\" queue_frames: 256 }\n";
  ASSERT_NO_FATAL_FAILURE(server.Start({"--fps", "10", "--config", config}));
  // kFrames + 5 processed frames: the recorder has been handed at least as many.
  const testing::RunResult watch =
      server.Stevi({"watch", "--count", std::to_string(kFrames + 5), "--json"});
  ASSERT_EQ(watch.exit_code, 0) << watch.err;
  const v1::RecordingStatus stopped =
      ParseRecordingStatus(server.Stevi({"record", "stop", "--json"}));
  EXPECT_FALSE(stopped.active());
  ASSERT_GE(stopped.frames_written(), static_cast<uint64_t>(kFrames));
  EXPECT_EQ(stopped.frames_dropped(), 0u);
  EXPECT_THAT(stopped.stop_reason(), HasSubstr("request"));
  std::cout << "recorded " << stopped.frames_written() << " frames, "
            << stopped.bytes_written() / stopped.frames_written() << " bytes a frame\n";
  // Stopped means stopped: frames keep flowing, the recording does not grow.
  ASSERT_EQ(server.Stevi({"watch", "--count", "5"}).exit_code, 0);
  EXPECT_EQ(Status(server).recording().frames_written(), stopped.frames_written());

  const std::string out_dir = testing::MakeTempDir("stevi-replay");
  const testing::RunResult first = ProcessReplay(
      dir, {"--frames", frames, "--algorithm", "stevie", "--out", out_dir + "/a.jsonl"});
  ASSERT_EQ(first.exit_code, 0) << first.err;
  const testing::RunResult second = ProcessReplay(
      dir, {"--frames", frames, "--algorithm", "stevie", "--out", out_dir + "/b.jsonl"});
  ASSERT_EQ(second.exit_code, 0) << second.err;
  const std::string a = ReadFile(out_dir + "/a.jsonl");
  const std::string b = ReadFile(out_dir + "/b.jsonl");
  const std::vector<v1::TrackFrame> replayed = ParseJsonLines<v1::TrackFrame>(a);
  ASSERT_EQ(replayed.size(), static_cast<size_t>(kFrames));
  EXPECT_TRUE(a == b) << "two replays of one recording differ";
  size_t tracks = 0, geodetic = 0;
  for (const v1::TrackFrame& f : replayed) {
    tracks += f.tracks_size();
    for (const v1::Track& t : f.tracks()) geodetic += t.has_geodetic() ? 1 : 0;
    EXPECT_EQ(f.timings_size(), 0) << "wall-clock timings would make the output differ";
  }
  EXPECT_GT(tracks, 3u * kFrames) << "the airfield has several obstacles in every frame";
  EXPECT_EQ(geodetic, tracks) << "the recorded vehicle poses georeference every track";
  std::cout << "replay: " << kFrames << " frames, " << tracks << " tracks, " << a.size()
            << " bytes of JSON, identical twice\n";

  // The same frames generated offline: identical detections and tracks (the geodetic fields
  // aside), frame by frame, from the first recorded frame on.
  const testing::RunResult live = testing::Run(
      {BinaryPath("stevi-process"), "--fps", "10", "--frames", frames, "--algorithm", "stevie"},
      kCommandTimeout);
  ASSERT_EQ(live.exit_code, 0) << live.err;
  const std::vector<v1::TrackFrame> generated = ParseJsonLines<v1::TrackFrame>(live.out);
  ASSERT_EQ(generated.size(), static_cast<size_t>(kFrames));
  int same = 0;
  for (size_t i = 0; i < generated.size(); ++i) {
    EXPECT_EQ(replayed[i].source_index(), generated[i].source_index());
    EXPECT_EQ(replayed[i].capture_time_ns(), generated[i].capture_time_ns());
    same += TracksWithoutGeo(replayed[i]) == TracksWithoutGeo(generated[i]) ? 1 : 0;
  }
  EXPECT_EQ(same, kFrames) << "the replay must reproduce the source's frames exactly";
}

// Recording through the RPCs: names are checked (no path escapes the data directory), one
// recording at a time, and the disk bound stops a recording by itself, leaving it replayable.
TEST(Recording, RpcChecksNamesAndStopsAtTheDiskLimit) {
  testing::ServerProcess server;
  ASSERT_NO_FATAL_FAILURE(server.Start({"--fps", "30"}));
  for (const std::string& bad :
       std::vector<std::string>{"../escape", "a/b", ".hidden", std::string(65, 'x')}) {
    const testing::RunResult r = server.Stevi({"record", "start", "--name", bad});
    EXPECT_NE(r.exit_code, 0) << bad;
    EXPECT_THAT(r.err, HasSubstr("INVALID_ARGUMENT")) << bad;
    EXPECT_THAT(r.err, HasSubstr("name")) << bad;
  }
  // One recording at a time. (Not shown with the small one below: its limit may end it before
  // a second command arrives.)
  const v1::RecordingStatus first =
      ParseRecordingStatus(server.Stevi({"record", "start", "--name", "first", "--json"}));
  EXPECT_TRUE(first.active());
  const testing::RunResult twice = server.Stevi({"record", "start", "--name", "other"});
  EXPECT_NE(twice.exit_code, 0);
  EXPECT_THAT(twice.err, HasSubstr("FAILED_PRECONDITION"));
  EXPECT_THAT(twice.err, HasSubstr("recordings/first"));
  ASSERT_EQ(server.Stevi({"record", "stop"}).exit_code, 0);

  const v1::RecordingStatus started = ParseRecordingStatus(
      server.Stevi({"record", "start", "--name", "small", "--max-mb", "1", "--json"}));
  EXPECT_EQ(started.max_bytes(), 1u << 20);
  EXPECT_THAT(started.dir(), HasSubstr("recordings/small"));

  // 1 MiB holds a handful of 640x480 pairs: the recording stops by itself. Wait for it through
  // the frames it sees (bounded: 300 frames at 30 fps).
  v1::RecordingStatus after;
  for (int i = 0; i < 30; ++i) {
    ASSERT_EQ(server.Stevi({"watch", "--count", "10"}).exit_code, 0);
    after = Status(server).recording();
    if (!after.active()) break;
  }
  EXPECT_FALSE(after.active()) << "still recording after 300 frames with a 1 MiB limit";
  EXPECT_THAT(after.stop_reason(), HasSubstr("disk limit"));
  EXPECT_GT(after.frames_written(), 0u);
  EXPECT_LE(after.bytes_written(), 1u << 20);
  const testing::RunResult again = server.Stevi({"record", "start", "--name", "small"});
  EXPECT_THAT(again.err, HasSubstr("ALREADY_EXISTS"));

  const testing::RunResult replay = ProcessReplay(server.data_dir() + "/recordings/small");
  ASSERT_EQ(replay.exit_code, 0) << replay.err;
  EXPECT_EQ(ParseJsonLines<v1::TrackFrame>(replay.out).size(), after.frames_written());
}

// stevi-server --source replay plays a recording at its recorded timing (here 4x), with the
// recorded capture times, and says ENDED at its end while it keeps serving.
TEST(Recording, TheServerPlaysARecordingAndEnds) {
  const std::string dir = testing::MakeTempDir("stevi-record") + "/short";
  {
    testing::ServerProcess recorder;
    ASSERT_NO_FATAL_FAILURE(recorder.Start({"--fps", "20", "--record", dir}));
    ASSERT_EQ(recorder.Stevi({"watch", "--count", "30"}).exit_code, 0);
    ASSERT_EQ(recorder.Stevi({"record", "stop"}).exit_code, 0);
  }
  const testing::RunResult offline = ProcessReplay(dir);
  ASSERT_EQ(offline.exit_code, 0) << offline.err;
  const std::vector<v1::TrackFrame> recorded = ParseJsonLines<v1::TrackFrame>(offline.out);
  ASSERT_GE(recorded.size(), 30u);

  testing::ServerProcess player;
  // 4x (80 fps). Under a sanitizer 0.1x (2 fps) and 5 frames: its instrumented pipeline takes
  // under 2 frames a second (ThreadSanitizer, 2026-11-29), and would see too few of the 30-odd
  // frames to fill the watch before the end.
  ASSERT_NO_FATAL_FAILURE(player.Start(
      {"--source", "replay", "--replay", dir, "--rate", testing::kSanitized ? "0.1" : "4"}));
  const int want = testing::kSanitized ? 5 : 10;
  const testing::RunResult watch =
      player.Stevi({"watch", "--count", std::to_string(want), "--json"});
  ASSERT_EQ(watch.exit_code, 0) << watch.err;
  const std::vector<v1::TrackFrame> played = ParseJsonLines<v1::TrackFrame>(watch.out);
  ASSERT_EQ(played.size(), static_cast<size_t>(want));
  for (const v1::TrackFrame& f : played) {
    ASSERT_LT(static_cast<size_t>(f.source_index()), recorded.size());
    EXPECT_EQ(f.capture_time_ns(), recorded[f.source_index()].capture_time_ns());
  }
  v1::GetStatusResponse status = Status(player);
  EXPECT_THAT(status.source(), HasSubstr("replay"));
  // At 4x, 30-odd frames at 20 fps last under 0.5 s (at 0.1x, under 20 s): the end comes within
  // a bounded number of status calls (each one a process start, tens of milliseconds; seconds
  // under a sanitizer).
  for (int i = 0; i < 200 && status.source_state() != v1::SOURCE_STATE_ENDED; ++i) {
    status = Status(player);
  }
  EXPECT_EQ(status.source_state(), v1::SOURCE_STATE_ENDED);
  EXPECT_EQ(status.frames_captured(), recorded.size());
}

// Refusals before anything runs: a replay of nothing, stevi-process on cameras.
TEST(Recording, BadReplayArgumentsAreNamed) {
  const std::string empty = testing::MakeTempDir("stevi-no-recording");
  const testing::RunResult none = ProcessReplay(empty);
  EXPECT_NE(none.exit_code, 0);
  EXPECT_THAT(none.err, HasSubstr("manifest"));
  const testing::RunResult no_dir =
      testing::Run({BinaryPath("stevi-process"), "--source", "replay"}, kCommandTimeout);
  EXPECT_EQ(no_dir.exit_code, 2);
  EXPECT_THAT(no_dir.err, HasSubstr("source.replay.dir"));
  const testing::RunResult cameras = testing::Run(
      {BinaryPath("stevi-process"), "--source", "aravis", "--left", "a", "--right", "b"},
      kCommandTimeout);
  EXPECT_EQ(cameras.exit_code, 2);
  EXPECT_THAT(cameras.err, HasSubstr("stevi-process runs recorded or generated frames"));
  const testing::RunResult rate = testing::Run(
      {BinaryPath("stevi-server"), "--source", "replay", "--replay", empty, "--rate", "fast"},
      kCommandTimeout);
  EXPECT_EQ(rate.exit_code, 2);
  EXPECT_THAT(rate.err, HasSubstr("--rate"));
}

}  // namespace
}  // namespace stevi
