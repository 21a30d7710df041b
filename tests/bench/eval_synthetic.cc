// stevi-eval: runs every detector over the synthetic evaluation scenarios and prints detection
// quality against the truth (recall, precision, depth error by distance band) and time per stage.
//
// Matching rule: a detection matches a truth obstacle when their boxes overlap with IoU >= 0.3,
// one-to-one, best IoU first. An obstacle is expected when at least 300 of its pixels are visible
// (the smallest scenario aircraft shows about 160: the rule drops to 100 px there, see kMinVisible)
// and its truth disparity is at least 8 px. Unmatched detections count against precision.
//
// Usage: stevi-eval [--frames N] [--scenario NAME] [--algorithm NAME] [--size WxH]
//   --frames caps the frames per scenario (default: each scenario's own length; the demo scene 200)
//   --size renders the scenarios at WxH with the focal length scaled by W / (the scenario's width),
//   so the horizontal field of view stays; the expectation rule scales with it (visible pixels by
//   the square of the scale, disparity by the scale), so the same obstacles are expected.
//   --max-width sets PipelineConfig::max_width_px (frames wider are binned; 0 = never bin), to
//   compare binned and unbinned at --size.
//
// Family mode: stevi-eval --family sky|airfield|long_range|close|all --seeds A-B [--frames N]
//   [--algorithm NAME] [--max-width N] [--json FILE] [--dump DIR] [--dump-scenes N]
//   [--scene-frames N] [--confirm-window N]
//   runs the detectors over the randomised scene families (drivers/synthetic/random_scenes.h) for
//   seeds A..B of each family and prints a table per family and for all (see eval_family.cc and
//   tests/bench/README.md). Seeds 1-999 are the TUNING split; seeds 1001 and up are the TEST
//   split: report on it, never tune on it (no parameter, threshold or rule may be chosen by
//   looking at test-split results or pictures). --dump writes the last frame of the first N
//   scenes (default 3) of each family per algorithm as PNG: truth boxes green (dark green: not
//   expected), detections red (orange: don't care) with their depth. A track-level table follows
//   (tests/testing/track_level.h: obstacles confirmed within --confirm-window N frames, default 5,
//   false confirmed tracks per 1000 frames, range error over sigma); --scene-frames N renders N
//   frames of every scene instead of its own 4..6 (the obstacles continue on their paths).
//   --algorithm takes any name the pipeline knows (PipelineConfig::kAlgorithmNames) or
//   stevis-graph.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <string>
#include <vector>

#include "core/pipeline/pipeline.h"
#include "drivers/synthetic/random_scenes.h"
#include "drivers/synthetic/synthetic_source.h"
#include "tests/bench/eval_family.h"
#include "tests/bench/eval_flags.h"
#include "tests/testing/truth_match.h"

namespace {

using namespace stevi;

constexpr int kMinVisible = 100;

struct Band {
  double lo_m, hi_m;
  std::vector<double> errors_pct;  // signed relative depth errors
};

struct Totals {
  int expected = 0, matched = 0, detections = 0, frames = 0;
  std::vector<Band> bands{{0, 25, {}}, {25, 35, {}}, {35, 45, {}}, {45, 60, {}}};
  std::map<std::string, double> stage_ms;

