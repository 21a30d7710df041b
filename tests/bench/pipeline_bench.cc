// Google Benchmark cases for the stages on the synthetic scene, at 640x480 and 1280x1024 (the rig
// keeps its horizontal field of view: f = 700 px and 1400 px), for every algorithm and matcher,
// against the disparity count, for the tracker with 100 tracks, and for the naive thesis baseline
// on one thread (naive_baseline.h). Compare ratios measured in the same run; the machine is noisy.
//
// Argument names: size 0 = 640x480, 1 = 1280x1024; matcher 0 = block matching, 1 = semi-global
// (3-way, the project's default mode); alg 0 = canonical, 1 = SteViE, 2 = SteViS (threshold),
// 3 = SteViS (graph segmentation). Pipeline cases report each stage's mean as a counter (ms).
#include <benchmark/benchmark.h>

#include <array>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <algorithm>
#include <thread>

#include <opencv2/calib3d.hpp>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

#include "core/detection/canonical.h"
#include "core/detection/ground.h"
#include "core/detection/ground_plane.h"
#include "core/detection/range_scan.h"
#include "core/detection/regions.h"
#include "core/detection/stevie.h"
#include "core/detection/stevis.h"
#include "core/extraction/edges.h"
#include "core/extraction/morphology.h"
#include "core/extraction/saliency.h"
#include "core/extraction/segmentation.h"
#include "core/geo/mount.h"
#include "core/pipeline/pipeline.h"
#include "core/stereo/block_matcher.h"
#include "core/stereo/matcher.h"
#include "core/tracking/tracker.h"
#include "drivers/synthetic/synthetic_source.h"
#include "tests/bench/naive_baseline.h"
#include "tests/testing/stereo_bm.h"

