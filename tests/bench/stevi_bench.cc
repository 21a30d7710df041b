// stevi-bench: the figures of issue 9 in one run, as a readable table and as JSON.
//
//   1. Stages: per-stage time (mean, p50, p99) of Pipeline::Process on the synthetic scene, for
//      every algorithm (canonical, SteViE, SteViS with threshold and with graph segmentation) and
//      matcher (block matching, semi-global 3-way), at 640x480 and 1280x1024, 64 disparities.
//   2. Scaling: the same against resolution, and against the disparity count (32, 64, 128).
//   3. Naive baseline: the thesis pipeline done naively on one thread at full resolution
//      (naive_baseline.h) on the same 640x480 frame, stage by stage, next to ours.
//   4. Tracking: Tracker::Update with 100 moving targets.
//   5. Throughput: an in-process stevi server (127.0.0.1:0) whose synthetic source runs as fast as
//      it is allowed (source.fps = 1000, the largest value the config accepts); frames_processed
//      per second from GetStatus, per algorithm. The source plays a loop of frames rendered once
//      (source.synthetic.loop_frames), so that capture costs about what a camera's does; for
//      reference, the same with the renderer drawing every frame (it costs about as much CPU as
//      the pipeline).
//   6. Clients: the same server at a camera's rate (--latency-fps) with 1, 4, 16 and 32 gRPC
//      StreamTracks clients (client::Client) in a child process: capture-to-receipt latency
//      (TrackFrame.capture_unix_time_ns against the wall clock at receipt), p50 and p99, the frame
//      rate sustained and the server's CPU per frame.
//   7. Targets: PASS or MISS against the figures measured above (N/A when the measurement failed).
//      The exit status is 3 unless every target passes, so a script can gate on it.
//   8. Preview cost: one server as in 5 (SteViE + BM, 640x480), its frame rate measured in
//      windows without and with two StreamPreview clients (annotated and disparity JPEGs at 5 Hz,
//      640 wide, quality 80), interleaved in one run; the ratio is judged in 7, and the hub
//      thread's CPU is printed beside it.
//
// Usage: stevi-bench [--seconds N] [--json FILE|-] [--quick] [--latency-fps F]
//                    [--latency-algorithm NAME] [--preview-only]
// With --json - the JSON goes to stdout and the table to stderr.
//
// Nothing here is a fixed figure: every number printed is measured in this run.
#include <sys/resource.h>
#include <sys/utsname.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "client/lib/client.h"
#include "core/common/allocator.h"
#include "core/common/flags.h"
#include "core/extraction/saliency.h"
#include "core/extraction/segmentation.h"
#include "core/geometry/calibration_io.h"
#include "core/geometry/stereo_rig.h"
#include "core/pipeline/pipeline.h"
#include "core/stereo/matcher.h"
#include "core/tracking/tracker.h"
#include "drivers/synthetic/synthetic_source.h"
#include "server/server.h"
#include "tests/bench/bench_flags.h"
#include "tests/bench/naive_baseline.h"

#ifndef STEVI_BUILD_TYPE
#define STEVI_BUILD_TYPE "unknown"
#endif
#ifndef STEVI_CXX_FLAGS
#define STEVI_CXX_FLAGS ""
#endif

namespace {

using namespace stevi;
using Clock = std::chrono::steady_clock;

// The largest source.fps the server's config accepts (server/app_config.cc): "as fast as
// possible" for the synthetic source, whose render then paces the capture.
constexpr double kMaxSourceFps = 1000.0;
constexpr int kWarmupFrames = 3;  // offline runs: frames processed before measuring
constexpr int kMinFrames = 5;     // offline runs: at least this many measured frames
constexpr int kMaxFrames = 100000;
// The synthetic source's loop (source.synthetic.loop_frames): rendered once, then played again at
// no cost per frame, as a camera delivers frames. The targets are judged on it.
constexpr int kLoopFrames = 60;

double MsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

int64_t UnixNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// CPU time (user + system) of this process, seconds.
double ProcessCpuSeconds() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  const auto seconds = [](const timeval& tv) {
    return static_cast<double>(tv.tv_sec) + static_cast<double>(tv.tv_usec) * 1e-6;
  };
  return seconds(usage.ru_utime) + seconds(usage.ru_stime);
}

std::string Format(const char* format, double value) {
  char buf[64];
  std::snprintf(buf, sizeof buf, format, value);
  return buf;
}

// "-" for a value that was not measured (NaN).
std::string Ms(double value, const char* format = "%.2f") {
  return std::isfinite(value) ? Format(format, value) : std::string("-");
}

const double kNaN = std::nan("");

// ---------------------------------------------------------------------------------------------
// A minimal JSON value (objects keep their insertion order).
// ---------------------------------------------------------------------------------------------

class Json {
 public:
  enum class Kind { kNull, kBool, kNumber, kString, kArray, kObject };
  Json() = default;
  Json(bool b) : kind_(Kind::kBool), bool_(b) {}                               // NOLINT
  Json(double d) : kind_(Kind::kNumber), number_(d) {}                         // NOLINT
  Json(int i) : kind_(Kind::kNumber), number_(i) {}                            // NOLINT
  Json(int64_t i) : kind_(Kind::kNumber), number_(static_cast<double>(i)) {}   // NOLINT
  Json(uint64_t i) : kind_(Kind::kNumber), number_(static_cast<double>(i)) {}  // NOLINT
  Json(const char* s) : kind_(Kind::kString), string_(s) {}                    // NOLINT
  Json(std::string s) : kind_(Kind::kString), string_(std::move(s)) {}         // NOLINT
  static Json Object() {
    Json j;
    j.kind_ = Kind::kObject;
    return j;
  }
  static Json Array() {
    Json j;
    j.kind_ = Kind::kArray;
    return j;
  }

  Json& Set(const std::string& key, Json value) {
    members_.emplace_back(key, std::move(value));
    return *this;
  }
  Json& Push(Json value) {
    items_.push_back(std::move(value));
    return *this;
  }

  void Dump(std::string& out, int indent = 0) const {
    const std::string pad(static_cast<size_t>(indent + 2), ' ');
    const std::string end_pad(static_cast<size_t>(indent), ' ');
    switch (kind_) {
      case Kind::kNull: out += "null"; break;
      case Kind::kBool: out += bool_ ? "true" : "false"; break;
      case Kind::kNumber:
        if (!std::isfinite(number_)) {
          out += "null";
        } else {
          char buf[40];
          std::snprintf(buf, sizeof buf, "%.6g", number_);
          out += buf;
        }
        break;
      case Kind::kString: Quote(string_, out); break;
      case Kind::kArray:
        if (items_.empty()) {
          out += "[]";
          break;
        }
        out += "[\n";
        for (size_t i = 0; i < items_.size(); ++i) {
          out += pad;
          items_[i].Dump(out, indent + 2);
          out += i + 1 < items_.size() ? ",\n" : "\n";
        }
        out += end_pad + "]";
        break;
      case Kind::kObject:
        if (members_.empty()) {
          out += "{}";
          break;
        }
        out += "{\n";
        for (size_t i = 0; i < members_.size(); ++i) {
          out += pad;
          Quote(members_[i].first, out);
          out += ": ";
          members_[i].second.Dump(out, indent + 2);
          out += i + 1 < members_.size() ? ",\n" : "\n";
        }
        out += end_pad + "}";
        break;
    }
  }

 private:
  static void Quote(const std::string& s, std::string& out) {
    out += '"';
    for (const char c : s) {
      switch (c) {
        case '"': out += "\\\""; break;
        case '\\': out += "\\\\"; break;
        case '\n': out += "\\n"; break;
        case '\t': out += "\\t"; break;
        default:
          if (static_cast<unsigned char>(c) < 0x20) {
            char buf[8];
            std::snprintf(buf, sizeof buf, "\\u%04x", static_cast<unsigned>(c));
            out += buf;
          } else {
            out += c;
          }
      }
    }
    out += '"';
  }

  Kind kind_ = Kind::kNull;
  bool bool_ = false;
  double number_ = 0;
  std::string string_;
  std::vector<Json> items_;
  std::vector<std::pair<std::string, Json>> members_;
};

// ---------------------------------------------------------------------------------------------
// Flags
// ---------------------------------------------------------------------------------------------

struct Flags {
  double seconds = 5.0;
  bool seconds_given = false;
  std::string json;  // "" none, "-" stdout
  bool quick = false;
  double latency_fps = 30.0;
  std::string latency_algorithm = "stevie";
  // The source's rate in the throughput runs: a fast camera, above every target. (Not "as fast as
  // possible": a capture loop spinning at 1000 Hz takes CPU from the pipeline that no camera
  // would.)
  double source_fps = 120.0;
  bool preview_only = false;  // only table 8 (and its target)
};

constexpr const char* kUsage =
    "usage: stevi-bench [--seconds N] [--json FILE|-] [--quick] [--latency-fps F]\n"
    "                   [--latency-algorithm canonical|stevie|stevis|stevis-graph] [--source-fps "
    "F]\n"
    "  --seconds N           time per measurement (default 5; --quick: 1)\n"
    "  --json FILE           also write the figures as JSON to FILE ('-': stdout, table to "
    "stderr)\n"
    "  --quick               short run: 1 s per measurement, 1 and 16 clients, block matching "
    "only\n"
    "                        through the server\n"
    "  --latency-fps F       source rate of the latency and client runs (default 30, 0 < F <= "
    "1000)\n"
    "  --latency-algorithm A algorithm of the latency and client runs (default stevie)\n"
    "  --source-fps F        source rate of the throughput runs (default 120, 0 < F <= 1000)\n"
    "  --preview-only        only the preview cost (table 8) and its target\n";

// The ranges of the numeric flags.
constexpr flags::RealRange kSecondsRange{
    .lo = 0, .hi = bench::kNoUpperBound, .unit = "seconds", .lo_open = true};
constexpr flags::RealRange kFpsRange{
    .lo = 0, .hi = kMaxSourceFps, .unit = "frames per second", .lo_open = true};
// --client-worker's CLIENTS (MeasureClients starts at most 32).
constexpr flags::WholeRange kWorkerClientsRange{
    .lo = 1, .hi = 1000, .what = "a whole number of clients"};

