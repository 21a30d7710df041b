// stevi-eval: runs the pipeline over the synthetic scene and prints detection quality against the
// truth (recall, precision, depth error by distance band) and the time per stage, for each matcher.
//
// Matching rule: a detection matches a truth obstacle when their boxes overlap with IoU >= 0.3,
// one-to-one, best IoU first. An obstacle is expected when at least 300 of its pixels are visible
// and its truth disparity is at least 8 px. Unmatched detections count against precision.
//
// Usage: stevi-eval [--frames N] [--fps F]   (default 200 frames at 10 fps: 20 s of the scene)
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <string>
#include <vector>

#include "core/pipeline/pipeline.h"
#include "drivers/synthetic/synthetic_source.h"
#include "tests/testing/truth_match.h"

namespace {

using namespace stevi;

struct Band {
  double lo_m, hi_m;
  std::vector<double> errors_pct;  // signed relative depth errors
};

struct Totals {
  int expected = 0, matched = 0, detections = 0;
  std::vector<Band> bands{{15, 25, {}}, {25, 35, {}}, {35, 45, {}}, {45, 55, {}}};
  std::map<std::string, double> stage_ms;
  int frames = 0;
};

void Evaluate(const pipeline::FrameResult& result, const drivers::FrameTruth& truth, double fB,
              Totals& totals) {
  std::vector<cv::Rect> boxes, truth_boxes;
  std::vector<const drivers::ObstacleTruth*> expected;
  for (const detection::Detection& d : result.detections) boxes.push_back(d.bbox);
  for (const drivers::ObstacleTruth& o : truth.obstacles) {
    if (o.visible_px < 300 || fB / o.depth_m < 8.0) continue;
    expected.push_back(&o);
    truth_boxes.push_back(o.bbox);
  }
  totals.expected += static_cast<int>(expected.size());
  totals.detections += static_cast<int>(boxes.size());
  for (const auto& [d, t] : testing::MatchByIoU(boxes, truth_boxes, 0.3)) {
    ++totals.matched;
    const double truth_depth = expected[t]->depth_m;
    const double error = 100 * (result.detections[d].depth_m - truth_depth) / truth_depth;
    for (Band& band : totals.bands) {
      if (truth_depth >= band.lo_m && truth_depth < band.hi_m) band.errors_pct.push_back(error);
    }
  }
  for (const pipeline::StageTiming& t : result.timings) totals.stage_ms[t.stage] += t.ms;
  ++totals.frames;
}

double Rms(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x * x;
  return v.empty() ? 0 : std::sqrt(s / v.size());
}

double MaxAbs(const std::vector<double>& v) {
  double m = 0;
  for (double x : v) m = std::max(m, std::abs(x));
  return m;
}

}  // namespace

int main(int argc, char** argv) {
  int frames = 200;
  double fps = 10;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string flag = argv[i];
    if (flag == "--frames") frames = std::max(1, std::atoi(argv[i + 1]));
    else if (flag == "--fps") fps = std::max(0.1, std::atof(argv[i + 1]));
    else {
      std::fprintf(stderr, "usage: stevi-eval [--frames N] [--fps F]\n");
      return 2;
    }
  }
  drivers::SyntheticOptions options;
  options.fps = fps;
  drivers::SyntheticRenderer renderer(options);
  const auto rig = std::make_shared<const geometry::StereoRig>(renderer.Rig());
  const double fB = options.f_px * options.baseline_m;

  std::printf("synthetic scene: %dx%d, f=%.0f px, B=%.2f m, %d frames at %.0f fps, noise %.1f\n",
              options.width, options.height, options.f_px, options.baseline_m, frames, fps,
              options.noise_sigma);
  std::printf("rule: IoU >= 0.3 one-to-one; expected = visible >= 300 px and disparity >= 8 px\n\n");

  struct Variant {
    std::string name;
    pipeline::PipelineConfig config;
  };
  std::vector<Variant> variants(2);
  variants[0].name = "canonical + BM";
  variants[1].name = "canonical + SGBM";
  variants[1].config.matcher.kind = stereo::MatcherKind::kSemiGlobal;

  for (const Variant& variant : variants) {
    pipeline::Pipeline pipe;
    const pipeline::Snapshot snapshot{
        std::make_shared<const pipeline::PipelineConfig>(variant.config), rig};
    Totals totals;
    for (int k = 0; k < frames; ++k) {
      drivers::FrameTruth truth;
      const StereoFrame frame = renderer.Render(k, &truth);
      Result<pipeline::FrameResult> result = pipe.Process(frame, snapshot);
      if (!result.ok()) {
        std::fprintf(stderr, "frame %d: %s\n", k, result.error().message.c_str());
        return 1;
      }
      Evaluate(*result, truth, fB, totals);
    }
    const double recall = totals.expected ? 100.0 * totals.matched / totals.expected : 0;
    const double precision = totals.detections ? 100.0 * totals.matched / totals.detections : 0;
    std::printf("%s: recall %.1f %% (%d/%d), precision %.1f %% (%d detections)\n",
                variant.name.c_str(), recall, totals.matched, totals.expected, precision,
                totals.detections);
    std::printf("  depth band   matched  rms err %%  max err %%  within 2 %%\n");
    for (const Band& band : totals.bands) {
      const int within = static_cast<int>(std::count_if(
          band.errors_pct.begin(), band.errors_pct.end(), [](double e) { return std::abs(e) <= 2; }));
      std::printf("  %4.0f-%-4.0f m  %7zu  %9.2f  %9.2f  %8.1f %%\n", band.lo_m, band.hi_m,
                  band.errors_pct.size(), Rms(band.errors_pct), MaxAbs(band.errors_pct),
                  band.errors_pct.empty() ? 0.0 : 100.0 * within / band.errors_pct.size());
    }
    std::printf("  mean ms per frame:");
    for (const std::string stage : {"rectify", "disparity", "extract", "total"}) {
      std::printf(" %s %.2f", stage.c_str(), totals.stage_ms[stage] / totals.frames);
    }
    std::printf("\n\n");
  }
  return 0;
}
