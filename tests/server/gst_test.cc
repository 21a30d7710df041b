// GStreamer sources through the real binaries: a side-by-side video read with `--source video`
// gives the obstacles and ranges of its own frames (lossless: all of them, every range within 1 %;
// Motion-JPEG: nearly all); the same frames from an RTSP camera (a real gst-rtsp-server on
// loopback) give the same obstacles, and its loss and return show in the server's status and the
// stream resumes by itself;
// bad settings are named before anything starts.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>

#include <opencv2/imgcodecs.hpp>

#include "core/geometry/calibration_io.h"
#include "drivers/synthetic/synthetic_source.h"
#include "stevi/v1/obstacle_service.pb.h"
#include "tests/server/server_process.h"
#include "tests/testing/gst_testing.h"
#include "tests/testing/sanitized.h"
#include "tests/testing/synthetic_calibration.h"
#include "tests/testing/truth_match.h"

namespace stevi {
namespace {

using testing::BinaryPath;
using ::testing::HasSubstr;
using testing::kCommandTimeout;
using testing::ParseJsonLines;

constexpr int kFps = 10;
constexpr int kFrames = 40;

v1::GetStatusResponse Status(const testing::ServerProcess& server) {
  const testing::RunResult r = server.Stevi({"status", "--json"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  const std::vector<v1::GetStatusResponse> s = ParseJsonLines<v1::GetStatusResponse>(r.out);
  return s.empty() ? v1::GetStatusResponse() : s[0];
}

cv::Rect Box(const v1::Track& t) {
  return {t.bbox().x(), t.bbox().y(), t.bbox().width(), t.bbox().height()};
}

// The synthetic rig's frames as PNG pairs (the frames themselves), the same frames side by side
// in a lossless video (raw GRAY8 in Matroska) and in a Motion-JPEG AVI, and the rig's
// calibration, in `dir`.
void WriteFramesAndVideos(const std::string& dir) {
  drivers::SyntheticOptions options;
  options.fps = kFps;
  Result<std::unique_ptr<drivers::SyntheticSource>> source = drivers::OpenSyntheticSource(options);
  ASSERT_TRUE(source.ok()) << source.error().message;
  std::vector<cv::Mat> side_by_side;
  for (int k = 0; k < kFrames; ++k) {
    Result<StereoFrame> frame = (*source)->Next();
    ASSERT_TRUE(frame.ok()) << frame.error().message;
    char name[64];
    std::snprintf(name, sizeof name, "/left_%03d.png", k);
    ASSERT_TRUE(cv::imwrite(dir + name, frame->left));
    std::snprintf(name, sizeof name, "/right_%03d.png", k);
    ASSERT_TRUE(cv::imwrite(dir + name, frame->right));
    cv::Mat whole;
    cv::hconcat(frame->left, frame->right, whole);
    side_by_side.push_back(whole);
  }
  ASSERT_NO_FATAL_FAILURE(testing::WriteRawMkv(dir + "/flight.mkv", side_by_side, kFps));
  // The same frames side by side as PNG files, for an RTSP camera to encode.
  for (int k = 0; k < kFrames; ++k) {
    char name[64];
    std::snprintf(name, sizeof name, "/sbs_%03d.png", k);
    ASSERT_TRUE(cv::imwrite(dir + name, side_by_side[k]));
  }
  ASSERT_NO_FATAL_FAILURE(testing::WriteMjpegAvi(dir + "/flight.avi", side_by_side, kFps, 100));
  ASSERT_TRUE(geometry::SaveCalibrationYaml(testing::SyntheticCalibration(options),
                                            dir + "/calibration.yaml")
                  .ok());
}

std::vector<v1::TrackFrame> Process(const std::vector<std::string>& source_args) {
  std::vector<std::string> args{BinaryPath("stevi-process")};
  args.insert(args.end(), source_args.begin(), source_args.end());
  const testing::RunResult r = testing::Run(args, kCommandTimeout);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  return ParseJsonLines<v1::TrackFrame>(r.out);
}

// The confirmed tracks of the frames and of a video of them, frame by frame, matched by their
// boxes (IoU >= 0.5).
struct Agreement {
  size_t compared = 0, missing = 0, extra = 0, within_1_percent = 0;
  double worst_percent = 0;
};

std::vector<std::pair<cv::Rect, double>> Confirmed(const v1::TrackFrame& frame) {
  std::vector<std::pair<cv::Rect, double>> tracks;
  for (const v1::Track& t : frame.tracks()) {
    if (t.state() == v1::TRACK_STATE_CONFIRMED) tracks.emplace_back(Box(t), t.range_m());
  }
  return tracks;
}

Agreement Compare(const std::vector<v1::TrackFrame>& frames,
                  const std::vector<v1::TrackFrame>& video, const char* name) {
  Agreement agreement;
  EXPECT_EQ(video.size(), frames.size()) << name << ": every frame of the video, once";
  for (size_t k = 0; k < std::min(frames.size(), video.size()); ++k) {
    EXPECT_EQ(video[k].capture_time_ns(), frames[k].capture_time_ns()) << name << " frame " << k;
    const auto a = Confirmed(frames[k]);
    const auto b = Confirmed(video[k]);
    std::vector<cv::Rect> boxes_a, boxes_b;
    for (const auto& [box, range] : a) boxes_a.push_back(box);
    for (const auto& [box, range] : b) boxes_b.push_back(box);
    const auto matches = testing::MatchByIoU(boxes_a, boxes_b, 0.5);
    agreement.missing += a.size() - matches.size();
    agreement.extra += b.size() - matches.size();
    for (const auto& [i, j] : matches) {
      const double percent = 100 * std::abs(b[j].second - a[i].second) / a[i].second;
      agreement.worst_percent = std::max(agreement.worst_percent, percent);
      if (percent <= 1.0) ++agreement.within_1_percent;
      ++agreement.compared;
    }
  }
  std::printf(
      "%s vs its frames: %zu confirmed tracks compared, %zu missing, %zu extra, %zu within 1 %%, "
      "worst range difference %.3f %%\n",
      name, agreement.compared, agreement.missing, agreement.extra, agreement.within_1_percent,
      agreement.worst_percent);
  return agreement;
}

TEST(GstSource, AVideoGivesTheObstaclesAndRangesOfItsFrames) {
  const std::string dir = testing::MakeTempDir("stevi-gst-video");
  ASSERT_NO_FATAL_FAILURE(WriteFramesAndVideos(dir));
  const std::string calibration = dir + "/calibration.yaml";
  const std::vector<v1::TrackFrame> frames = Process(
      {"--source", "images", "--left", dir + "/left_%03d.png", "--right", dir + "/right_%03d.png",
       "--calibration", calibration, "--fps", std::to_string(kFps)});
  ASSERT_EQ(frames.size(), static_cast<size_t>(kFrames));

  // A lossless video: the same pixels through filesrc, the demuxer, the layout's split and the
  // appsink. The same obstacles, every range within 1 %.
  const Agreement lossless =
      Compare(frames,
              Process({"--source", "video", "--file", dir + "/flight.mkv", "--layout",
                       "side-by-side", "--calibration", calibration}),
              "lossless video (GRAY8 in Matroska)");
  EXPECT_GE(lossless.compared, 200u) << "the scene's obstacles were confirmed";
  EXPECT_EQ(lossless.missing, 0u);
  EXPECT_EQ(lossless.extra, 0u);
  EXPECT_EQ(lossless.within_1_percent, lossless.compared);

  // Motion-JPEG, even at quality 100, is not lossless: it moves a sub-pixel disparity a little,
  // and a box's pixels with it, so a marginal obstacle may be confirmed a frame earlier or later,
  // and a far one's range differ by over 1 % (measured: 263 compared, 2 missing, 2 extra, 261
  // within 1 %, worst 1.66 % at 26 m). Held: the same obstacles save 2 % of them, 98 % of the
  // ranges within 1 %, none beyond 2.5 %. This measures the codec, not the source.
  const Agreement mjpeg =
      Compare(frames,
              Process({"--source", "video", "--file", dir + "/flight.avi", "--layout",
                       "side-by-side", "--calibration", calibration}),
              "Motion-JPEG video (quality 100)");
  EXPECT_GE(mjpeg.compared, 200u);
  EXPECT_LE(static_cast<double>(mjpeg.missing + mjpeg.extra),
            0.02 * static_cast<double>(mjpeg.compared));
  EXPECT_GE(static_cast<double>(mjpeg.within_1_percent),
            0.98 * static_cast<double>(mjpeg.compared));
  EXPECT_LE(mjpeg.worst_percent, 2.5);
}

// Each frame's confirmed tracks against the reference frame they agree with best (the camera
// loops the sequence and a live source skips frames, so frames are matched by content): the
// same boxes (IoU >= 0.5), and the ranges of their last detections.
Agreement CompareUnaligned(const std::vector<v1::TrackFrame>& reference,
                           const std::vector<v1::TrackFrame>& got, const char* name) {
  Agreement agreement;
  for (const v1::TrackFrame& frame : got) {
    const auto b = Confirmed(frame);
    if (b.empty()) continue;
    std::vector<cv::Rect> boxes_b;
    for (const auto& [box, range] : b) boxes_b.push_back(box);
    size_t best_matches = 0;
    double best_worst = 0;
    size_t best_within = 0;
    for (const v1::TrackFrame& ref : reference) {
      const auto a = Confirmed(ref);
      std::vector<cv::Rect> boxes_a;
      for (const auto& [box, range] : a) boxes_a.push_back(box);
      const auto matches = testing::MatchByIoU(boxes_a, boxes_b, 0.5);
      double worst = 0;
      size_t within = 0;
      for (const auto& [i, j] : matches) {
        const double percent = 100 * std::abs(b[j].second - a[i].second) / a[i].second;
        worst = std::max(worst, percent);
        if (percent <= 1.0) ++within;
      }
      if (matches.size() > best_matches ||
          (matches.size() == best_matches && within > best_within)) {
        best_matches = matches.size();
        best_worst = worst;
        best_within = within;
      }
    }
    agreement.compared += best_matches;
    agreement.extra += b.size() - best_matches;
    agreement.within_1_percent += best_within;
    agreement.worst_percent = std::max(agreement.worst_percent, best_worst);
  }
  std::printf(
      "%s vs the frames: %zu confirmed tracks compared, %zu unmatched, %zu within 1 %%, worst "
      "range difference %.3f %%\n",
      name, agreement.compared, agreement.extra, agreement.within_1_percent,
      agreement.worst_percent);
  return agreement;
}

// The synthetic sequence, served by a real RTSP server on loopback (the side-by-side frames,
// looped, as RTP/JPEG), read through --source rtsp with the rig's calibration: the obstacles and
// ranges of the frames. Then the camera goes away and comes back: the loss shows in the status, and
// the stream and its obstacles resume by themselves.
TEST(GstSource, AnRtspCameraGivesTheObstaclesAndIsLostAndBackByItself) {
  const std::string dir = testing::MakeTempDir("stevi-gst-rtsp");
  ASSERT_NO_FATAL_FAILURE(WriteFramesAndVideos(dir));
  const std::string calibration = dir + "/calibration.yaml";
  const std::vector<v1::TrackFrame> reference = Process(
      {"--source", "images", "--left", dir + "/left_%03d.png", "--right", dir + "/right_%03d.png",
       "--calibration", calibration, "--fps", std::to_string(kFps)});
  ASSERT_EQ(reference.size(), static_cast<size_t>(kFrames));

  // Motion-JPEG at quality 100 over RTP, as the video file's (jpegenc, 4:2:0).
  testing::LoopbackRtspServer camera(
      "( multifilesrc location=\"" + dir +
      "/sbs_%03d.png\" loop=true caps=\"image/png,framerate=" + std::to_string(kFps) +
      "/1\" ! pngdec ! videoconvert ! video/x-raw,format=I420 ! jpegenc quality=100 ! "
      "rtpjpegpay name=pay0 pt=26 )");
  const int port = camera.Serve();
  ASSERT_GT(port, 0);
  testing::ServerProcess server;
  ASSERT_NO_FATAL_FAILURE(server.Start(
      {"--source", "rtsp", "--url", "rtsp://127.0.0.1:" + std::to_string(port) + "/stereo",
       "--latency-ms", "0", "--fps", std::to_string(kFps), "--calibration", calibration}));
  v1::GetStatusResponse status = Status(server);
  for (int i = 0; i < 300 && status.fps_in() <= 0; ++i) status = Status(server);
  EXPECT_EQ(status.source_state(), v1::SOURCE_STATE_RUNNING);
  EXPECT_THAT(status.source(), HasSubstr("rtspsrc"));
  EXPECT_GT(status.fps_in(), 0);

  // Held as the video file's Motion-JPEG is, on the tracks of 30 frames.
  const testing::RunResult watched =
      server.Stevi({"watch", "--json", "--count", "30", "--confirmed"}, kCommandTimeout);
  ASSERT_EQ(watched.exit_code, 0) << watched.err;
  const Agreement rtsp =
      CompareUnaligned(reference, ParseJsonLines<v1::TrackFrame>(watched.out), "RTSP camera");
  EXPECT_GE(rtsp.compared, 60u) << "the scene's obstacles were confirmed";
  EXPECT_LE(static_cast<double>(rtsp.extra), 0.02 * static_cast<double>(rtsp.compared));
  EXPECT_GE(static_cast<double>(rtsp.within_1_percent), 0.98 * static_cast<double>(rtsp.compared));
  EXPECT_LE(rtsp.worst_percent, 2.5);

  camera.Stop();
  for (int i = 0; i < 300 && status.source_state() != v1::SOURCE_STATE_DOWN; ++i) {
    status = Status(server);
  }
  ASSERT_EQ(status.source_state(), v1::SOURCE_STATE_DOWN);
  std::printf("camera lost: %s\n", status.source_error().c_str());
  EXPECT_THAT(status.source_error(), HasSubstr("lost"));

  ASSERT_EQ(camera.Serve(), port);
  for (int i = 0; i < 600 && status.source_state() != v1::SOURCE_STATE_RUNNING; ++i) {
    status = Status(server);
  }
  ASSERT_EQ(status.source_state(), v1::SOURCE_STATE_RUNNING);
  EXPECT_GE(status.pairing().reconnects(), 1u);
  // Frames, and obstacles, flow again.
  const testing::RunResult again =
      server.Stevi({"watch", "--json", "--count", "10", "--confirmed"}, kCommandTimeout);
  ASSERT_EQ(again.exit_code, 0) << again.err;
  const Agreement resumed =
      CompareUnaligned(reference, ParseJsonLines<v1::TrackFrame>(again.out), "after the return");
  EXPECT_GE(resumed.compared, 10u);
}

TEST(GstSource, BadSettingsAreNamedAtStart) {
  struct Case {
    std::vector<std::string> args;
    std::string says;
  };
  const Case cases[] = {
      {{"--source", "video"}, "source.gst.file: required"},
      {{"--source", "uvc"}, "source.gst.width, height: required for uvc"},
      {{"--source", "rtsp", "--url", "http://camera/stream"}, "source.gst.url"},
      {{"--source", "video", "--file", "/no/such/flight.avi"}, "flight.avi"},
      {{"--source", "gst", "--pipeline", "nosuchelement ! jpegdec"}, "nosuchelement"},
      {{"--source", "uvc", "--size", "320x240", "--device", "/dev/video-none"}, "video-none"},
      {{"--source", "video", "--file", "f.avi", "--layout", "diagonal"}, "--layout"},
      {{"--source", "video", "--file", "f.avi", "--left", "a.avi"}, "only with the layout two"},
  };
  for (const Case& c : cases) {
    std::vector<std::string> args{BinaryPath("stevi-server"), "--listen", "127.0.0.1:0",
                                  "--data-dir", testing::MakeTempDir("stevi-gst-bad")};
    args.insert(args.end(), c.args.begin(), c.args.end());
    const testing::RunResult r = testing::Run(args, kCommandTimeout);
    EXPECT_NE(r.exit_code, 0) << r.err;
    EXPECT_THAT(r.err, HasSubstr(c.says)) << "for " << c.args.back();
  }
}

}  // namespace
}  // namespace stevi