// The flags; exits 0 after --help, 2 with the problem and the usage on stderr.
Flags ParseFlags(int argc, char** argv) {
  Flags parsed;
  bool help = false;
  flags::FlagSet set("");
  set.Switch("--quick", &parsed.quick)
      .Switch("--preview-only", &parsed.preview_only)
      .Text("--json", &parsed.json)
      .Value("--latency-algorithm",
             [&parsed](const std::string& name) {
               if (name != "canonical" && name != "stevie" && name != "stevis" &&
                   name != "stevis-graph") {
                 return flags::Expected("", "--latency-algorithm",
                                        "canonical, stevie, stevis or stevis-graph", name);
               }
               parsed.latency_algorithm = name;
               return std::string();
             })
      .Stop("--help", &help)
      .Stop("-h", &help);
  bench::Real(set, "--seconds", kSecondsRange, [&parsed](double seconds) {
    parsed.seconds = seconds;
    parsed.seconds_given = true;
  });
  bench::Real(set, "--latency-fps", kFpsRange, &parsed.latency_fps);
  bench::Real(set, "--source-fps", kFpsRange, &parsed.source_fps);
  const std::string problem = bench::ParseArgs(set, argc, argv);
  if (!problem.empty()) {
    std::fprintf(stderr, "%s\n%s", problem.c_str(), kUsage);
    std::exit(2);
  }
  if (help) {
    std::fputs(kUsage, stdout);
    std::exit(0);
  }
  if (parsed.quick && !parsed.seconds_given) parsed.seconds = 1.0;
  return parsed;
}

// ---------------------------------------------------------------------------------------------
// Variants
// ---------------------------------------------------------------------------------------------

struct Variant {
  std::string name;  // "stixels", "canonical", "stevie", "stevis", "stevis-graph"
  pipeline::Algorithm algorithm;
  detection::SteViSOptions::Segmentation segmentation;
};

const std::vector<Variant>& Variants() {
  using Seg = detection::SteViSOptions::Segmentation;
  static const std::vector<Variant> variants = {
      {"stixels", pipeline::Algorithm::kStixels, Seg::kThreshold},
      {"canonical", pipeline::Algorithm::kCanonical, Seg::kThreshold},
      {"stevie", pipeline::Algorithm::kSteViE, Seg::kThreshold},
      {"stevis", pipeline::Algorithm::kSteViS, Seg::kThreshold},
      {"stevis-graph", pipeline::Algorithm::kSteViS, Seg::kGraph},
  };
  return variants;
}

const Variant& VariantNamed(const std::string& name) {
  for (const Variant& v : Variants()) {
    if (v.name == name) return v;
  }
  return Variants().front();
}

const char* MatcherName(stereo::MatcherKind kind) {
  switch (kind) {
    case stereo::MatcherKind::kBlockMatching: return "bm";
    case stereo::MatcherKind::kSemiGlobal: return "sgbm";
    case stereo::MatcherKind::kDense: return "dense";
  }
  return "?";
}

// The stixel world always runs with its own matcher, the dense one (it needs disparities on real
// surfaces); the thesis detectors run with the matcher asked for.
stereo::MatcherKind MatcherFor(const Variant& variant, stereo::MatcherKind kind) {
  return variant.algorithm == pipeline::Algorithm::kStixels ? stereo::MatcherKind::kDense : kind;
}

// max_width_px: PipelineConfig::max_width_px (0: each size at its own resolution).
pipeline::PipelineConfig ConfigFor(const Variant& variant, stereo::MatcherKind kind,
                                   int disparities, int max_width_px = 0) {
  pipeline::PipelineConfig config;
  config.max_width_px = max_width_px;
  config.algorithm = variant.algorithm;
  config.stevis.segmentation = variant.segmentation;
  config.matcher.kind = MatcherFor(variant, kind);
  config.matcher.block_matching.num_disparities = disparities;
  config.matcher.semi_global.num_disparities = disparities;
  return config;
}

v1::PipelineConfig ProtoConfigFor(const Variant& variant, stereo::MatcherKind kind) {
  v1::PipelineConfig config;
  switch (variant.algorithm) {
    case pipeline::Algorithm::kCanonical: config.set_algorithm(v1::ALGORITHM_CANONICAL); break;
    case pipeline::Algorithm::kSteViE: config.set_algorithm(v1::ALGORITHM_STEVIE); break;
    case pipeline::Algorithm::kSteViS: config.set_algorithm(v1::ALGORITHM_STEVIS); break;
    case pipeline::Algorithm::kStixels: config.set_algorithm(v1::ALGORITHM_STIXELS); break;
  }
  config.mutable_stevis()->set_segmentation(variant.segmentation ==
                                                    detection::SteViSOptions::Segmentation::kGraph
                                                ? v1::SEGMENTATION_GRAPH
                                                : v1::SEGMENTATION_THRESHOLD);
  switch (MatcherFor(variant, kind)) {
    case stereo::MatcherKind::kBlockMatching:
      config.mutable_matcher()->set_kind(v1::MATCHER_KIND_BLOCK_MATCHING);
      break;
    case stereo::MatcherKind::kSemiGlobal:
      config.mutable_matcher()->set_kind(v1::MATCHER_KIND_SEMI_GLOBAL);
      break;
    case stereo::MatcherKind::kDense:
      config.mutable_matcher()->set_kind(v1::MATCHER_KIND_DENSE);
      break;
  }
  return config;
}

// ---------------------------------------------------------------------------------------------
// 1-2. Offline per-stage runs
// ---------------------------------------------------------------------------------------------

struct Stats {
  double mean = kNaN, p50 = kNaN, p99 = kNaN;
  int n = 0;
};

Stats StatsOf(const std::vector<double>& values) {
  Stats s;
  if (values.empty()) return s;
  s.mean = bench::Mean(values);
  s.p50 = bench::Percentile(values, 50);
  s.p99 = bench::Percentile(values, 99);
  s.n = static_cast<int>(values.size());
  return s;
}

Json StatsJson(const Stats& s) {
  return Json::Object()
      .Set("mean_ms", s.mean)
      .Set("p50_ms", s.p50)
      .Set("p99_ms", s.p99)
      .Set("n", s.n);
}

struct OfflineRun {
  std::string variant;
  stereo::MatcherKind matcher = stereo::MatcherKind::kBlockMatching;
  cv::Size size;
  int disparities = 64;
  int max_width_px = 0;  // PipelineConfig::max_width_px: 0 = unbinned
  int frames = 0;
  Stats render;  // the synthetic renderer, outside the pipeline
  double detections_per_frame = 0;
  double tracks_per_frame = 0;
  std::vector<std::pair<std::string, Stats>> stages;  // pipeline order, "total" last
  std::string error;

  Stats Stage(const std::string& name) const {
    for (const auto& [stage, stats] : stages) {
      if (stage == name) return stats;
    }
    return {};
  }
};

// The size column of a run: "1280x1024", or "1280x1024/2" when the pipeline bins it by 2.
std::string RunSizeName(cv::Size size, int max_width_px) {
  const int factor =
      geometry::BinningFactor(size.width, max_width_px, geometry::RangeOptions{}.min_disparity_px);
  return bench::SizeName(size) + (factor > 1 ? "/" + std::to_string(factor) : "");
}

OfflineRun MeasureOffline(const Variant& variant, stereo::MatcherKind kind, cv::Size size,
                          int disparities, double seconds, int max_width_px = 0) {
  OfflineRun run;
  run.variant = variant.name;
  run.matcher = MatcherFor(variant, kind);
  run.size = size;
  run.disparities = disparities;
  run.max_width_px = max_width_px;
  std::fprintf(stderr, "  stages: %s + %s, %s, %d disparities\n", variant.name.c_str(),
               MatcherName(kind), RunSizeName(size, max_width_px).c_str(), disparities);

  const drivers::SyntheticRenderer renderer(bench::SyntheticAt(size));
  const pipeline::PipelineConfig config = ConfigFor(variant, kind, disparities, max_width_px);
  const std::vector<std::string> problems = config.Validate();
  if (!problems.empty()) {
    run.error = "invalid config: " + problems.front();
    return run;
  }
  const pipeline::Snapshot snapshot{std::make_shared<const pipeline::PipelineConfig>(config),
                                    std::make_shared<const geometry::StereoRig>(renderer.Rig())};
  pipeline::Pipeline pipe;
  int64_t index = 0;
  for (int i = 0; i < kWarmupFrames; ++i) {
    Result<pipeline::FrameResult> warm = pipe.Process(renderer.Render(index++), snapshot);
    if (!warm.ok()) {
      run.error = warm.error().message;
      return run;
    }
  }
  std::vector<std::string> order;
  std::map<std::string, std::vector<double>> per_stage;
  std::vector<double> render_ms;
  double processed_ms = 0;
  size_t detections = 0, tracks = 0;
  while ((processed_ms < seconds * 1000.0 || run.frames < kMinFrames) && run.frames < kMaxFrames) {
    const Clock::time_point render_start = Clock::now();
    const StereoFrame frame = renderer.Render(index++);
    render_ms.push_back(MsSince(render_start));
    Result<pipeline::FrameResult> result = pipe.Process(frame, snapshot);
    if (!result.ok()) {
      run.error = result.error().message;
      break;
    }
    for (const pipeline::StageTiming& t : result->timings) {
      auto [it, inserted] = per_stage.try_emplace(t.stage);
      if (inserted) order.push_back(t.stage);
      it->second.push_back(t.ms);
      if (t.stage == "total") processed_ms += t.ms;
    }
    detections += result->detections.size();
    tracks += result->tracks.size();
    ++run.frames;
  }
  run.render = StatsOf(render_ms);
  for (const std::string& stage : order) run.stages.emplace_back(stage, StatsOf(per_stage[stage]));
  if (run.frames > 0) {
    run.detections_per_frame = static_cast<double>(detections) / run.frames;
    run.tracks_per_frame = static_cast<double>(tracks) / run.frames;
  }
  return run;
}

Json OfflineJson(const OfflineRun& run) {
  Json stages = Json::Object();
  for (const auto& [stage, stats] : run.stages) stages.Set(stage, StatsJson(stats));
  Json j = Json::Object();
  j.Set("algorithm", run.variant)
      .Set("matcher", MatcherName(run.matcher))
      .Set("width", run.size.width)
      .Set("height", run.size.height)
      .Set("disparities", run.disparities)
      .Set("max_width_px", run.max_width_px)
      .Set("binning", geometry::BinningFactor(run.size.width, run.max_width_px,
                                              geometry::RangeOptions{}.min_disparity_px))
      .Set("frames", run.frames)
      .Set("detections_per_frame", run.detections_per_frame)
      .Set("tracks_per_frame", run.tracks_per_frame)
      .Set("render", StatsJson(run.render))
      .Set("stages", std::move(stages));
  if (!run.error.empty()) j.Set("error", run.error);
  return j;
}

// ---------------------------------------------------------------------------------------------
// 3. Naive baseline against ours, on one 640x480 frame
// ---------------------------------------------------------------------------------------------

