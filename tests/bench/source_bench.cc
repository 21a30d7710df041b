// stevi-bench-io: what reading frames through GStreamer and writing an MCAP flight log cost the
// server, as ratios of its frame rate and of its CPU time per frame, measured in the same run (the
// machines are noisy).
//
//   synthetic  the synthetic rig, 640x480, 60 frames rendered once and looped (a camera's cost)
//   video      the same 60 frames side by side (1280x480) in a Motion-JPEG AVI, read through
//              --source video (GStreamer: filesrc, decodebin, jpegdec, appsink), with the rig's
//              calibration (so the frames are rectified as a camera's are)
//   raw        the same frames uncompressed, YUY2 in Matroska, as a UVC camera's raw mode gives
//              them (filesrc, decodebin, appsink), with the calibration
//   mcap       the synthetic rig again, recording an MCAP flight log with 5 Hz images
//
// Each is run for --seconds (default 10) after a 2 s warm-up, in --rounds interleaved rounds
// (default 2), at two rates the sources offer:
//   camera     --camera-fps (default 60, a fast UVC stereo camera): does the server keep the
//              camera's rate? Targets: video and raw within 10 % of synthetic, mcap costing under
//              10 %. The CPU per frame shows what each costs at that rate.
//   flat out   1000 fps, so that the pipeline is the bottleneck: the sources' costs show as lost
//              frame rate. On 2 cores Motion-JPEG's decoding (a few ms of a core per 1280x480
//              frame) competes with the pipeline for the same cores; reported, not held.
// --source-fps F runs one rate only, F, with the targets.
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "core/common/allocator.h"
#include "core/common/flags.h"
#include "core/geometry/calibration_io.h"
#include "drivers/synthetic/synthetic_source.h"
#include "server/server.h"
#include "tests/bench/bench_flags.h"
#include "tests/testing/data.h"
#include "tests/testing/gst_testing.h"
#include "tests/testing/synthetic_calibration.h"

namespace {

using namespace stevi;
using Clock = std::chrono::steady_clock;

constexpr int kFrames = 60;

struct Setup {
  std::string dir;
  std::vector<cv::Mat> frames;  // side by side
  std::string calibration;
};

bool Prepare(Setup& s) {
  s.dir = testing::MakeTempDir("stevi-bench-io");
  drivers::SyntheticOptions options;
  options.fps = 10;
  Result<std::unique_ptr<drivers::SyntheticSource>> source = drivers::OpenSyntheticSource(options);
  if (!source.ok()) return false;
  for (int k = 0; k < kFrames; ++k) {
    Result<StereoFrame> frame = (*source)->Next();
    if (!frame.ok()) return false;
    cv::Mat whole;
    cv::hconcat(frame->left, frame->right, whole);
    s.frames.push_back(whole);
  }
  s.calibration = s.dir + "/calibration.yaml";
  return geometry::SaveCalibrationYaml(testing::SyntheticCalibration(options), s.calibration).ok();
}

// The video of `variant` at `fps`: the server plays a file at the file's own rate, so each rate
// has its files, written on first use.
std::string VideoFile(const Setup& s, const std::string& variant, double fps) {
  const int rate = static_cast<int>(std::lround(fps));
  const std::string path =
      s.dir + "/flight-" + std::to_string(rate) + (variant == "video" ? ".avi" : ".mkv");
  if (std::filesystem::exists(path)) return path;
  if (variant == "video") {
    testing::WriteMjpegAvi(path, s.frames, rate);
  } else {
    testing::WriteVideo(path, s.frames, rate,
                        "videoconvert ! video/x-raw,format=YUY2 ! matroskamux");
  }
  return path;
}

v1::ServerConfig Config(const Setup& s, const std::string& variant, double source_fps, int round) {
  v1::ServerConfig config;
  config.set_listen("127.0.0.1:0");
  config.set_data_dir(s.dir + "/data");
  v1::SourceConfig* source = config.mutable_source();
  source->set_fps(source_fps);
  if (variant == "video" || variant == "raw") {
    source->set_kind(v1::SOURCE_KIND_VIDEO);
    source->mutable_gst()->set_file(VideoFile(s, variant, source_fps));
    source->set_calibration(s.calibration);
    source->set_loop(true);
  } else {
    source->set_kind(v1::SOURCE_KIND_SYNTHETIC);
    source->mutable_synthetic()->set_loop_frames(kFrames);
  }
  if (variant == "mcap") {
    config.mutable_record_mcap()->set_file(s.dir + "/flight-" + std::to_string(source_fps) + "-" +
                                           std::to_string(round) + ".mcap");
    config.mutable_record_mcap()->set_image_hz(5);
  }
  return config;
}

struct Rate {
  double fps = -1;              // frames processed per second; < 0 on failure
  double cpu_ms_per_frame = 0;  // the process's CPU time (all threads) per frame processed
};

double CpuSeconds() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  const auto seconds = [](const timeval& t) {
    return static_cast<double>(t.tv_sec) + 1e-6 * static_cast<double>(t.tv_usec);
  };
  return seconds(usage.ru_utime) + seconds(usage.ru_stime);
}

