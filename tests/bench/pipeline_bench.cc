// Google Benchmark cases for the stages at 640x480 on the synthetic scene. Compare ratios measured
// in the same run; the machine is noisy.
#include <benchmark/benchmark.h>

#include <memory>

#include "core/detection/canonical.h"
#include "core/pipeline/pipeline.h"
#include "drivers/synthetic/synthetic_source.h"

namespace {

using namespace stevi;

struct Scene {
  drivers::SyntheticRenderer renderer{drivers::SyntheticOptions{}};
  StereoFrame frame = renderer.Render(50);
  std::shared_ptr<const geometry::StereoRig> rig =
      std::make_shared<const geometry::StereoRig>(renderer.Rig());
};

const Scene& TheScene() {
  static const Scene scene;
  return scene;
}

void BM_Render(benchmark::State& state) {
  const Scene& scene = TheScene();
  int64_t k = 0;
  for (auto _ : state) benchmark::DoNotOptimize(scene.renderer.Render(k++));
}
BENCHMARK(BM_Render)->Unit(benchmark::kMillisecond);

void BM_Matcher(benchmark::State& state) {
  const Scene& scene = TheScene();
  stereo::MatcherOptions options;
  options.kind = state.range(0) == 0 ? stereo::MatcherKind::kBlockMatching
                                     : stereo::MatcherKind::kSemiGlobal;
  std::unique_ptr<stereo::DisparityMatcher> matcher = stereo::MakeMatcher(options);
  for (auto _ : state) benchmark::DoNotOptimize(matcher->Compute(scene.frame.left, scene.frame.right));
  state.SetLabel(options.kind == stereo::MatcherKind::kBlockMatching ? "BM block 15, 64 disp"
                                                                     : "SGBM 3-way, 64 disp");
}
BENCHMARK(BM_Matcher)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

void BM_Canonical(benchmark::State& state) {
  const Scene& scene = TheScene();
  std::unique_ptr<stereo::DisparityMatcher> matcher = stereo::MakeMatcher({});
  const stereo::DisparityMap disparity = matcher->Compute(scene.frame.left, scene.frame.right);
  for (auto _ : state) {
    benchmark::DoNotOptimize(detection::DetectCanonical(disparity, *scene.rig, {}, {}));
  }
}
BENCHMARK(BM_Canonical)->Unit(benchmark::kMillisecond);

void BM_Pipeline(benchmark::State& state) {
  const Scene& scene = TheScene();
  pipeline::PipelineConfig config;
  if (state.range(0) == 1) config.matcher.kind = stereo::MatcherKind::kSemiGlobal;
  const pipeline::Snapshot snapshot{std::make_shared<const pipeline::PipelineConfig>(config),
                                    scene.rig};
  pipeline::Pipeline pipe;
  for (auto _ : state) benchmark::DoNotOptimize(pipe.Process(scene.frame, snapshot));
  state.SetLabel(state.range(0) == 0 ? "canonical + BM" : "canonical + SGBM");
}
BENCHMARK(BM_Pipeline)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