// Runs `fn` until `seconds` have passed and at least `min_reps` times; the time of each call.
std::vector<double> TimeRepeated(const std::function<void()>& fn, double seconds,
                                 int min_reps = 3) {
  fn();  // warm-up (allocations, lazy initialisation)
  std::vector<double> ms;
  const Clock::time_point start = Clock::now();
  while (static_cast<int>(ms.size()) < min_reps || SecondsSince(start) < seconds) {
    const Clock::time_point t = Clock::now();
    fn();
    ms.push_back(MsSince(t));
    if (ms.size() >= static_cast<size_t>(kMaxFrames)) break;
  }
  return ms;
}

struct BaselineRow {
  std::string stage;  // "rectify", "disparity", "saliency", "graph segmentation", "total"
  std::string naive;  // what the naive stage is
  std::string ours;   // what our counterpart is
  Stats naive_ms;     // one thread
  Stats ours_ms;      // OpenCV's default thread count (as the server runs)
  Stats ours_1t_ms;   // one thread
  bool available = true;
  std::string note;
};

struct Baseline {
  int opencv_threads = 0;
  std::vector<BaselineRow> rows;
};

Baseline MeasureBaseline(double seconds, const std::vector<OfflineRun>& offline) {
  std::fprintf(stderr, "  naive baseline (one thread) and our stages on one 640x480 frame\n");
  Baseline b;
  b.opencv_threads = cv::getNumThreads();
  const drivers::SyntheticRenderer renderer(bench::SyntheticAt({640, 480}));
  const StereoFrame frame = renderer.Render(50);
  const geometry::StereoRig ideal = renderer.Rig();
  Result<geometry::StereoRig> raw = bench::RawRigLike(ideal);
  const geometry::StereoRig& remap_rig = raw.ok() ? *raw : ideal;
  bench::NaiveThesisPipeline naive(remap_rig);

  const auto both = [&](BaselineRow& row, const std::function<void()>& naive_fn,
                        const std::function<void()>& ours_fn) {
    {
      const bench::SingleThreadScope one_thread;
      if (naive_fn) row.naive_ms = StatsOf(TimeRepeated(naive_fn, seconds));
      row.ours_1t_ms = StatsOf(TimeRepeated(ours_fn, seconds));
    }
    row.ours_ms = StatsOf(TimeRepeated(ours_fn, seconds));
  };

  cv::Mat rect_left, rect_right, our_left, our_right;
  BaselineRow rectify{"rectify",
                      "cv::remap, float maps, bilinear, both images",
                      "StereoRig::Rectify of a raw rig (fixed-point maps)",
                      {},
                      {},
                      {},
                      true,
                      ""};
  if (!raw.ok()) rectify.note = "raw rig refused: " + raw.error().message;
  both(
      rectify, [&] { naive.Rectify(frame.left, frame.right, rect_left, rect_right); },
      [&] { (void)remap_rig.Rectify(frame.left, frame.right, our_left, our_right); });
  b.rows.push_back(rectify);

  stereo::MatcherOptions sgbm_options;
  sgbm_options.kind = stereo::MatcherKind::kSemiGlobal;
  std::unique_ptr<stereo::DisparityMatcher> sgbm = stereo::MakeMatcher(sgbm_options);
  BaselineRow disparity{"disparity",
                        "StereoSGBM MODE_SGBM (5 paths), 64 disp, block 5",
                        "SGBM 3-way, 64 disp, block 5, padded, texture gate",
                        {},
                        {},
                        {},
                        true,
                        ""};
  both(
      disparity, [&] { (void)naive.Disparity(frame.left, frame.right); },
      [&] { (void)sgbm->Compute(frame.left, frame.right); });
  b.rows.push_back(disparity);

  std::unique_ptr<stereo::DisparityMatcher> bm = stereo::MakeMatcher({});
  BaselineRow disparity_bm{"disparity (ours BM)",
                           "StereoSGBM MODE_SGBM (5 paths), 64 disp",
                           "block matching, block 15, 64 disp (the default matcher)",
                           {},
                           {},
                           {},
                           true,
                           ""};
  both(disparity_bm, nullptr, [&] { (void)bm->Compute(frame.left, frame.right); });
  disparity_bm.naive_ms = disparity.naive_ms;  // the same naive stage, not measured twice
  b.rows.push_back(disparity_bm);

  const cv::Mat1b left = frame.left;
  const extraction::SaliencyOptions saliency_options;
  BaselineRow saliency{"saliency",
                       "StaticSaliencyFineGrained, full resolution",
                       "VOCUS intensity (ComputeSaliency), summed at level 2",
                       {},
                       {},
                       {},
                       true,
                       ""};
  both(
      saliency, [&] { (void)naive.Saliency(frame.left); },
      [&] { (void)extraction::ComputeSaliency(left, saliency_options); });
  b.rows.push_back(saliency);

  const detection::SteViSOptions stevis;
  BaselineRow graph{"graph segmentation",
                    "GraphSegmentation, full resolution",
                    "GraphSegmentation on the image shrunk by 2^graph_level (level 1)",
                    {},
                    {},
                    {},
                    true,
                    ""};
  both(
      graph, [&] { (void)naive.Segment(frame.left); },
      [&] {
        cv::Mat small;
        const double scale = 1.0 / (1 << stevis.graph_level);
        cv::resize(left, small, cv::Size(), scale, scale, cv::INTER_AREA);
        (void)extraction::SegmentGraph(small, stevis.graph);
      });
  b.rows.push_back(graph);

  // Totals: the naive front end (the sum of its stages) against our whole pipeline per frame on the
  // synthetic sequence (table 1, rectified input) plus our raw-rig rectification measured above.
  double naive_sum = 0;
  for (const BaselineRow& row : b.rows) {
    if (row.stage == "disparity (ours BM)") continue;
    if (std::isfinite(row.naive_ms.mean)) naive_sum += row.naive_ms.mean;
  }
  const double our_rectify = b.rows.front().ours_ms.mean;
  const auto ours_total = [&](const std::string& variant, stereo::MatcherKind kind,
                              const std::string& what) {
    BaselineRow row{
        "total", "sum of the naive stages above (no blobs, no tracking)", what, {}, {}, {}, true,
        ""};
    row.naive_ms.mean = naive_sum;
    for (const OfflineRun& run : offline) {
      if (run.variant == variant && run.matcher == kind && run.size == cv::Size(640, 480) &&
          run.disparities == 64 && run.error.empty()) {
        row.ours_ms.mean = run.Stage("total").mean + our_rectify;
        row.note = "pipeline total of table 1 + raw-rig rectify";
        return row;
      }
    }
    row.available = false;
    row.note = "not measured";
    return row;
  };
  b.rows.push_back(ours_total("stevis-graph", stereo::MatcherKind::kSemiGlobal,
                              "whole pipeline, SteViS graph + SGBM"));
  b.rows.push_back(ours_total("stevis", stereo::MatcherKind::kBlockMatching,
                              "whole pipeline, SteViS threshold + BM (defaults)"));
  b.rows.push_back(
      ours_total("stevie", stereo::MatcherKind::kBlockMatching, "whole pipeline, SteViE + BM"));
  return b;
}

Json BaselineJson(const Baseline& b) {
  Json rows = Json::Array();
  for (const BaselineRow& row : b.rows) {
    Json j = Json::Object();
    j.Set("stage", row.stage)
        .Set("naive", row.naive)
        .Set("ours", row.ours)
        .Set("available", row.available)
        .Set("naive_1thread", StatsJson(row.naive_ms))
        .Set("ours_default_threads", StatsJson(row.ours_ms))
        .Set("ours_1thread", StatsJson(row.ours_1t_ms))
        .Set("ratio_ours_to_naive", row.ours_ms.mean / row.naive_ms.mean)
        .Set("ratio_ours_1thread_to_naive", row.ours_1t_ms.mean / row.naive_ms.mean);
    if (!row.note.empty()) j.Set("note", row.note);
    rows.Push(std::move(j));
  }
  return Json::Object()
      .Set("frame", "synthetic demo scene, frame 50, 640x480")
      .Set("opencv_threads_default", b.opencv_threads)
      .Set("rows", std::move(rows));
}

// ---------------------------------------------------------------------------------------------
// 4. Tracking
// ---------------------------------------------------------------------------------------------

struct TrackerRun {
  int targets = 0;
  int updates = 0;
  Stats update_ms;
  double tracks = 0;     // live tracks after the last update
  double confirmed = 0;  // of which confirmed
};

TrackerRun MeasureTracker(int targets, double seconds) {
  std::fprintf(stderr, "  tracker: %d moving targets\n", targets);
  const tracking::CameraModel camera{700.0, 320.0, 240.0, 0.6, 640, 480};
  bench::MovingTargets field(targets, camera);
  constexpr double kDt = 0.1;
  constexpr int64_t kDtNs = 100'000'000;
  tracking::Tracker tracker;
  int64_t frame = 0;
  for (; frame < 10; ++frame) tracker.Update(field.Detections(frame, kDt), frame * kDtNs, camera);
  std::vector<double> ms;
  std::vector<tracking::Track> out;
  double timed_s = 0;
  while ((timed_s < seconds || ms.size() < 50) && ms.size() < static_cast<size_t>(kMaxFrames)) {
    const std::vector<detection::Detection> detections = field.Detections(frame, kDt);
    const Clock::time_point t = Clock::now();
    out = tracker.Update(detections, frame * kDtNs, camera);
    const double elapsed = MsSince(t);
    ms.push_back(elapsed);
    timed_s += elapsed / 1000.0;
    ++frame;
  }
  TrackerRun run;
  run.targets = targets;
  run.updates = static_cast<int>(ms.size());
  run.update_ms = StatsOf(ms);
  run.tracks = static_cast<double>(out.size());
  run.confirmed =
      static_cast<double>(std::count_if(out.begin(), out.end(), [](const tracking::Track& t) {
        return t.state == tracking::TrackState::kConfirmed;
      }));
  return run;
}

// ---------------------------------------------------------------------------------------------
// 5-6. Through the server
// ---------------------------------------------------------------------------------------------

struct TempDir {
  TempDir() {
    char pattern[] = "/tmp/stevi-bench-XXXXXX";
    if (char* made = ::mkdtemp(pattern)) path = made;
  }
  ~TempDir() {
    if (!path.empty()) {
      std::error_code ignored;
      std::filesystem::remove_all(path, ignored);
    }
  }
  std::string path;
};

struct ServerSnapshot {
  v1::GetStatusResponse status;
  double cpu_s = 0;
  Clock::time_point at;
};