// The server's rate over `seconds`, after a warm-up.
Rate Measure(const v1::ServerConfig& config, double seconds, std::string& note) {
  Result<std::unique_ptr<server::Server>> started = server::Server::Start(config);
  if (!started.ok()) {
    note = started.error().message;
    return {};
  }
  server::Server& server = **started;
  // Polls the engine's own counters: nothing outside it has an event to wait on.
  const auto processed = [&server] { return server.engine().Status().frames_processed; };
  const Clock::time_point warm = Clock::now() + std::chrono::seconds(2);
  while (Clock::now() < warm) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  const uint64_t first = processed();
  const double cpu_first = CpuSeconds();
  const Clock::time_point start = Clock::now();
  std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  const uint64_t last = processed();
  const double cpu = CpuSeconds() - cpu_first;
  const double elapsed = std::chrono::duration<double>(Clock::now() - start).count();
  note = server.engine().Status().source;
  if (server::McapRecording* mcap = server.mcap_recording()) {
    const server::McapRecordingStatus st = mcap->Status();
    note += "; mcap " + std::to_string(st.counts.track_frames) + " frames, " +
            std::to_string(st.counts.images) + " images, " + std::to_string(st.frames_dropped) +
            " dropped";
  }
  server.Shutdown();
  const auto frames = static_cast<double>(last - first);
  return {frames / elapsed, frames > 0 ? 1000 * cpu / frames : 0};
}

// Runs every variant at `source_fps` for `rounds` interleaved rounds and prints the means and,
// when `held`, the verdicts. False on a failure to start.
bool RunAt(const Setup& setup, const std::vector<std::string>& variants, double source_fps,
           double seconds, int rounds, bool held) {
  std::vector<double> fps(variants.size(), 0), cpu(variants.size(), 0);
  for (int round = 0; round < rounds; ++round) {
    for (size_t v = 0; v < variants.size(); ++v) {
      std::string note;
      const Rate rate = Measure(Config(setup, variants[v], source_fps, round), seconds, note);
      if (rate.fps < 0) {
        std::fprintf(stderr, "stevi-bench-io: %s: %s\n", variants[v].c_str(), note.c_str());
        return false;
      }
      std::printf("%4.0f fps offered, round %d  %-9s %6.1f fps  %5.2f ms CPU/frame  (%s)\n",
                  source_fps, round + 1, variants[v].c_str(), rate.fps, rate.cpu_ms_per_frame,
                  note.c_str());
      std::fflush(stdout);
      fps[v] += rate.fps / rounds;
      cpu[v] += rate.cpu_ms_per_frame / rounds;
    }
  }
  std::printf("\nsources offering %.0f fps, mean over %d rounds of %.0f s:\n", source_fps, rounds,
              seconds);
  for (size_t v = 0; v < variants.size(); ++v) {
    std::printf("  %-9s %6.1f fps  %5.2f ms CPU/frame", variants[v].c_str(), fps[v], cpu[v]);
    if (v > 0 && variants[0] == "synthetic") {
      const double ratio = fps[v] / fps[0];
      std::printf("  rate / synthetic %.3f", ratio);
      if (held) std::printf(" (target >= 0.90: %s)", ratio >= 0.90 ? "PASS" : "FAIL");
      std::printf("  CPU/frame %+.2f ms", cpu[v] - cpu[0]);
    }
    std::printf("\n");
  }
  std::printf("\n");
  return true;
}

constexpr char kUsage[] =
    "usage: stevi-bench-io [--seconds S] [--rounds N] [--camera-fps F] [--source-fps F] "
    "[--only synthetic|video|raw|mcap]\n";

constexpr flags::RealRange kSecondsRange{
    .lo = 0, .hi = bench::kNoUpperBound, .unit = "seconds", .lo_open = true};
constexpr flags::WholeRange kRoundsRange{.lo = 1, .what = "a whole number of rounds"};
constexpr flags::RealRange kFpsRange{.lo = 1, .hi = 1000, .unit = "frames per second"};

const std::vector<std::string> kVariants = {"synthetic", "video", "raw", "mcap"};

struct Options {
  double seconds = 10;
  int rounds = 2;
  double camera_fps = 60;
  double source_fps = 0;                          // one rate only, when given
  std::vector<std::string> variants = kVariants;  // --only: one alone (for a profiler)
};

// The flags; exits 0 after --help, 2 with the problem and the usage on stderr.
Options ParseOptions(int argc, char** argv) {
  Options o;
  bool help = false;
  flags::FlagSet set("");
  set.Value("--only",
            [&o](const std::string& variant) {
              if (std::find(kVariants.begin(), kVariants.end(), variant) == kVariants.end()) {
                return flags::Expected("", "--only", "synthetic, video, raw or mcap", variant);
              }
              o.variants = {variant};
              return std::string();
            })
      .Stop("--help", &help);
  bench::Real(set, "--seconds", kSecondsRange, &o.seconds);
  bench::WholeInt(set, "--rounds", kRoundsRange, &o.rounds);
  bench::Real(set, "--camera-fps", kFpsRange, &o.camera_fps);
  bench::Real(set, "--source-fps", kFpsRange, &o.source_fps);
  const std::string problem = bench::ParseArgs(set, argc, argv);
  if (!problem.empty()) {
    std::fprintf(stderr, "stevi-bench-io: %s\n%s", problem.c_str(), kUsage);
    std::exit(2);
  }
  if (help) {
    std::fputs(kUsage, stdout);
    std::exit(0);
  }
  return o;
}

}  // namespace

int main(int argc, char** argv) {
  stevi::KeepFrameMemory();  // first, as stevi-server does: before any thread starts
  const Options o = ParseOptions(argc, argv);
  Setup setup;
  if (!Prepare(setup)) {
    std::fprintf(stderr, "stevi-bench-io: cannot prepare the video and calibration\n");
    return 1;
  }
  if (o.source_fps != 0) {
    return RunAt(setup, o.variants, o.source_fps, o.seconds, o.rounds, true) ? 0 : 1;
  }
  const bool ok = RunAt(setup, o.variants, o.camera_fps, o.seconds, o.rounds, /*held=*/true) &&
                  RunAt(setup, o.variants, 1000, o.seconds, o.rounds, /*held=*/false);
  return ok ? 0 : 1;
}
