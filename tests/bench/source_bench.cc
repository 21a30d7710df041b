// stevi-bench-io: what reading frames through GStreamer and writing an MCAP flight log cost the
// server, as ratios of its frame rate measured in the same run (the machines are noisy).
//
//   synthetic  the synthetic rig, 640x480, 60 frames rendered once and looped (a camera's cost)
//   video      the same 60 frames side by side (1280x480) in a Motion-JPEG AVI, read through
//              --source video (GStreamer: filesrc, decodebin, jpegdec, videoconvert, appsink),
//              with the rig's calibration (so the frames are rectified as a camera's are)
//   mcap       the synthetic rig again, recording an MCAP flight log with 5 Hz images
//
// Each is run for --seconds (default 10) after a 2 s warm-up, in --rounds interleaved rounds
// (default 2), every source offering --source-fps (default 1000) so that the pipeline is the
// bottleneck. Targets: video within 10 % of synthetic, mcap costing under 10 %.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "core/geometry/calibration_io.h"
#include "drivers/synthetic/synthetic_source.h"
#include "server/server.h"
#include "tests/testing/data.h"
#include "tests/testing/gst_testing.h"

namespace {

using namespace stevi;
using Clock = std::chrono::steady_clock;

constexpr int kFrames = 60;
// The rate every source offers (--source-fps; the video is written at it): by default well over
// what the pipeline processes, so that the pipeline is the bottleneck and the sources' costs show.
double source_fps = 1000;

struct Setup {
  std::string dir;
  std::string video, calibration;
};

bool Prepare(Setup& s) {
  s.dir = testing::MakeTempDir("stevi-bench-io");
  drivers::SyntheticOptions options;
  options.fps = 10;
  Result<std::unique_ptr<drivers::SyntheticSource>> source = drivers::OpenSyntheticSource(options);
  if (!source.ok()) return false;
  std::vector<cv::Mat> frames;
  for (int k = 0; k < kFrames; ++k) {
    Result<StereoFrame> frame = (*source)->Next();
    if (!frame.ok()) return false;
    cv::Mat whole;
    cv::hconcat(frame->left, frame->right, whole);
    frames.push_back(whole);
  }
  s.video = s.dir + "/flight.avi";
  testing::WriteMjpegAvi(s.video, frames, static_cast<int>(source_fps));
  s.calibration = s.dir + "/calibration.yaml";
  return geometry::SaveCalibrationYaml(
             geometry::IdealCalibration(cv::Size(options.width, options.height), options.f_px,
                                        options.baseline_m, options.width / 2.0,
                                        options.height / 2.0),
             s.calibration)
      .ok();
}

v1::ServerConfig Config(const Setup& s, const std::string& variant, int round) {
  v1::ServerConfig config;
  config.set_listen("127.0.0.1:0");
  config.set_data_dir(s.dir + "/data");
  v1::SourceConfig* source = config.mutable_source();
  source->set_fps(source_fps);
  if (variant == "video") {
    source->set_kind(v1::SOURCE_KIND_VIDEO);
    source->mutable_gst()->set_file(s.video);
    source->set_calibration(s.calibration);
    source->set_loop(true);
  } else {
    source->set_kind(v1::SOURCE_KIND_SYNTHETIC);
    source->mutable_synthetic()->set_loop_frames(kFrames);
  }
  if (variant == "mcap") {
    config.mutable_record_mcap()->set_file(s.dir + "/flight-" + std::to_string(round) + ".mcap");
    config.mutable_record_mcap()->set_image_hz(5);
  }
  return config;
}

// Frames processed per second over `seconds`, after a warm-up; < 0 on failure.
double Measure(const v1::ServerConfig& config, double seconds, std::string& note) {
  Result<std::unique_ptr<server::Server>> started = server::Server::Start(config);
  if (!started.ok()) {
    note = started.error().message;
    return -1;
  }
  server::Server& server = **started;
  // Polls the engine's own counters: nothing outside it has an event to wait on.
  const auto processed = [&server] { return server.engine().Status().frames_processed; };
  const Clock::time_point warm = Clock::now() + std::chrono::seconds(2);
  while (Clock::now() < warm) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  const uint64_t first = processed();
  const Clock::time_point start = Clock::now();
  std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  const uint64_t last = processed();
  const double elapsed = std::chrono::duration<double>(Clock::now() - start).count();
  note = server.engine().Status().source;
  if (server::McapRecording* mcap = server.mcap_recording()) {
    const server::McapRecordingStatus st = mcap->Status();
    note += "; mcap " + std::to_string(st.counts.track_frames) + " frames, " +
            std::to_string(st.counts.images) + " images, " + std::to_string(st.frames_dropped) +
            " dropped";
  }
  server.Shutdown();
  return static_cast<double>(last - first) / elapsed;
}

}  // namespace

int main(int argc, char** argv) {
  double seconds = 10;
  int rounds = 2;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string flag = argv[i];
    if (flag == "--seconds") {
      seconds = std::atof(argv[i + 1]);
    } else if (flag == "--rounds") {
      rounds = std::atoi(argv[i + 1]);
    } else if (flag == "--source-fps") {
      source_fps = std::atof(argv[i + 1]);
    } else {
      std::fprintf(stderr, "usage: stevi-bench-io [--seconds S] [--rounds N] [--source-fps F]\n");
      return 2;
    }
  }
  if (!(seconds > 0) || rounds < 1 || !(source_fps >= 1 && source_fps <= 1000)) {
    std::fprintf(stderr,
                 "stevi-bench-io: --seconds must be > 0, --rounds >= 1, --source-fps in [1, "
                 "1000]\n");
    return 2;
  }
  Setup setup;
  if (!Prepare(setup)) {
    std::fprintf(stderr, "stevi-bench-io: cannot prepare the video and calibration\n");
    return 1;
  }
  const std::vector<std::string> variants = {"synthetic", "video", "mcap"};
  std::vector<double> sum(variants.size(), 0);
  for (int round = 0; round < rounds; ++round) {
    for (size_t v = 0; v < variants.size(); ++v) {
      std::string note;
      const double fps = Measure(Config(setup, variants[v], round), seconds, note);
      if (fps < 0) {
        std::fprintf(stderr, "stevi-bench-io: %s: %s\n", variants[v].c_str(), note.c_str());
        return 1;
      }
      std::printf("round %d  %-9s %6.1f fps  (%s)\n", round + 1, variants[v].c_str(), fps,
                  note.c_str());
      std::fflush(stdout);
      sum[v] += fps;
    }
  }
  const double synthetic = sum[0] / rounds, video = sum[1] / rounds, mcap = sum[2] / rounds;
  std::printf(
      "\nmean over %d rounds of %.0f s: synthetic %.1f fps, video %.1f fps, mcap %.1f fps\n",
      rounds, seconds, synthetic, video, mcap);
  const double video_ratio = video / synthetic, mcap_ratio = mcap / synthetic;
  std::printf("video / synthetic: %.3f (target >= 0.90: %s)\n", video_ratio,
              video_ratio >= 0.90 ? "PASS" : "FAIL");
  std::printf("mcap  / synthetic: %.3f (target >= 0.90: %s)\n", mcap_ratio,
              mcap_ratio >= 0.90 ? "PASS" : "FAIL");
  return 0;
}