std::optional<ServerSnapshot> Snap(client::Client& control) {
  ServerSnapshot s;
  if (!control.GetStatus(&s.status).ok()) return std::nullopt;
  s.cpu_s = ProcessCpuSeconds();
  s.at = Clock::now();
  return s;
}

struct RunningServer {
  TempDir dir;
  std::unique_ptr<server::Server> server;
  std::unique_ptr<client::Client> control;
  std::string address;
  std::string error;
};

// The synthetic source at `fps`: looped (the default: kLoopFrames rendered once) or rendering every
// frame on the capture thread (about a core at 30 fps on the reference machine).
v1::SourceConfig SyntheticSourceAt(double fps, bool looped = true) {
  v1::SourceConfig source;
  source.set_kind(v1::SOURCE_KIND_SYNTHETIC);
  source.set_fps(fps);
  if (looped) source.mutable_synthetic()->set_loop_frames(kLoopFrames);
  return source;
}

// The server's threads: pipeline_workers and opencv_threads (0: unset, the defaults).
struct Threads {
  uint32_t workers = 0;
  uint32_t opencv = 0;
};

// Starts a server on 127.0.0.1:0 with `source` and waits for its first frames.
std::unique_ptr<RunningServer> StartServer(const v1::PipelineConfig& pipeline_config,
                                           const v1::SourceConfig& source, Threads threads = {}) {
  auto running = std::make_unique<RunningServer>();
  v1::ServerConfig config;
  config.set_listen("127.0.0.1:0");
  *config.mutable_source() = source;
  config.set_data_dir(running->dir.path.empty() ? std::string("stevi-bench-data")
                                                : running->dir.path);
  *config.mutable_pipeline() = pipeline_config;
  if (threads.workers > 0) config.set_pipeline_workers(threads.workers);
  if (threads.opencv > 0) config.set_opencv_threads(threads.opencv);
  Result<std::unique_ptr<server::Server>> started = server::Server::Start(config);
  if (!started.ok()) {
    running->error = "server did not start: " + started.error().message;
    return running;
  }
  running->server = std::move(started).value();
  running->address = std::string("127.0.0.1:").append(std::to_string(running->server->port()));
  client::ClientOptions options;
  options.address = running->address;
  options.timeout = std::chrono::seconds(20);
  running->control = std::make_unique<client::Client>(options);
  // A bounded poll of the server's own report: there is no event to wait on from outside.
  const Clock::time_point deadline = Clock::now() + std::chrono::seconds(60);
  while (true) {
    v1::GetStatusResponse status;
    if (running->control->GetStatus(&status).ok() && status.frames_processed() >= 3) break;
    if (Clock::now() > deadline) {
      running->error = "no frames processed within 60 s";
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return running;
}

Json StatusTimingsJson(const v1::GetStatusResponse& status) {
  Json j = Json::Object();
  for (const v1::StageTiming& t : status.timings()) j.Set(t.stage(), t.ms());
  return j;
}

struct ThroughputRun {
  std::string source;  // "looped" (judged) or "rendered"
  std::string variant;
  stereo::MatcherKind matcher = stereo::MatcherKind::kBlockMatching;
  double source_fps = kNaN;  // the source's rate setting
  Threads threads;           // asked for (the defaults are judged)
  double seconds = 0;
  uint64_t frames = 0;
  double fps = kNaN;           // frames_processed per second (GetStatus)
  double fps_captured = kNaN;  // frames_captured per second
  uint64_t dropped_capture = 0;
  uint64_t failed = 0;
  double cpu_ms_per_frame = kNaN;  // this process (server only: no clients here) per frame
  double cpu_cores = kNaN;         // CPU seconds per second
  v1::GetStatusResponse last;
  std::string error;
};

// Waits (at most 30 s) until the source has played past its loop's first lap, which it renders:
// measurements start when reading a frame costs what it will cost from then on.
void WaitPastTheFirstLap(client::Client& control) {
  for (int i = 0; i < 600; ++i) {
    const std::optional<ServerSnapshot> w = Snap(control);
    if (!w || w->status.frames_captured() > static_cast<uint64_t>(kLoopFrames)) return;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
}

// `rendered`: the synthetic source renders every frame (else it plays its loop).
ThroughputRun MeasureThroughput(const Variant& variant, stereo::MatcherKind kind, double seconds,
                                double source_fps, bool rendered = false, Threads threads = {}) {
  ThroughputRun run;
  run.source = rendered ? "rendered" : "looped";
  run.source_fps = source_fps;
  run.threads = threads;
  run.variant = variant.name;
  run.matcher = MatcherFor(variant, kind);
  std::fprintf(stderr, "  server throughput: %s source, %s + %s at source.fps %.0f for %.1f s\n",
               run.source.c_str(), variant.name.c_str(), MatcherName(kind), source_fps, seconds);
  const v1::SourceConfig source = SyntheticSourceAt(source_fps, !rendered);
  std::unique_ptr<RunningServer> s = StartServer(ProtoConfigFor(variant, kind), source, threads);
  if (!s->error.empty()) {
    run.error = s->error;
    return run;
  }
  WaitPastTheFirstLap(*s->control);
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  const std::optional<ServerSnapshot> a = Snap(*s->control);
  std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  const std::optional<ServerSnapshot> b = Snap(*s->control);
  s->server->Shutdown();
  if (!a || !b) {
    run.error = "GetStatus failed";
    return run;
  }
  run.seconds = std::chrono::duration<double>(b->at - a->at).count();
  run.frames = b->status.frames_processed() - a->status.frames_processed();
  run.fps = static_cast<double>(run.frames) / run.seconds;
  run.fps_captured =
      static_cast<double>(b->status.frames_captured() - a->status.frames_captured()) / run.seconds;
  run.dropped_capture = b->status.frames_dropped_capture() - a->status.frames_dropped_capture();
  run.failed = b->status.frames_failed() - a->status.frames_failed();
  run.cpu_cores = (b->cpu_s - a->cpu_s) / run.seconds;
  if (run.frames > 0)
    run.cpu_ms_per_frame = 1000.0 * (b->cpu_s - a->cpu_s) / static_cast<double>(run.frames);
  run.last = b->status;
  return run;
}

Json ThroughputJson(const ThroughputRun& run) {
  Json j = Json::Object();
  j.Set("source", run.source)
      .Set("algorithm", run.variant)
      .Set("matcher", MatcherName(run.matcher))
      .Set("source_fps_setting", run.source_fps)
      .Set("pipeline_workers", static_cast<uint64_t>(run.last.pipeline_workers()))
      .Set("opencv_threads", static_cast<uint64_t>(run.last.opencv_threads()))
      .Set("seconds", run.seconds)
      .Set("frames_processed", run.frames)
      .Set("fps_processed", run.fps)
      .Set("fps_captured", run.fps_captured)
      .Set("frames_dropped_capture", run.dropped_capture)
      .Set("frames_failed", run.failed)
      .Set("server_cpu_ms_per_frame", run.cpu_ms_per_frame)
      .Set("server_cpu_cores", run.cpu_cores)
      .Set("status_mean_timings_ms", StatusTimingsJson(run.last));
  if (!run.error.empty()) j.Set("error", run.error);
  return j;
}

struct ClientsRun {
  int clients = 0;
  double seconds = kNaN;
  double fps_processed = kNaN;
  double delivered_fps_min = kNaN;  // per client, the slowest
  uint64_t samples = 0;
  double p50_ms = kNaN, p99_ms = kNaN, max_ms = kNaN, mean_ms = kNaN;
  uint64_t dropped = 0;  // frames dropped for the clients during the window (sum)
  int subscribers = 0;   // as GetStatus saw them at the end of the window
  double server_cpu_ms_per_frame = kNaN;
  double server_cpu_cores = kNaN;
  double client_cpu_cores = kNaN;  // the child process holding the clients
  std::string error;
};

std::string SelfExe() {
  char buf[4096];
  const ssize_t n = ::readlink("/proc/self/exe", buf, sizeof buf - 1);
  if (n <= 0) return "stevi-bench";
  buf[n] = '\0';
  return buf;
}

std::string ShellQuote(const std::string& s) {
  std::string out = "'";
  for (const char c : s) {
    if (c == '\'') {
      out += "'\\''";
    } else {
      out += c;
    }
  }
  return out + "'";
}

// key=value pairs of a RESULT line.
std::map<std::string, double> ParseFields(const std::string& line) {
  std::map<std::string, double> out;
  std::istringstream in(line);
  std::string word;
  while (in >> word) {
    const size_t eq = word.find('=');
    if (eq == std::string::npos) continue;
    out[word.substr(0, eq)] = std::strtod(word.c_str() + eq + 1, nullptr);
  }
  return out;
}

ClientsRun MeasureClients(RunningServer& s, int clients, double seconds) {
  std::fprintf(stderr, "  latency: %d client(s) for %.1f s\n", clients, seconds);
  ClientsRun run;
  run.clients = clients;
  const std::string command = ShellQuote(SelfExe())
                                  .append(" --client-worker ")
                                  .append(s.address)
                                  .append(" ")
                                  .append(std::to_string(clients))
                                  .append(" ")
                                  .append(Format("%.3f", seconds));
  FILE* child = ::popen(command.c_str(), "r");
  if (child == nullptr) {
    run.error = "could not start the client process";
    return run;
  }
  std::optional<ServerSnapshot> a, b;
  std::map<std::string, double> result;
  char line[1024];
  while (std::fgets(line, sizeof line, child) != nullptr) {
    const std::string text(line);
    if (text.rfind("START", 0) == 0) {
      a = Snap(*s.control);
    } else if (text.rfind("STOP", 0) == 0) {
      b = Snap(*s.control);
    } else if (text.rfind("RESULT", 0) == 0) {
      result = ParseFields(text);
    } else if (text.rfind("ERROR", 0) == 0) {
      run.error = text.substr(0, text.find('\n'));
    }
  }
  const int status = ::pclose(child);
  if (run.error.empty() && (status != 0 || result.empty())) run.error = "the client process failed";
  if (!a || !b || result.empty()) {
    if (run.error.empty()) run.error = "no measurement window";
    return run;
  }
  const double window = std::chrono::duration<double>(b->at - a->at).count();
  const uint64_t frames = b->status.frames_processed() - a->status.frames_processed();
  run.seconds = result["seconds"];
  run.fps_processed = static_cast<double>(frames) / window;
  run.delivered_fps_min = result["min_frames"] / result["seconds"];
  run.samples = static_cast<uint64_t>(result["samples"]);
  run.p50_ms = result["p50_ms"];
  run.p99_ms = result["p99_ms"];
  run.max_ms = result["max_ms"];
  run.mean_ms = result["mean_ms"];
  run.dropped = static_cast<uint64_t>(result["dropped"]);
  run.subscribers = b->status.subscribers_size();
  run.server_cpu_cores = (b->cpu_s - a->cpu_s) / window;
  if (frames > 0)
    run.server_cpu_ms_per_frame = 1000.0 * (b->cpu_s - a->cpu_s) / static_cast<double>(frames);
  run.client_cpu_cores = result["cpu_s"] / result["seconds"];
  return run;
}

Json ClientsJson(const ClientsRun& run) {
  Json j = Json::Object();
  j.Set("clients", run.clients)
      .Set("seconds", run.seconds)
      .Set("fps_processed", run.fps_processed)
      .Set("delivered_fps_slowest_client", run.delivered_fps_min)
      .Set("latency_samples", run.samples)
      .Set("latency_p50_ms", run.p50_ms)
      .Set("latency_p99_ms", run.p99_ms)
      .Set("latency_max_ms", run.max_ms)
      .Set("latency_mean_ms", run.mean_ms)
      .Set("frames_dropped_for_clients", run.dropped)
      .Set("subscribers_seen", run.subscribers)
      .Set("server_cpu_ms_per_frame", run.server_cpu_ms_per_frame)
      .Set("server_cpu_cores", run.server_cpu_cores)
      .Set("client_process_cpu_cores", run.client_cpu_cores);
  if (!run.error.empty()) j.Set("error", run.error);
  return j;
}

// The child process of MeasureClients: `clients` StreamTracks streams (client::Client, one TCP
// connection each), then a measurement window of `seconds`, marked by START and STOP lines on
// stdout, then a RESULT line. Latency = wall clock at receipt - TrackFrame.capture_unix_time_ns.
int RunClientWorker(const std::string& address, int clients, double seconds) {
  struct Log {
    std::vector<double> latency_ms;
    std::atomic<uint64_t> received{0};
    uint64_t frames = 0;  // in the window
    bool have_first = false;
    uint64_t first_dropped = 0, last_dropped = 0;
    grpc::Status status;
  };
  std::atomic<bool> measuring{false};
  std::vector<std::unique_ptr<Log>> logs;
  std::vector<std::unique_ptr<client::Client>> streams;
  for (int i = 0; i < clients; ++i) {
    logs.push_back(std::make_unique<Log>());
    logs.back()->latency_ms.reserve(static_cast<size_t>(seconds * 2000) + 1024);
    client::ClientOptions options;
    options.address = address;
    options.timeout = std::chrono::seconds(20);
    // Distinct channel arguments, so that gRPC does not share one connection between the clients
    // of this process: each gets a TCP connection of its own, as separate programs would.
    options.max_message_bytes = (64 << 20) + i;
    streams.push_back(std::make_unique<client::Client>(options));
  }
  std::vector<std::thread> threads;
  for (int i = 0; i < clients; ++i) {
    threads.emplace_back([&, i] {
      Log& log = *logs[static_cast<size_t>(i)];
      log.status = streams[static_cast<size_t>(i)]->StreamTracks([&](const v1::TrackFrame& f) {
        const int64_t now = UnixNowNs();
        if (measuring.load(std::memory_order_relaxed)) {
          log.latency_ms.push_back(static_cast<double>(now - f.capture_unix_time_ns()) / 1e6);
          if (!log.have_first) {
            log.have_first = true;
            log.first_dropped = f.dropped_frames();
          }
          log.last_dropped = f.dropped_frames();
          ++log.frames;
        }
        ++log.received;
        return true;
      });
    });
  }
  const auto stop_all = [&] {
    for (auto& c : streams) c->Cancel();
    for (auto& t : threads) t.join();
  };
  // Every stream delivering before the window opens (bounded: 30 s).
  const Clock::time_point deadline = Clock::now() + std::chrono::seconds(30);
  while (true) {
    bool all = true;
    for (const auto& log : logs) all = all && log->received.load() >= 2;
    if (all) break;
    if (Clock::now() > deadline) {
      std::printf("ERROR not every client received frames within 30 s\n");
      std::fflush(stdout);
      stop_all();
      return 1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(500));  // settle
  const double cpu0 = ProcessCpuSeconds();
  const Clock::time_point t0 = Clock::now();
  std::printf("START\n");
  std::fflush(stdout);
  measuring = true;
  std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  measuring = false;
  const double window = SecondsSince(t0);
  const double cpu1 = ProcessCpuSeconds();
  std::printf("STOP\n");
  std::fflush(stdout);
  stop_all();

  std::vector<double> all;
  uint64_t min_frames = UINT64_MAX, max_frames = 0, dropped = 0;
  for (const auto& log : logs) {
    all.insert(all.end(), log->latency_ms.begin(), log->latency_ms.end());
    min_frames = std::min(min_frames, log->frames);
    max_frames = std::max(max_frames, log->frames);
    dropped += log->last_dropped - log->first_dropped;
  }
  if (logs.empty()) min_frames = 0;
  std::printf(
      "RESULT samples=%zu p50_ms=%.4f p99_ms=%.4f max_ms=%.4f mean_ms=%.4f min_frames=%llu "
      "max_frames=%llu dropped=%llu cpu_s=%.4f seconds=%.4f\n",
      all.size(), bench::Percentile(all, 50), bench::Percentile(all, 99),
      all.empty() ? 0.0 : *std::max_element(all.begin(), all.end()), bench::Mean(all),
      static_cast<unsigned long long>(min_frames), static_cast<unsigned long long>(max_frames),
      static_cast<unsigned long long>(dropped), cpu1 - cpu0, window);
  std::fflush(stdout);
  return 0;
}

// ---------------------------------------------------------------------------------------------
// 8. Preview cost
// ---------------------------------------------------------------------------------------------

// The case: annotated and disparity previews at 5 Hz for two viewers, 640x480 frames.
constexpr double kPreviewRateHz = 5.0;
constexpr int kPreviewClients = 2;
constexpr int kPreviewWindowPairs = 4;  // windows without and with previews

struct PreviewCostRun {
  std::string variant = "stevie";
  double source_fps = kNaN;
  double seconds = 0;  // per window
  uint32_t workers = 0;
  std::vector<double> fps_off, fps_on;  // frames processed per second, per window
  double mean_fps_off = kNaN, mean_fps_on = kNaN;
  double ratio = kNaN;             // mean_fps_on / mean_fps_off
  double previews_per_s = kNaN;    // received per client, both kinds (the "on" windows)
  double encodes_per_s = kNaN;     // the server's JPEG encodings per second
  double hub_cpu_ms_per_s = kNaN;  // CPU of the preview hub's thread per second
  double hub_cpu_share = kNaN;     // the same as a fraction of the machine's cores
  double mean_jpeg_bytes = kNaN;
  uint64_t dropped_previews = 0;  // for the clients, at the end of the last window
  std::string error;
};

// Frames processed per second over `seconds` (GetStatus before and after).
std::optional<double> ProcessedFps(client::Client& control, double seconds) {
  const std::optional<ServerSnapshot> a = Snap(control);
  std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  const std::optional<ServerSnapshot> b = Snap(control);
  if (!a || !b) return std::nullopt;
  return static_cast<double>(b->status.frames_processed() - a->status.frames_processed()) /
         std::chrono::duration<double>(b->at - a->at).count();
}

PreviewCostRun MeasurePreviewCost(double seconds, double source_fps) {
  PreviewCostRun run;
  run.source_fps = source_fps;
  run.seconds = seconds;
  std::fprintf(stderr,
               "  preview cost: %s + bm at source.fps %.0f, %d windows of %.1f s, %d clients\n",
               run.variant.c_str(), source_fps, 2 * kPreviewWindowPairs, seconds, kPreviewClients);
  std::unique_ptr<RunningServer> s =
      StartServer(ProtoConfigFor(VariantNamed(run.variant), stereo::MatcherKind::kBlockMatching),
                  SyntheticSourceAt(source_fps));
  if (!s->error.empty()) {
    run.error = s->error;
    return run;
  }
  WaitPastTheFirstLap(*s->control);
  server::PreviewHub& hub = s->server->previews();
  v1::StreamPreviewRequest request;
  request.add_kinds(v1::PREVIEW_KIND_ANNOTATED_LEFT);
  request.add_kinds(v1::PREVIEW_KIND_DISPARITY);
  request.set_rate_hz(kPreviewRateHz);
  request.set_max_width_px(640);
  request.set_jpeg_quality(80);
  struct Viewer {
    std::unique_ptr<client::Client> client;
    std::thread thread;
    std::atomic<uint64_t> previews{0}, bytes{0}, dropped{0};
  };
  double received = 0, received_bytes = 0, on_seconds = 0, encodes = 0, hub_cpu_ns = 0;
  // A window without previews.
  const auto off_window = [&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(500));  // settle
    const std::optional<double> off = ProcessedFps(*s->control, seconds);
    if (!off) {
      run.error = "GetStatus failed";
      return;
    }
    run.fps_off.push_back(*off);
  };
  // A window with the preview clients, which connect before it and leave after it.
  const auto on_window = [&] {
    std::vector<std::unique_ptr<Viewer>> viewers;
    for (int i = 0; i < kPreviewClients; ++i) {
      auto v = std::make_unique<Viewer>();
      client::ClientOptions options;
      options.address = s->address;
      options.timeout = std::chrono::seconds(20);
      options.max_message_bytes = (64 << 20) + i;  // a connection each, as separate programs
      v->client = std::make_unique<client::Client>(options);
      Viewer* raw = v.get();
      v->thread = std::thread([raw, &request] {
        raw->client->StreamPreview(request, [raw](const v1::Preview& p) {
          raw->bytes += p.jpeg().size();
          raw->dropped = p.dropped_previews();
          ++raw->previews;
          return true;
        });
      });
      viewers.push_back(std::move(v));
    }
    // Every viewer receiving before the window opens (a bounded poll: 30 s).
    const Clock::time_point deadline = Clock::now() + std::chrono::seconds(30);
    bool all = false;
    while (!all && Clock::now() < deadline) {
      all = true;
      for (const auto& v : viewers) all = all && v->previews.load() >= 2;
      if (!all) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    if (!all) run.error = "not every preview client received previews within 30 s";
    std::this_thread::sleep_for(std::chrono::milliseconds(500));  // settle
    uint64_t previews0 = 0, bytes0 = 0;
    for (const auto& v : viewers) {
      previews0 += v->previews.load();
      bytes0 += v->bytes.load();
    }
    const server::PreviewHub::Stats hub0 = hub.stats();
    const Clock::time_point t0 = Clock::now();
    const std::optional<double> on = ProcessedFps(*s->control, seconds);
    const double window = SecondsSince(t0);
    const server::PreviewHub::Stats hub1 = hub.stats();
    encodes += static_cast<double>(hub1.encodes - hub0.encodes);
    hub_cpu_ns += static_cast<double>(hub1.cpu_ns - hub0.cpu_ns);
    uint64_t previews1 = 0, bytes1 = 0;
    run.dropped_previews = 0;
    for (const auto& v : viewers) {
      previews1 += v->previews.load();
      bytes1 += v->bytes.load();
      run.dropped_previews += v->dropped.load();
    }
    received += static_cast<double>(previews1 - previews0);
    received_bytes += static_cast<double>(bytes1 - bytes0);
    on_seconds += window;
    for (auto& v : viewers) v->client->Cancel();
    for (auto& v : viewers) v->thread.join();
    if (!on) {
      if (run.error.empty()) run.error = "GetStatus failed";
      return;
    }
    run.fps_on.push_back(*on);
    // The server lets the streams go (a bounded poll of its hub: 10 s).
    const Clock::time_point gone = Clock::now() + std::chrono::seconds(10);
    while (hub.size() > 0 && Clock::now() < gone) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  };
  // Without, with, with, without, without, with, ...: a drift of the machine's load over the run
  // falls on both alike.
  for (int w = 0; w < 2 * kPreviewWindowPairs && run.error.empty(); ++w) {
    if (w % 4 == 1 || w % 4 == 2) {
      on_window();
    } else {
      off_window();
    }
  }
  v1::GetStatusResponse status;
  if (s->control->GetStatus(&status).ok()) run.workers = status.pipeline_workers();
  s->server->Shutdown();
  if (!run.error.empty() || run.fps_on.empty()) return run;
  run.mean_fps_off = bench::Mean(run.fps_off);
  run.mean_fps_on = bench::Mean(run.fps_on);
  run.ratio = run.mean_fps_on / run.mean_fps_off;
  run.previews_per_s = received / on_seconds / kPreviewClients;
  run.encodes_per_s = encodes / on_seconds;
  run.hub_cpu_ms_per_s = hub_cpu_ns / 1e6 / on_seconds;
  run.hub_cpu_share =
      run.hub_cpu_ms_per_s / 1000.0 / static_cast<double>(std::max(1, cv::getNumberOfCPUs()));
  if (received > 0) run.mean_jpeg_bytes = received_bytes / received;
  return run;
}

Json PreviewCostJson(const PreviewCostRun& run) {
  Json off = Json::Array(), on = Json::Array();
  for (double f : run.fps_off) off.Push(f);
  for (double f : run.fps_on) on.Push(f);
  Json j = Json::Object();
  j.Set("algorithm", run.variant)
      .Set("matcher", "bm")
      .Set("size", "640x480")
      .Set("source_fps_setting", run.source_fps)
      .Set("pipeline_workers", static_cast<uint64_t>(run.workers))
      .Set("clients", kPreviewClients)
      .Set("kinds", "annotated_left+disparity")
      .Set("rate_hz", kPreviewRateHz)
      .Set("max_width_px", 640)
      .Set("jpeg_quality", 80)
      .Set("seconds_per_window", run.seconds)
      .Set("fps_without_previews", std::move(off))
      .Set("fps_with_previews", std::move(on))
      .Set("mean_fps_without", run.mean_fps_off)
      .Set("mean_fps_with", run.mean_fps_on)
      .Set("ratio", run.ratio)
      .Set("previews_per_s_per_client", run.previews_per_s)
      .Set("encodes_per_s", run.encodes_per_s)
      .Set("hub_cpu_ms_per_s", run.hub_cpu_ms_per_s)
      .Set("hub_cpu_share_of_cores", run.hub_cpu_share)
      .Set("mean_jpeg_bytes", run.mean_jpeg_bytes)
      .Set("dropped_previews", run.dropped_previews);
  if (!run.error.empty()) j.Set("error", run.error);
  return j;
}

void PrintPreviewCost(FILE* table, const PreviewCostRun& run) {
  std::fprintf(table,
               "\n8. Preview cost (%s + BM, 640x480, source.fps %.0f, %u workers; %d StreamPreview "
               "clients, annotated + disparity JPEGs at %.0f Hz, 640 wide, quality 80; windows of "
               "%.1f s, four without and four with them, ABBA)\n",
               run.variant.c_str(), run.source_fps, run.workers, kPreviewClients, kPreviewRateHz,
               run.seconds);
  if (!run.error.empty()) {
    std::fprintf(table, "   error: %s\n", run.error.c_str());
    return;
  }
  std::string off, on;
  for (double f : run.fps_off) off += Format(" %.1f", f);
  for (double f : run.fps_on) on += Format(" %.1f", f);
  std::fprintf(table, "   fps without previews:%s (mean %.1f)\n", off.c_str(), run.mean_fps_off);
  std::fprintf(table, "   fps with previews:   %s (mean %.1f)\n", on.c_str(), run.mean_fps_on);
  std::fprintf(table,
               "   ratio %.3f; %.1f previews/s per client, %.1f encodings/s, mean JPEG %.0f "
               "bytes, %llu previews dropped for the clients\n",
               run.ratio, run.previews_per_s, run.encodes_per_s, run.mean_jpeg_bytes,
               static_cast<unsigned long long>(run.dropped_previews));
  std::fprintf(table,
               "   the hub's thread (render, scale, encode): %.1f ms of CPU a second, %.2f %% of "
               "the %d cores: the most encoding can take from a pipeline that saturates them\n",
               run.hub_cpu_ms_per_s, 100.0 * run.hub_cpu_share, cv::getNumberOfCPUs());
}

// ---------------------------------------------------------------------------------------------
// Machine and build
// ---------------------------------------------------------------------------------------------

std::string ReadFirstLine(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);
  return line;
}

Json MachineJson() {
  std::ifstream in("/proc/cpuinfo");
  std::string line, model;
  int processors = 0;
  while (std::getline(in, line)) {
    if (line.rfind("processor", 0) == 0) ++processors;
    if (model.empty() && line.rfind("model name", 0) == 0) {
      const size_t colon = line.find(':');
      if (colon != std::string::npos) model = line.substr(colon + 2);
    }
  }
  utsname u{};
  ::uname(&u);
  return Json::Object()
      .Set("cpu_model", model.empty() ? std::string("unknown") : model)
      .Set("cpus_in_cpuinfo", processors)
      .Set("cpus_online", static_cast<int64_t>(::sysconf(_SC_NPROCESSORS_ONLN)))
      .Set("hardware_concurrency", static_cast<int64_t>(std::thread::hardware_concurrency()))
      .Set("kernel", std::string(u.sysname).append(" ").append(u.release))
      .Set("loadavg_at_start", ReadFirstLine("/proc/loadavg"));
}

// OpenCV's thread count when the run began: the stage tables (1 to 4) use it; each server sets its
// own (opencv_threads, the wrk/cv column), and that setting belongs to the process.
int g_opencv_threads_at_start = 0;

Json BuildJson() {
  return Json::Object()
      .Set("build_type", STEVI_BUILD_TYPE)
      .Set("cxx_flags", STEVI_CXX_FLAGS)
      .Set("compiler", std::string("g++ ").append(__VERSION__))
      .Set("opencv", CV_VERSION)
      .Set("opencv_threads_stage_tables", g_opencv_threads_at_start)
      .Set("opencv_cpu_features", cv::getCPUFeaturesLine())
#ifdef NDEBUG
      .Set("ndebug", true);
#else
      .Set("ndebug", false);
#endif
}

std::string UtcNow() {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&now, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

// ---------------------------------------------------------------------------------------------
// Output
// ---------------------------------------------------------------------------------------------

struct Target {
  std::string name;
  std::string rule;
  double measured = kNaN;
  std::string unit;
  bool higher_is_better = true;
  double threshold = 0;
  std::string note;

  std::string Verdict() const {
    if (!std::isfinite(measured)) return "N/A";
    return (higher_is_better ? measured >= threshold : measured <= threshold) ? "PASS" : "MISS";
  }
};

Target PreviewTarget(const PreviewCostRun& run) {
  return {"preview cost",
          ">= 0.90",
          run.ratio,
          "x",
          true,
          0.90,
          "fps with / without 2 preview clients (annotated + disparity, 5 Hz, 640x480), table 8"};
}

}  // namespace

int main(int argc, char** argv) {
  stevi::KeepFrameMemory();  // first: before any thread starts
  g_opencv_threads_at_start = cv::getNumThreads();
  if (argc >= 2 && std::string(argv[1]) == "--client-worker") {
    // Started by MeasureClients with its own arguments (positional: not a FlagSet's).
    const flags::Parsed<std::int64_t> clients =
        flags::ParseNumber(argc == 5 ? argv[3] : "", kWorkerClientsRange);
    const flags::Parsed<double> seconds =
        flags::ParseNumber(argc == 5 ? argv[4] : "", kSecondsRange);
    if (!clients.ok() || !seconds.ok()) {
      std::fprintf(stderr, "usage: stevi-bench --client-worker ADDRESS CLIENTS SECONDS\n");
      return 2;
    }
    return RunClientWorker(argv[2], static_cast<int>(clients.value), seconds.value);
  }
  const Flags flags = ParseFlags(argc, argv);
  FILE* table = flags.json == "-" ? stderr : stdout;
  if (flags.preview_only) {
    const PreviewCostRun run = MeasurePreviewCost(flags.seconds, flags.source_fps);
    PrintPreviewCost(table, run);
    const Target target = PreviewTarget(run);
    std::fprintf(table, "\n%-22s %-10s %10s  %-4s  %s\n", target.name.c_str(), target.rule.c_str(),
                 (Ms(target.measured, "%.3f") + " " + target.unit).c_str(),
                 target.Verdict().c_str(), target.note.c_str());
    if (!flags.json.empty()) {
      std::string text;
      Json::Object()
          .Set("tool", "stevi-bench")
          .Set("schema", 1)
          .Set("started_utc", UtcNow())
          .Set("build", BuildJson())
          .Set("machine", MachineJson())
          .Set("preview_cost", PreviewCostJson(run))
          .Dump(text);
      text += "\n";
      if (flags.json == "-") {
        std::fputs(text.c_str(), stdout);
      } else {
        std::ofstream(flags.json) << text;
      }
    }
    return target.Verdict() == "PASS" ? 0 : 3;
  }

  const std::vector<cv::Size> sizes = {{640, 480}, {1280, 1024}};
  const std::vector<stereo::MatcherKind> matchers = {stereo::MatcherKind::kBlockMatching,
                                                     stereo::MatcherKind::kSemiGlobal};
  const std::vector<int> disparity_counts = {32, 64, 128};
  const std::vector<int> client_counts =
      flags.quick ? std::vector<int>{1, 16} : std::vector<int>{1, 4, 16, 32};

  Json root = Json::Object();
  root.Set("tool", "stevi-bench").Set("schema", 1).Set("started_utc", UtcNow());
  Json machine = MachineJson();
  root.Set("build", BuildJson());
  root.Set("settings",
           Json::Object()
               .Set("seconds_per_measurement", flags.seconds)
               .Set("quick", flags.quick)
               .Set("latency_source_fps", flags.latency_fps)
               .Set("latency_algorithm", flags.latency_algorithm)
               .Set("throughput_source_fps", flags.source_fps)
               .Set("offline_warmup_frames", kWarmupFrames)
               .Set("synthetic_scene", "demo (DefaultScene), noise sigma 2, seed 1")
               .Set("rig_640x480", "f 700 px, B 0.6 m")
               .Set("rig_1280x1024", "f 1400 px, B 0.6 m (same horizontal field of view)"));

  // 1-2. Stages, resolution and disparity count.
  std::fprintf(stderr, "stevi-bench: %.1f s per measurement\n", flags.seconds);
  std::vector<OfflineRun> offline;
  for (const cv::Size& size : sizes) {
    for (const Variant& variant : Variants()) {
      for (stereo::MatcherKind kind : matchers) {
        // The stixel world has one matcher: measured once.
        if (variant.algorithm == pipeline::Algorithm::kStixels && kind != matchers.front())
          continue;
        offline.push_back(MeasureOffline(variant, kind, size, 64, flags.seconds));
      }
    }
  }
  // 1280x1024 as the server runs it by default: binned by 2 (max_width_px 800).
  const int default_max_width = pipeline::PipelineConfig{}.max_width_px;
  for (const Variant& variant : Variants()) {
    offline.push_back(MeasureOffline(variant, stereo::MatcherKind::kBlockMatching, {1280, 1024}, 64,
                                     flags.seconds, default_max_width));
  }
  std::vector<OfflineRun> disparity_runs;
  for (stereo::MatcherKind kind : matchers) {
    for (int d : disparity_counts) {
      if (d == 64) continue;  // measured above
      disparity_runs.push_back(
          MeasureOffline(VariantNamed("stevie"), kind, {640, 480}, d, flags.seconds));
    }
  }
  const auto find_offline = [&](const std::string& variant, stereo::MatcherKind kind, cv::Size size,
                                int d, int max_width_px = 0) -> const OfflineRun* {
    for (const std::vector<OfflineRun>* runs : {&offline, &disparity_runs}) {
      for (const OfflineRun& run : *runs) {
        if (run.variant == variant && run.matcher == kind && run.size == size &&
            run.disparities == d && run.max_width_px == max_width_px) {
          return &run;
        }
      }
    }
    return nullptr;
  };

  // 3. Baseline.
  const Baseline baseline = MeasureBaseline(flags.seconds, offline);

  // 4. Tracking.
  std::vector<TrackerRun> tracker_runs;
  tracker_runs.push_back(MeasureTracker(10, std::min(1.0, flags.seconds)));
  tracker_runs.push_back(MeasureTracker(100, flags.seconds));

  // 5. Throughput through the server.
  std::vector<ThroughputRun> throughput;
  for (stereo::MatcherKind kind : matchers) {
    if (flags.quick && kind == stereo::MatcherKind::kSemiGlobal) continue;
    for (const Variant& variant : Variants()) {
      if (variant.algorithm == pipeline::Algorithm::kStixels && kind != matchers.front()) continue;
      throughput.push_back(MeasureThroughput(variant, kind, flags.seconds, flags.source_fps));
    }
  }
  // For reference (not judged), against the defaults above (a worker per core, OpenCV on one thread
  // in each): one worker whose OpenCV calls use every core (parallelism inside a frame only), and
  // a worker per core whose OpenCV calls use every core too (both).
  const uint32_t cores = static_cast<uint32_t>(std::max(1, cv::getNumberOfCPUs()));
  for (const Threads threads : {Threads{1, cores}, Threads{0, cores}}) {
    for (const char* name : {"canonical", "stevie"}) {
      throughput.push_back(MeasureThroughput(VariantNamed(name),
                                             stereo::MatcherKind::kBlockMatching, flags.seconds,
                                             flags.source_fps, false, threads));
    }
  }
  // For reference (not judged): the synthetic source rendering every frame, block matching.
  for (const Variant& variant : Variants()) {
    throughput.push_back(MeasureThroughput(variant, stereo::MatcherKind::kBlockMatching,
                                           flags.seconds, flags.source_fps, true));
  }

  // 6. Latency and clients, one server at the camera rate.
  std::vector<ClientsRun> clients_runs;
  std::string clients_error;
  {
    std::fprintf(stderr, "  latency server: %s + bm at source.fps %.1f\n",
                 flags.latency_algorithm.c_str(), flags.latency_fps);
    std::unique_ptr<RunningServer> s = StartServer(
        ProtoConfigFor(VariantNamed(flags.latency_algorithm), stereo::MatcherKind::kBlockMatching),
        SyntheticSourceAt(flags.latency_fps));
    if (!s->error.empty()) {
      clients_error = s->error;
    } else {
      WaitPastTheFirstLap(*s->control);
      for (int n : client_counts) clients_runs.push_back(MeasureClients(*s, n, flags.seconds));
      s->server->Shutdown();
    }
  }
  // 8. Preview cost, against the same server setup as 5.
  const PreviewCostRun preview_cost = MeasurePreviewCost(flags.seconds, flags.source_fps);
  machine.Set("loadavg_at_end", ReadFirstLine("/proc/loadavg"));
  root.Set("machine", std::move(machine));

  // 7. Targets.
  const auto throughput_of = [&](const std::string& variant) {
    const stereo::MatcherKind matcher =
        MatcherFor(VariantNamed(variant), stereo::MatcherKind::kBlockMatching);
    for (const ThroughputRun& run : throughput) {
      if (run.source == "looped" && run.variant == variant && run.threads.workers == 0 &&
          run.threads.opencv == 0 && run.matcher == matcher) {
        return run.fps;
      }
    }
    return kNaN;
  };
  const auto clients_of = [&](int n) -> const ClientsRun* {
    for (const ClientsRun& run : clients_runs) {
      if (run.clients == n) return &run;
    }
    return nullptr;
  };
  std::vector<Target> targets;
  targets.push_back(
      {"stixels throughput", ">= 60 fps", throughput_of("stixels"), "fps", true, 60,
       "server, the default (stixels + dense), 640x480, GetStatus frames_processed/s"});
  targets.push_back(
      {"SteViS throughput", ">= 30 fps", throughput_of("stevis"), "fps", true, 30,
       "server, threshold segmentation, BM, 640x480, 64 disp, GetStatus frames_processed/s"});
  targets.push_back({"SteViE throughput", ">= 60 fps", throughput_of("stevie"), "fps", true, 60,
                     "server, BM, 640x480, 64 disp, GetStatus frames_processed/s"});
  for (int n : {1, 16}) {
    const ClientsRun* run = clients_of(n);
    targets.push_back({std::string("latency p99, ")
                           .append(std::to_string(n))
                           .append(n == 1 ? " client" : " clients"),
                       "<= 50 ms", run ? run->p99_ms : kNaN, "ms", false, 50,
                       std::string("capture to receipt, ")
                           .append(flags.latency_algorithm)
                           .append(" + BM at ")
                           .append(Format("%.0f", flags.latency_fps))
                           .append(" fps")});
  }
  targets.push_back(PreviewTarget(preview_cost));
  for (const TrackerRun& run : tracker_runs) {
    if (run.targets != 100) continue;
    targets.push_back({"tracking, 100 tracks", "<= 0.5 ms", run.update_ms.mean, "ms", false, 0.5,
                       std::string("Tracker::Update mean; p99 ")
                           .append(Ms(run.update_ms.p99, "%.3f"))
                           .append(" ms; ")
                           .append(Format("%.0f", run.confirmed))
                           .append(" confirmed tracks")});
  }

  // ---- The table ----
  std::string machine_text;
  {
    std::ifstream in("/proc/cpuinfo");
    std::string line;
    while (std::getline(in, line)) {
      if (line.rfind("model name", 0) == 0) {
        machine_text = line.substr(line.find(':') + 2);
        break;
      }
    }
  }
  std::fprintf(table, "\nstevi-bench  %s\n", UtcNow().c_str());
  std::fprintf(table,
               "machine: %s, %ld CPUs online; build %s; OpenCV %s, %d threads in tables 1-4; "
               "%.1f s per measurement%s\n",
               machine_text.c_str(), ::sysconf(_SC_NPROCESSORS_ONLN), STEVI_BUILD_TYPE, CV_VERSION,
               g_opencv_threads_at_start, flags.seconds, flags.quick ? " (quick)" : "");

  std::fprintf(table,
               "\n1. Stages (ms, mean; total also p99), synthetic demo scene, 64 disparities, "
               "rectified input (rectify = copy)\n");
  std::fprintf(table, "%-11s %-13s %-5s %7s %8s %8s %7s %7s %8s %8s %6s %6s %7s\n", "size",
               "algorithm", "match", "rectify", "disparity", "extract", "track", "total", "p50",
               "p99", "frames", "dets", "render");
  for (const OfflineRun& run : offline) {
    if (!run.error.empty()) {
      std::fprintf(table, "%-11s %-13s %-5s error: %s\n",
                   RunSizeName(run.size, run.max_width_px).c_str(), run.variant.c_str(),
                   MatcherName(run.matcher), run.error.c_str());
      continue;
    }
    std::fprintf(table, "%-11s %-13s %-5s %7s %8s %8s %7s %7s %8s %8s %6d %6.1f %7s\n",
                 RunSizeName(run.size, run.max_width_px).c_str(), run.variant.c_str(),
                 MatcherName(run.matcher), Ms(run.Stage("rectify").mean).c_str(),
                 Ms(run.Stage("disparity").mean).c_str(), Ms(run.Stage("extract").mean).c_str(),
                 Ms(run.Stage("track").mean, "%.3f").c_str(), Ms(run.Stage("total").mean).c_str(),
                 Ms(run.Stage("total").p50).c_str(), Ms(run.Stage("total").p99).c_str(), run.frames,
                 run.detections_per_frame, Ms(run.render.mean).c_str());
  }

  std::fprintf(table,
               "\n2a. Cost against resolution (total ms, mean; 1280x1024 has 4.27x the pixels;"
               " /2 = binned to 640x512, the default)\n");
  std::fprintf(table, "%-13s %-5s %9s %10s %7s %12s %7s\n", "algorithm", "match", "640x480",
               "1280x1024", "ratio", "1280x1024/2", "ratio");
  for (const Variant& variant : Variants()) {
    for (stereo::MatcherKind kind : matchers) {
      const OfflineRun* lo = find_offline(variant.name, kind, {640, 480}, 64);
      const OfflineRun* hi = find_offline(variant.name, kind, {1280, 1024}, 64);
      const OfflineRun* binned =
          find_offline(variant.name, kind, {1280, 1024}, 64, default_max_width);
      const double a = lo ? lo->Stage("total").mean : kNaN, c = hi ? hi->Stage("total").mean : kNaN;
      const double b = binned ? binned->Stage("total").mean : kNaN;
      std::fprintf(table, "%-13s %-5s %9s %10s %7s %12s %7s\n", variant.name.c_str(),
                   MatcherName(kind), Ms(a).c_str(), Ms(c).c_str(), Ms(c / a, "%.2fx").c_str(),
                   Ms(b).c_str(), Ms(b / a, "%.2fx").c_str());
    }
  }
  std::fprintf(table, "\n2b. Cost against the disparity count (SteViE, 640x480; ms, mean)\n");
  std::fprintf(table, "%-5s %6s %10s %8s %8s\n", "match", "disp", "disparity", "total", "vs 64");
  for (stereo::MatcherKind kind : matchers) {
    const OfflineRun* ref = find_offline("stevie", kind, {640, 480}, 64);
    for (int d : disparity_counts) {
      const OfflineRun* run = find_offline("stevie", kind, {640, 480}, d);
      const double disp = run ? run->Stage("disparity").mean : kNaN;
      const double ref_disp = ref ? ref->Stage("disparity").mean : kNaN;
      std::fprintf(table, "%-5s %6d %10s %8s %8s\n", MatcherName(kind), d, Ms(disp).c_str(),
                   Ms(run ? run->Stage("total").mean : kNaN).c_str(),
                   Ms(disp / ref_disp, "%.2fx").c_str());
    }
  }

  std::fprintf(table,
               "\n3. Naive thesis baseline (1 OpenCV thread, full resolution) vs ours, one 640x480 "
               "frame (ms, mean)\n");
  std::fprintf(table, "%-20s %9s %9s %9s %10s %10s  %s\n", "stage", "naive 1t", "ours", "ours 1t",
               "ours/naive", "1t/naive", "ours is");
  for (const BaselineRow& row : baseline.rows) {
    std::fprintf(table, "%-20s %9s %9s %9s %10s %10s  %s%s%s\n", row.stage.c_str(),
                 Ms(row.naive_ms.mean).c_str(), Ms(row.ours_ms.mean).c_str(),
                 Ms(row.ours_1t_ms.mean).c_str(),
                 Ms(row.ours_ms.mean / row.naive_ms.mean, "%.3f").c_str(),
                 Ms(row.ours_1t_ms.mean / row.naive_ms.mean, "%.3f").c_str(), row.ours.c_str(),
                 row.note.empty() ? "" : "; ", row.note.c_str());
  }

  std::fprintf(table, "\n4. Tracking (Tracker::Update, moving targets on a grid, 10 fps)\n");
  std::fprintf(table, "%8s %8s %9s %9s %9s %7s %10s\n", "targets", "updates", "mean ms", "p50 ms",
               "p99 ms", "tracks", "confirmed");
  for (const TrackerRun& run : tracker_runs) {
    std::fprintf(table, "%8d %8d %9s %9s %9s %7.0f %10.0f\n", run.targets, run.updates,
                 Ms(run.update_ms.mean, "%.4f").c_str(), Ms(run.update_ms.p50, "%.4f").c_str(),
                 Ms(run.update_ms.p99, "%.4f").c_str(), run.tracks, run.confirmed);
  }

  std::fprintf(table,
               "\n5. Sustained throughput through the server (source.fps %.0f, 640x480, 64 disp; "
               "looped: the synthetic source plays %d frames rendered once, as a camera costs "
               "nothing to read; rendered: it renders each pair on the capture thread; "
               "offline cap = 1000 / table-1 total)\n",
               flags.source_fps, kLoopFrames);
  std::fprintf(table, "%-9s %-13s %-5s %8s %8s %8s %9s %10s %8s %9s  %s\n", "source", "algorithm",
               "match", "fps out", "fps in", "dropped", "CPU ms/f", "CPU cores", "offl cap",
               "wrk/cv", "GetStatus mean stage ms");
  for (const ThroughputRun& run : throughput) {
    if (!run.error.empty()) {
      std::fprintf(table, "%-9s %-13s %-5s error: %s\n", run.source.c_str(), run.variant.c_str(),
                   MatcherName(run.matcher), run.error.c_str());
      continue;
    }
    const OfflineRun* offline_run = find_offline(run.variant, run.matcher, {640, 480}, 64);
    const double cap = offline_run ? 1000.0 / offline_run->Stage("total").mean : kNaN;
    std::string stages;
    for (const v1::StageTiming& t : run.last.timings()) {
      stages.append(t.stage()).append(" ").append(Format("%.2f", t.ms())).append("  ");
    }
    const std::string threads = std::to_string(run.last.pipeline_workers()) + "/" +
                                std::to_string(run.last.opencv_threads());
    std::fprintf(table, "%-9s %-13s %-5s %8.1f %8.1f %8llu %9s %10s %8s %9s  %s\n",
                 run.source.c_str(), run.variant.c_str(), MatcherName(run.matcher), run.fps,
                 run.fps_captured, static_cast<unsigned long long>(run.dropped_capture),
                 Ms(run.cpu_ms_per_frame).c_str(), Ms(run.cpu_cores).c_str(),
                 Ms(cap, "%.1f").c_str(), threads.c_str(), stages.c_str());
  }

  std::fprintf(table,
               "\n6. Clients (%s + BM, source at %.1f fps; clients in a child process, one "
               "connection each)\n",
               flags.latency_algorithm.c_str(), flags.latency_fps);
  if (!clients_error.empty()) std::fprintf(table, "   error: %s\n", clients_error.c_str());
  std::fprintf(table, "%7s %8s %10s %8s %8s %8s %8s %9s %9s %9s\n", "clients", "fps out",
               "slowest/s", "p50 ms", "p99 ms", "max ms", "dropped", "srv ms/f", "srv cores",
               "cli cores");
  for (const ClientsRun& run : clients_runs) {
    if (!run.error.empty()) {
      std::fprintf(table, "%7d error: %s\n", run.clients, run.error.c_str());
      continue;
    }
    std::fprintf(table, "%7d %8.1f %10.1f %8s %8s %8s %8llu %9s %9s %9s\n", run.clients,
                 run.fps_processed, run.delivered_fps_min, Ms(run.p50_ms).c_str(),
                 Ms(run.p99_ms).c_str(), Ms(run.max_ms).c_str(),
                 static_cast<unsigned long long>(run.dropped),
                 Ms(run.server_cpu_ms_per_frame).c_str(), Ms(run.server_cpu_cores).c_str(),
                 Ms(run.client_cpu_cores).c_str());
  }

  PrintPreviewCost(table, preview_cost);

  std::fprintf(table, "\n7. Targets\n");
  std::fprintf(table, "%-22s %-10s %10s  %-4s  %s\n", "target", "rule", "measured", "", "how");
  bool missed = false;
  for (const Target& t : targets) {
    missed = missed || t.Verdict() != "PASS";
    std::fprintf(table, "%-22s %-10s %10s  %-4s  %s\n", t.name.c_str(), t.rule.c_str(),
                 (Ms(t.measured, t.threshold < 1 ? "%.3f" : "%.1f") + " " + t.unit).c_str(),
                 t.Verdict().c_str(), t.note.c_str());
  }
  std::fflush(table);

  // ---- JSON ----
  if (!flags.json.empty()) {
    Json stages = Json::Array();
    for (const OfflineRun& run : offline) stages.Push(OfflineJson(run));
    Json disparity = Json::Array();
    for (stereo::MatcherKind kind : matchers) {
      for (int d : disparity_counts) {
        if (const OfflineRun* run = find_offline("stevie", kind, {640, 480}, d))
          disparity.Push(OfflineJson(*run));
      }
    }
    Json tracker = Json::Array();
    for (const TrackerRun& run : tracker_runs) {
      tracker.Push(Json::Object()
                       .Set("targets", run.targets)
                       .Set("updates", run.updates)
                       .Set("update", StatsJson(run.update_ms))
                       .Set("tracks_after_last_update", run.tracks)
                       .Set("confirmed_after_last_update", run.confirmed));
    }
    Json through = Json::Array();
    for (const ThroughputRun& run : throughput) through.Push(ThroughputJson(run));
    Json clients = Json::Array();
    for (const ClientsRun& run : clients_runs) clients.Push(ClientsJson(run));
    Json target_json = Json::Array();
    for (const Target& t : targets) {
      target_json.Push(Json::Object()
                           .Set("name", t.name)
                           .Set("rule", t.rule)
                           .Set("threshold", t.threshold)
                           .Set("measured", t.measured)
                           .Set("unit", t.unit)
                           .Set("result", t.Verdict())
                           .Set("how", t.note));
    }
    root.Set("stages", std::move(stages))
        .Set("disparity_scaling", std::move(disparity))
        .Set("baseline", BaselineJson(baseline))
        .Set("tracking", std::move(tracker))
        .Set("throughput", std::move(through))
        .Set("clients", Json::Object()
                            .Set("algorithm", flags.latency_algorithm)
                            .Set("matcher", "bm")
                            .Set("source_fps", flags.latency_fps)
                            .Set("error", clients_error.empty() ? Json() : Json(clients_error))
                            .Set("runs", std::move(clients)))
        .Set("preview_cost", PreviewCostJson(preview_cost))
        .Set("targets", std::move(target_json));
    std::string text;
    root.Dump(text);
    text += "\n";
    if (flags.json == "-") {
      std::fputs(text.c_str(), stdout);
    } else {
      std::ofstream out(flags.json);
      out << text;
      if (!out) {
        std::fprintf(stderr, "could not write %s\n", flags.json.c_str());
        return 1;
      }
    }
  }
  if (missed) {
    std::fprintf(stderr, "stevi-bench: not every target passed (table 7)\n");
    return 3;
  }
  return 0;
}