  void Add(const Totals& o) {
    expected += o.expected;
    matched += o.matched;
    detections += o.detections;
    frames += o.frames;
    for (size_t i = 0; i < bands.size(); ++i) {
      bands[i].errors_pct.insert(bands[i].errors_pct.end(), o.bands[i].errors_pct.begin(),
                                 o.bands[i].errors_pct.end());
    }
    for (const auto& [stage, ms] : o.stage_ms) stage_ms[stage] += ms;
  }
  double recall() const { return expected ? 100.0 * matched / expected : 100.0; }
  double precision() const { return detections ? 100.0 * matched / detections : 100.0; }
};

// `scale`: the rendering's focal length over the scenario's own (1 at the scenario's size).
void Evaluate(const pipeline::FrameResult& result, const drivers::FrameTruth& truth, double fB,
              double scale, Totals& totals) {
  std::vector<cv::Rect> boxes, truth_boxes;
  std::vector<const drivers::ObstacleTruth*> expected;
  // Boxes in the camera's pixels (the pipeline bins frames wider than max_width_px).
  const int bin = result.binning;
  for (const detection::Detection& d : result.detections) {
    boxes.emplace_back(d.bbox.x * bin, d.bbox.y * bin, d.bbox.width * bin, d.bbox.height * bin);
  }
  for (const drivers::ObstacleTruth& o : truth.obstacles) {
    if (o.visible_px < kMinVisible * scale * scale || fB / o.depth_m < 8.0 * scale) continue;
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

struct Variant {
  std::string name;
  pipeline::PipelineConfig config;
};

std::vector<Variant> Variants() {
  std::vector<Variant> v(4);
  v[0].name = "canonical";
  v[1].name = "stevie";
  v[1].config.algorithm = pipeline::Algorithm::kSteViE;
  v[2].name = "stevis";
  v[2].config.algorithm = pipeline::Algorithm::kSteViS;
  v[3].name = "stevis-graph";
  v[3].config.algorithm = pipeline::Algorithm::kSteViS;
  v[3].config.stevis.segmentation = detection::SteViSOptions::Segmentation::kGraph;
  // Every other algorithm the pipeline knows by name (e.g. a new default), with its defaults.
  for (const auto& choice : pipeline::PipelineConfig::kAlgorithmNames) {
    const std::string name(choice.name);
    if (std::none_of(v.begin(), v.end(), [&](const Variant& x) { return x.name == name; })) {
      Variant extra;
      extra.name = name;
      extra.config = pipeline::ConfigForAlgorithm(choice.value);
      v.push_back(extra);
    }
  }
  return v;
}

constexpr char kUsage[] =
    "usage: stevi-eval [--frames N] [--scenario NAME] "
    "[--algorithm canonical|stevie|stevis|stevis-graph|stixels] [--size WxH] [--max-width N]\n"
    "       stevi-eval --family sky|airfield|long_range|close|all --seeds A-B "
    "[--frames N] [--algorithm NAME] [--max-width N] [--json FILE] [--dump DIR] "
    "[--dump-scenes N] [--scene-frames N] [--confirm-window N]\n"
    "  --set path=value (repeatable): a pipeline setting over each algorithm's own\n"
    "  seeds 1-999: the tuning split; seeds 1001 and up: the TEST split, never to be "
    "tuned on\n";

}  // namespace

int main(int argc, char** argv) {
  int max_frames = 0;
  std::string only_scenario, only_algorithm;
  const auto usage = [](const std::string& problem) {
    std::fprintf(stderr, "stevi-eval: %s\n%s", problem.c_str(), kUsage);
    return 2;
  };
  bench::EvalFlags flags =
      bench::ParseEvalFlagsOrExit("stevi-eval", kUsage, argc, argv, false, true, true);
  if (!flags.family.empty() || !flags.seeds.empty()) {
    bench::FamilyEvalOptions fo;
    const std::vector<std::string>& families = drivers::RandomSceneFamilies();
    if (flags.family == "all") {
      fo.families = families;
    } else if (std::find(families.begin(), families.end(), flags.family) != families.end()) {
      fo.families = {flags.family};
    } else {
      return usage("--family: expected sky, airfield, long_range, close or all, got '" +
                   flags.family + "'");
    }
    if (flags.seeds.empty()) flags.seeds = "1-40";
    if (!bench::ParseSeedRange(flags.seeds, fo.seed_first, fo.seed_last)) {
      return usage("--seeds: expected A-B with A <= B, got '" + flags.seeds + "'");
    }
    if (!flags.scenario.empty() || flags.width > 0) {
      return usage("--scenario and --size do not apply to --family");
    }
    fo.max_frames = flags.max_frames;
    fo.scene_frames = flags.scene_frames;
    fo.confirm_window = flags.confirm_window;
    fo.max_width_px = flags.max_width_px;
    fo.json_path = flags.json;
    fo.dump_dir = flags.dump;
    fo.dump_scenes = flags.dump_scenes;
    std::vector<bench::EvalVariant> variants;
    for (Variant& v : Variants()) {
      bench::ApplySettingFlags(flags, v.config);
      if (flags.algorithm.empty() || v.name == flags.algorithm)
        variants.push_back({v.name, v.config});
    }
    if (variants.empty()) return usage("unknown algorithm '" + flags.algorithm + "'");
    return bench::RunFamilyEval(fo, variants);
  }
  if (!flags.json.empty() || !flags.dump.empty()) {
    return usage("--json and --dump need --family");
  }
  max_frames = flags.max_frames;
  only_scenario = flags.scenario;
  only_algorithm = flags.algorithm;

  std::vector<drivers::Scenario> scenarios = drivers::EvaluationScenarios();
  drivers::Scenario demo;
  demo.name = "demo";
  demo.description = "the server's default scene (20 s loop)";
  demo.frames = 200;
  scenarios.insert(scenarios.begin(), demo);
  if (const std::string problem = bench::UnknownScenario(scenarios, only_scenario);
      !problem.empty()) {
    return usage(problem);
  }
  std::vector<Variant> variants = Variants();
  for (Variant& v : variants) bench::ApplySettingFlags(flags, v.config);
  if (!only_algorithm.empty() &&
      std::none_of(variants.begin(), variants.end(),
                   [&](const Variant& v) { return v.name == only_algorithm; })) {
    return usage("unknown algorithm '" + only_algorithm + "'");
  }

  std::printf(
      "rule: IoU >= 0.3 one-to-one; expected = visible >= %d px and disparity >= 8 px; "
      "matcher BM (default)\n",
      kMinVisible);
  if (flags.width > 0) {
    std::printf("size: %dx%d, focal length scaled by width / 640 (the rule's pixels with it)\n",
                flags.width, flags.height);
  }
  const int max_width_px = flags.max_width_px.value_or(pipeline::PipelineConfig{}.max_width_px);
  std::printf("max_width_px: %d (frames wider are binned%s)\n", max_width_px,
              max_width_px == 0 ? "; 0 = never" : "");
  std::printf("\n");
  std::printf("%-16s %-13s %7s %9s %7s %10s %9s %9s %9s\n", "scenario", "algorithm", "frames",
              "expected", "recall", "precision", "depth rms", "depth max", "extract");
  std::map<std::string, Totals> overall;
  for (const drivers::Scenario& scenario : scenarios) {
    if (!only_scenario.empty() && scenario.name != only_scenario) continue;
    drivers::SyntheticOptions options = scenario.options;
    double scale = 1.0;
    if (flags.width > 0) {
      scale = static_cast<double>(flags.width) / options.width;
      options.width = flags.width;
      options.height = flags.height;
      options.f_px *= scale;
    }
    drivers::SyntheticRenderer renderer(options);
    const auto rig = std::make_shared<const geometry::StereoRig>(renderer.Rig());
    const double fB = options.f_px * options.baseline_m;
    const int frames = max_frames > 0 ? std::min(max_frames, scenario.frames) : scenario.frames;
    std::vector<StereoFrame> rendered;
    std::vector<drivers::FrameTruth> truths(frames);
    for (int k = 0; k < frames; ++k) rendered.push_back(renderer.Render(k, &truths[k]));
    for (const Variant& variant : variants) {
      if (!only_algorithm.empty() && variant.name != only_algorithm) continue;
      pipeline::Pipeline pipe;
      pipeline::PipelineConfig config = variant.config;
      config.max_width_px = max_width_px;
      const pipeline::Snapshot snapshot{std::make_shared<const pipeline::PipelineConfig>(config),
                                        rig};
      Totals totals;
      for (int k = 0; k < frames; ++k) {
        Result<pipeline::FrameResult> result = pipe.Process(rendered[k], snapshot);
        if (!result.ok()) {
          std::fprintf(stderr, "%s frame %d: %s\n", scenario.name.c_str(), k,
                       result.error().message.c_str());
          return 1;
        }
        Evaluate(*result, truths[k], fB, scale, totals);
      }
      std::vector<double> all;
      for (const Band& b : totals.bands)
        all.insert(all.end(), b.errors_pct.begin(), b.errors_pct.end());
      std::printf("%-16s %-13s %7d %9d %6.1f%% %9.1f%% %8.2f%% %8.2f%% %6.1f ms\n",
                  scenario.name.c_str(), variant.name.c_str(), totals.frames, totals.expected,
                  totals.recall(), totals.precision(), Rms(all), MaxAbs(all),
                  totals.stage_ms["extract"] / totals.frames);
      overall[variant.name].Add(totals);
    }
  }

  std::printf(
      "\nall scenarios: recall, precision, depth error (rms / max) by band, mean ms per stage\n");
  for (const Variant& variant : variants) {
    auto it = overall.find(variant.name);
    if (it == overall.end()) continue;
    const Totals& t = it->second;
    std::printf("%-13s recall %5.1f%%  precision %5.1f%% ", variant.name.c_str(), t.recall(),
                t.precision());
    for (const Band& b : t.bands) {
      std::printf(" %2.0f-%2.0f m %.2f/%.2f%%", b.lo_m, b.hi_m, Rms(b.errors_pct),
                  MaxAbs(b.errors_pct));
    }
    std::printf("\n              ");
    for (const std::string stage : {"rectify", "disparity", "extract", "total"}) {
      std::printf(" %s %.2f ms", stage.c_str(),
                  t.stage_ms.count(stage) ? t.stage_ms.at(stage) / t.frames : 0.0);
    }
    std::printf("\n");
  }
  return 0;
}