namespace {

using namespace stevi;

const std::array<cv::Size, 2> kSizes = {cv::Size(640, 480), cv::Size(1280, 1024)};
constexpr int kSequenceFrames = 8;  // consecutive frames the pipeline cases cycle through

struct Scene {
  explicit Scene(cv::Size size) : renderer(bench::SyntheticAt(size)) {
    for (int k = 0; k < kSequenceFrames; ++k) sequence.push_back(renderer.Render(50 + k));
    frame = sequence.front();
    rig = std::make_shared<const geometry::StereoRig>(renderer.Rig());
  }
  drivers::SyntheticRenderer renderer;
  std::vector<StereoFrame> sequence;
  StereoFrame frame;  // frame 50, as before
  std::shared_ptr<const geometry::StereoRig> rig;
};

const Scene& SceneAt(int64_t size_index) {
  static std::map<int64_t, std::unique_ptr<Scene>> scenes;  // benchmarks run on one thread
  std::unique_ptr<Scene>& scene = scenes[size_index];
  if (scene == nullptr) scene = std::make_unique<Scene>(kSizes.at(static_cast<size_t>(size_index)));
  return *scene;
}

const char* AlgorithmLabel(int64_t alg) {
  switch (alg) {
    case 0: return "canonical";
    case 1: return "stevie";
    case 2: return "stevis-threshold";
    default: return "stevis-graph";
  }
}

pipeline::PipelineConfig ConfigFor(int64_t alg, int64_t matcher, int num_disparities) {
  pipeline::PipelineConfig config;
  config.algorithm = alg == 0   ? pipeline::Algorithm::kCanonical
                     : alg == 1 ? pipeline::Algorithm::kSteViE
                                : pipeline::Algorithm::kSteViS;
  config.stevis.segmentation = alg == 3 ? detection::SteViSOptions::Segmentation::kGraph
                                        : detection::SteViSOptions::Segmentation::kThreshold;
  config.matcher.kind =
      matcher == 0 ? stereo::MatcherKind::kBlockMatching : stereo::MatcherKind::kSemiGlobal;
  config.matcher.block_matching.num_disparities = num_disparities;
  config.matcher.semi_global.num_disparities = num_disparities;
  // Every size at its own resolution: these cases measure what the pixels cost (the server's
  // default, max_width_px 800, would bin 1280x1024 to 640x512).
  config.max_width_px = 0;
  return config;
}

std::string Label(int64_t size, const char* what) {
  return bench::SizeName(kSizes.at(static_cast<size_t>(size))).append(" ").append(what);
}

// ---------------------------------------------------------------------------------------------
// Sources and stages
// ---------------------------------------------------------------------------------------------

void BM_Render(benchmark::State& state) {
  const Scene& scene = SceneAt(state.range(0));
  int64_t k = 0;
  for (auto _ : state) benchmark::DoNotOptimize(scene.renderer.Render(k++));
  state.SetLabel(Label(state.range(0), "synthetic pair"));
}
BENCHMARK(BM_Render)->ArgName("size")->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

// StereoRig::Rectify of a raw (distorted) rig: both images remapped with fixed-point maps. The
// synthetic source delivers rectified pairs, so the pipeline cases below only copy; a camera rig
// pays this.
void BM_RectifyRawRig(benchmark::State& state) {
  const Scene& scene = SceneAt(state.range(0));
  Result<geometry::StereoRig> raw = bench::RawRigLike(*scene.rig);
  if (!raw.ok()) {
    state.SkipWithError(raw.error().message.c_str());
    return;
  }
  cv::Mat left, right;
  for (auto _ : state) {
    benchmark::DoNotOptimize(raw->Rectify(scene.frame.left, scene.frame.right, left, right));
  }
  state.SetLabel(Label(state.range(0), "remap of both images"));
}
BENCHMARK(BM_RectifyRawRig)->ArgName("size")->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

void BM_Matcher(benchmark::State& state) {
  const Scene& scene = SceneAt(state.range(1));
  stereo::MatcherOptions options =
      ConfigFor(0, std::min<int64_t>(state.range(0), 1), static_cast<int>(state.range(2))).matcher;
  if (state.range(0) == 2) {  // the dense matcher (census SGM), default options
    options.kind = stereo::MatcherKind::kDense;
    options.dense.num_disparities = static_cast<int>(state.range(2));
  }
  std::unique_ptr<stereo::DisparityMatcher> matcher = stereo::MakeMatcher(options);
  for (auto _ : state)
    benchmark::DoNotOptimize(matcher->Compute(scene.frame.left, scene.frame.right));
  const std::string what = std::string(state.range(0) == 0   ? "BM block 15, "
                                       : state.range(0) == 1 ? "SGBM 3-way block 5, "
                                                             : "dense census 5 paths, ")
                               .append(std::to_string(state.range(2)))
                               .append(" disp");
  state.SetLabel(Label(state.range(1), what.c_str()));
}
BENCHMARK(BM_Matcher)
    ->ArgNames({"matcher", "size", "disp"})
    ->ArgsProduct({{0, 1, 2}, {0, 1}, {64}})
    ->ArgsProduct({{0, 1, 2}, {0}, {32, 128}})
    ->Unit(benchmark::kMillisecond);

// The block-matching core on the 640x480 pair padded as the matcher pads it, default options:
// impl 0 = cv::StereoBM on one OpenCV thread (what the matcher used before), 1 = SadBlockMatcher
// (the same output, bit for bit) on one stripe, 2 = SadBlockMatcher on a stripe per core (at most
// 4), as the matcher runs it. Speckle filtering included, texture gate and crop not.
void BM_BlockMatchingCore(benchmark::State& state) {
  const Scene& scene = SceneAt(0);
  const stereo::BlockMatchingOptions o;
  const int pad = stereo::BlockMatchingLeftPad(o);
  cv::Mat left, right, out;
  cv::copyMakeBorder(scene.frame.left, left, 0, 0, pad, 0, cv::BORDER_REPLICATE);
  cv::copyMakeBorder(scene.frame.right, right, 0, 0, pad, 0, cv::BORDER_REPLICATE);
  stereo::SadBlockMatcherParams p = stereo::SadParamsFor(o);
  if (state.range(0) == 0) {
    bench::SingleThreadScope one_thread;
    cv::Ptr<cv::StereoBM> bm = testing::StereoBMFor(p);
    for (auto _ : state) bm->compute(left, right, out);
    state.SetLabel("cv::StereoBM, 1 thread");
    return;
  }
  p.stripes = state.range(0) == 1
                  ? 1
                  : static_cast<int>(std::clamp(std::thread::hardware_concurrency(), 1u, 4u));
  stereo::SadBlockMatcher matcher(p);
  for (auto _ : state) matcher.Compute(left, right, out);
  state.SetLabel(std::string(stereo::SadBlockMatcher::UsesAvx2() ? "SadBlockMatcher AVX2, "
                                                                 : "SadBlockMatcher portable, ")
                     .append(std::to_string(p.stripes))
                     .append(p.stripes == 1 ? " stripe" : " stripes"));
}
BENCHMARK(BM_BlockMatchingCore)
    ->ArgName("impl")
    ->Arg(0)
    ->Arg(1)
    ->Arg(2)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// The extraction stage alone, on the block-matching disparity of the frame.
void BM_Extract(benchmark::State& state) {
  const Scene& scene = SceneAt(state.range(1));
  const pipeline::PipelineConfig config = ConfigFor(state.range(0), 0, 64);
  std::unique_ptr<stereo::DisparityMatcher> matcher = stereo::MakeMatcher(config.matcher);
  const stereo::DisparityMap disparity = matcher->Compute(scene.frame.left, scene.frame.right);
  const cv::Mat1b left = scene.frame.left;
  size_t detections = 0;
  for (auto _ : state) {
    std::vector<detection::Detection> found;
    switch (state.range(0)) {
      case 0:
        found = detection::DetectCanonical(disparity, *scene.rig, config.range, config.canonical);
        break;
      case 1:
        found = detection::DetectSteViE(left, disparity, *scene.rig, config.range, config.stevie);
        break;
      default:
        found = detection::DetectSteViS(left, disparity, *scene.rig, config.range, config.stevis);
        break;
    }
    detections = found.size();
    benchmark::DoNotOptimize(found);
  }
  state.counters["detections"] = static_cast<double>(detections);
  state.SetLabel(Label(state.range(1), AlgorithmLabel(state.range(0))));
}
BENCHMARK(BM_Extract)
    ->ArgNames({"alg", "size"})
    ->ArgsProduct({{0, 1, 2, 3}, {0, 1}})
    ->Unit(benchmark::kMillisecond);

// SteViE's extraction step by step at 640x480 (issue 15's speed floor: where the stage's time
// goes). step: 0 noise estimate, 1 Canny edges, 2 close-fill-open, 3 ground fit, 4 pixel classes,
// 5 RangeRegions without the sub-pixel range, 6 RangeRegions with it (the pipeline's case).
void BM_SteViESteps(benchmark::State& state) {
  const Scene& scene = SceneAt(0);
  const pipeline::PipelineConfig config = ConfigFor(1, 0, 64);
  std::unique_ptr<stereo::DisparityMatcher> matcher = stereo::MakeMatcher(config.matcher);
  const stereo::DisparityMap disparity = matcher->Compute(scene.frame.left, scene.frame.right);
  const cv::Mat1b left = scene.frame.left, right = scene.frame.right;
  const detection::SteViEOptions& o = config.stevie;
  extraction::MorphologyOptions morphology = o.morphology;
  morphology.close_size = detection::ScaledKernel(morphology.close_size, left.cols);
  morphology.open_size = detection::ScaledKernel(morphology.open_size, left.cols);
  const cv::Mat1b edges = extraction::DetectEdges(left, o.edges);
  const cv::Mat1b regions = extraction::CloseFillOpen(edges, morphology);
  const std::optional<detection::GroundModel> ground = detection::FitGround(disparity, o.ground);
  const cv::Mat1b classes =
      detection::ClassifyPixels(disparity, *scene.rig, config.range, ground, o.ground);
  const detection::FullResolutionPair full{left, right, 1};
  static const char* const kSteps[] = {"noise estimate",
                                       "Canny edges",
                                       "close-fill-open",
                                       "ground fit",
                                       "pixel classes",
                                       "RangeRegions",
                                       "RangeRegions + sub-pixel range"};
  const int64_t step = state.range(0);
  for (auto _ : state) {
    switch (step) {
      case 0: benchmark::DoNotOptimize(stereo::EstimateNoiseSigma(left)); break;
      case 1: benchmark::DoNotOptimize(extraction::DetectEdges(left, o.edges)); break;
      case 2: benchmark::DoNotOptimize(extraction::CloseFillOpen(edges, morphology)); break;
      case 3: benchmark::DoNotOptimize(detection::FitGround(disparity, o.ground)); break;
      case 4:
        benchmark::DoNotOptimize(
            detection::ClassifyPixels(disparity, *scene.rig, config.range, ground, o.ground));
        break;
      default:
        benchmark::DoNotOptimize(detection::RangeRegions(regions, classes, disparity, *scene.rig,
                                                         config.range, o.blobs, "stevie", ground,
                                                         step == 6 ? &full : nullptr));
        break;
    }
  }
  state.SetLabel(Label(0, kSteps[step]));
}
BENCHMARK(BM_SteViESteps)->ArgName("step")->DenseRange(0, 6)->Unit(benchmark::kMillisecond);

// The range scan on the block-matching disparity of the frame (issue 17). step: 0 the ground plane
// fit, 1 the scan of the pixels with that plane, 2 both (the pipeline's "scan" stage); row_step 1
// reads every row, 2 every other one.
void BM_RangeScan(benchmark::State& state) {
  const int64_t step = state.range(0), size = state.range(1);
  const Scene& scene = SceneAt(size);
  pipeline::PipelineConfig config = ConfigFor(1, 0, 64);
  config.range_scan.row_step = static_cast<int>(state.range(2));
  std::unique_ptr<stereo::DisparityMatcher> matcher = stereo::MakeMatcher(config.matcher);
  const stereo::DisparityMap disparity = matcher->Compute(scene.frame.left, scene.frame.right);
  const Eigen::Isometry3d body_from_cam = geo::BodyFromCam(config.mount);
  const Eigen::Vector3d down = body_from_cam.linear().transpose() * Eigen::Vector3d::UnitZ();
  const auto fit = [&] {
    return detection::FitGroundPlane(disparity, *scene.rig, down, config.range.min_disparity_px,
                                     config.range_scan.ground);
  };
  const std::optional<detection::GroundPlane> plane = fit();
  detection::RangeScan scan;
  for (auto _ : state) {
    if (step == 0) {
      benchmark::DoNotOptimize(fit());
    } else {
      scan = detection::ComputeRangeScan(disparity, *scene.rig, config.range, body_from_cam,
                                         step == 1 ? plane : fit(), config.range_scan);
      benchmark::DoNotOptimize(scan);
    }
  }
  static const char* const kSteps[] = {"ground plane", "scan with the plane", "plane + scan"};
  state.counters["ground"] = plane ? 1 : 0;
  state.counters["bins"] = static_cast<double>(scan.range_m.size());
  state.counters["returns"] = static_cast<double>(
      std::count_if(scan.range_m.begin(), scan.range_m.end(), [](float r) { return r > 0; }));
  state.SetLabel(Label(size, kSteps[step]) + ", row step " + std::to_string(state.range(2)));
}
BENCHMARK(BM_RangeScan)
    ->ArgNames({"step", "size", "row_step"})
    ->ArgsProduct({{0, 1, 2}, {0, 1}, {1}})
    ->ArgsProduct({{2}, {0, 1}, {2}})
    ->Unit(benchmark::kMillisecond);

// Kept from the first version of this file: canonical extraction at 640x480 with default options.
void BM_Canonical(benchmark::State& state) {
  const Scene& scene = SceneAt(0);
  std::unique_ptr<stereo::DisparityMatcher> matcher = stereo::MakeMatcher({});
  const stereo::DisparityMap disparity = matcher->Compute(scene.frame.left, scene.frame.right);
  for (auto _ : state) {
    benchmark::DoNotOptimize(detection::DetectCanonical(disparity, *scene.rig, {}, {}));
  }
}
BENCHMARK(BM_Canonical)->Unit(benchmark::kMillisecond);

// The project's VOCUS saliency (centre level 2) and its graph segmentation at graph_level 1, for
// comparison with the naive full-resolution stages below.
void BM_OurSaliency(benchmark::State& state) {
  const Scene& scene = SceneAt(0);
  const cv::Mat1b left = scene.frame.left;
  const extraction::SaliencyOptions options;
  for (auto _ : state) benchmark::DoNotOptimize(extraction::ComputeSaliency(left, options));
  state.SetLabel("640x480 VOCUS intensity, summed at level 2");
}
BENCHMARK(BM_OurSaliency)->Unit(benchmark::kMillisecond);

void BM_OurGraphSegmentation(benchmark::State& state) {
  const Scene& scene = SceneAt(0);
  const detection::SteViSOptions options;
  for (auto _ : state) {
    cv::Mat small;
    const double scale = 1.0 / (1 << options.graph_level);
    cv::resize(scene.frame.left, small, cv::Size(), scale, scale, cv::INTER_AREA);
    benchmark::DoNotOptimize(extraction::SegmentGraph(small, options.graph));
  }
  state.SetLabel("640x480 shrunk by 2^graph_level (1), Felzenszwalb-Huttenlocher");
}
BENCHMARK(BM_OurGraphSegmentation)->Unit(benchmark::kMillisecond);

// ---------------------------------------------------------------------------------------------
// The whole pipeline
// ---------------------------------------------------------------------------------------------

void BM_Pipeline(benchmark::State& state) {
  const int64_t alg = state.range(0), matcher = state.range(1), size = state.range(2);
  const Scene& scene = SceneAt(size);
  const pipeline::Snapshot snapshot{std::make_shared<const pipeline::PipelineConfig>(
                                        ConfigFor(alg, matcher, static_cast<int>(state.range(3)))),
                                    scene.rig};
  pipeline::Pipeline pipe;
  std::map<std::string, double> stage_ms;
  int64_t k = 0;
  for (auto _ : state) {
    StereoFrame frame = scene.sequence[static_cast<size_t>(k % kSequenceFrames)];
    frame.t_ns = k * 100'000'000;  // 10 fps, increasing across the cycles
    ++k;
    Result<pipeline::FrameResult> result = pipe.Process(frame, snapshot);
    if (!result.ok()) {
      state.SkipWithError(result.error().message.c_str());
      break;
    }
    for (const pipeline::StageTiming& t : result->timings) stage_ms[t.stage] += t.ms;
    benchmark::DoNotOptimize(result);
  }
  for (const auto& [stage, ms] : stage_ms) {
    state.counters[stage + "_ms"] = benchmark::Counter(ms, benchmark::Counter::kAvgIterations);
  }
  const std::string what = std::string(AlgorithmLabel(alg))
                               .append(matcher == 0 ? " + BM " : " + SGBM ")
                               .append(std::to_string(state.range(3)))
                               .append(" disp");
  state.SetLabel(Label(size, what.c_str()));
}
BENCHMARK(BM_Pipeline)
    ->ArgNames({"alg", "matcher", "size", "disp"})
    ->ArgsProduct({{0, 1, 2, 3}, {0, 1}, {0, 1}, {64}})
    ->ArgsProduct({{1}, {0, 1}, {0}, {32, 128}})
    ->Unit(benchmark::kMillisecond);

// ---------------------------------------------------------------------------------------------
// Tracking: Tracker::Update with N moving targets (confirmed tracks after the warm-up).
// ---------------------------------------------------------------------------------------------

void BM_Tracker(benchmark::State& state) {
  const tracking::CameraModel camera{700.0, 320.0, 240.0, 0.6, 640, 480};
  bench::MovingTargets targets(static_cast<int>(state.range(0)), camera);
  constexpr double kDt = 0.1;
  tracking::Tracker tracker;
  int64_t frame = 0;
  for (; frame < 10; ++frame) {  // warm-up: tracks confirmed
    tracker.Update(targets.Detections(frame, kDt), static_cast<int64_t>(frame * kDt * 1e9), camera);
  }
  // The detections are drawn outside the timed region.
  std::vector<detection::Detection> detections = targets.Detections(frame, kDt);
  size_t tracks = 0;
  for (auto _ : state) {
    const std::vector<tracking::Track> out =
        tracker.Update(detections, static_cast<int64_t>(frame * kDt * 1e9), camera);
    tracks = out.size();
    state.PauseTiming();
    ++frame;
    detections = targets.Detections(frame, kDt);
    state.ResumeTiming();
  }
  state.counters["tracks"] = static_cast<double>(tracks);
  state.SetLabel(std::to_string(state.range(0)).append(" moving targets, 10 fps"));
}
BENCHMARK(BM_Tracker)->ArgName("targets")->Arg(10)->Arg(100)->Unit(benchmark::kMicrosecond);

// ---------------------------------------------------------------------------------------------
// The naive thesis baseline at 640x480, one OpenCV thread (naive_baseline.h).
// ---------------------------------------------------------------------------------------------

struct Naive {
  Naive() {
    const Scene& scene = SceneAt(0);
    Result<geometry::StereoRig> rig = bench::RawRigLike(*scene.rig);
    pipe = std::make_unique<bench::NaiveThesisPipeline>(rig.ok() ? *rig : *scene.rig);
  }
  std::unique_ptr<bench::NaiveThesisPipeline> pipe;
};

bench::NaiveThesisPipeline& TheNaive() {
  static Naive naive;
  return *naive.pipe;
}

void BM_NaiveRectify(benchmark::State& state) {
  const Scene& scene = SceneAt(0);
  bench::NaiveThesisPipeline& naive = TheNaive();
  const bench::SingleThreadScope one_thread;
  cv::Mat left, right;
  for (auto _ : state) {
    naive.Rectify(scene.frame.left, scene.frame.right, left, right);
    benchmark::DoNotOptimize(left.data);
  }
  state.SetLabel("640x480 1 thread cv::remap float maps, both images");
}
BENCHMARK(BM_NaiveRectify)->Unit(benchmark::kMillisecond);

void BM_NaiveSgbm(benchmark::State& state) {
  const Scene& scene = SceneAt(0);
  bench::NaiveThesisPipeline& naive = TheNaive();
  const bench::SingleThreadScope one_thread;
  for (auto _ : state)
    benchmark::DoNotOptimize(naive.Disparity(scene.frame.left, scene.frame.right));
  state.SetLabel("640x480 1 thread StereoSGBM MODE_SGBM 5-path, 64 disp");
}
BENCHMARK(BM_NaiveSgbm)->Unit(benchmark::kMillisecond);

void BM_NaiveSaliency(benchmark::State& state) {
  const Scene& scene = SceneAt(0);
  bench::NaiveThesisPipeline& naive = TheNaive();
  const bench::SingleThreadScope one_thread;
  for (auto _ : state) benchmark::DoNotOptimize(naive.Saliency(scene.frame.left));
  state.SetLabel("640x480 1 thread StaticSaliencyFineGrained, full resolution");
}
BENCHMARK(BM_NaiveSaliency)->Unit(benchmark::kMillisecond);

void BM_NaiveGraphSegmentation(benchmark::State& state) {
  const Scene& scene = SceneAt(0);
  bench::NaiveThesisPipeline& naive = TheNaive();
  const bench::SingleThreadScope one_thread;
  for (auto _ : state) benchmark::DoNotOptimize(naive.Segment(scene.frame.left));
  state.SetLabel("640x480 1 thread GraphSegmentation, full resolution");
}
BENCHMARK(BM_NaiveGraphSegmentation)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
