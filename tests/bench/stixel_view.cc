// stevi-stixel-view: the stixel world and its obstacles on the KITTI 2015 pairs of the shared data,
// drawn and scored against the truth obstacles (tests/testing/gt_obstacles.h), to look at.
//
//   stevi-stixel-view [--out DIR] [--set path=value]... [--jpeg]
//                     [--synthetic FAMILY SEED]   (one frame of a random scene: disparity,
//                                                  confidence and stixels, the truth boxes green)
//
// The configuration is the stixels algorithm's own (pipeline::ConfigForAlgorithm: the dense
// matcher); --set changes any setting by its option-table path ("stixels.segment_penalty=5",
// "matcher.kind=semi_global").
//
// Writes DIR/PAIR-stixels.png: the left image with ground stixels green, object stixels coloured
// by disparity, the obstacles' boxes (red: matched to a truth obstacle, orange: fragment, magenta:
// false on free ground, cyan: other false) with their depth, and the truth boxes in thin green.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/flags.h"
#include "core/pipeline/config.h"
#include "core/pipeline/pipeline.h"
#include "drivers/synthetic/random_scenes.h"
#include "drivers/synthetic/synthetic_source.h"
#include "tests/testing/data.h"
#include "tests/testing/gt_obstacles.h"
#include "tests/testing/real_pairs.h"

namespace stevi {
namespace {

cv::Scalar VerdictColour(testing::BoxVerdict v) {
  switch (v) {
    case testing::BoxVerdict::kMatched: return {0, 0, 255};
    case testing::BoxVerdict::kFragment: return {0, 165, 255};
    case testing::BoxVerdict::kFpFree: return {255, 0, 255};
    default: return {255, 255, 0};
  }
}

void DrawStixels(const pipeline::FrameResult& r, int bin, cv::Mat3b& out) {
  if (!r.stixels) return;
  const double max_d = r.disparity.min_disparity + r.disparity.num_disparities;
  cv::Mat3b overlay = out.clone();
  for (const detection::Stixel& s : r.stixels->stixels) {
    const cv::Rect rect(s.x0 * bin, s.top_row * bin, s.width * bin,
                        (s.bottom_row - s.top_row + 1) * bin);
    if (s.label == detection::StixelClass::kGround) {
      cv::rectangle(overlay, rect, {0, 160, 0}, cv::FILLED);
    } else if (s.label == detection::StixelClass::kObject) {
      cv::Mat1b v(1, 1, static_cast<uchar>(std::clamp(255.0 * s.disparity_px / max_d, 0.0, 255.0)));
      cv::Mat3b c;
      cv::applyColorMap(v, c, cv::COLORMAP_TURBO);
      cv::rectangle(overlay, rect, cv::Scalar(c(0, 0)), cv::FILLED);
    }
  }
  cv::addWeighted(overlay, 0.45, out, 0.55, 0, out);
}

// One frame of a random synthetic scene: the disparity, its confidence and the stixel world.
int RunSynthetic(const std::string& family, uint64_t seed, const pipeline::PipelineConfig& base,
                 const std::string& out_dir) {
  // "demo": the server's built-in scene (SyntheticOptions' defaults), frame `seed`; a tracking
  // scenario by its name, frame `seed`; else a random family's scene `seed`, frame 0.
  drivers::Scenario scenario;
  bool by_frame = family == "demo";
  for (const drivers::Scenario& t : drivers::TrackingScenarios()) {
    if (t.name == family) {
      scenario = t;
      by_frame = true;
    }
  }
  if (!by_frame) scenario = drivers::RandomScenario(family, seed);
  drivers::SyntheticRenderer renderer(scenario.options);
  pipeline::PipelineConfig config = base;
  config.mount.pitch_deg = scenario.options.scene.camera_pitch_deg;
  const pipeline::Snapshot snapshot{std::make_shared<const pipeline::PipelineConfig>(config),
                                    std::make_shared<const geometry::StereoRig>(renderer.Rig())};
  pipeline::Pipeline pipe;
  drivers::FrameTruth truth;
  Result<pipeline::FrameResult> result =
      pipe.Process(renderer.Render(by_frame ? static_cast<int64_t>(seed) : 0, &truth), snapshot);
  if (!result.ok()) {
    std::fprintf(stderr, "%s\n", result.error().message.c_str());
    return 1;
  }
  const pipeline::FrameResult& r = result.value();
  const std::string stem = out_dir + "/" + family + "-" + std::to_string(seed);
  {
    // The matched disparities of the sky (truth 0) among the trusted pixels.
    const double s = static_cast<double>(r.disparity.fixed.cols) / truth.disparity_px.cols;
    int hist[8] = {0}, n = 0;
    for (int v = 0; v < r.disparity.fixed.rows; ++v) {
      for (int u = 0; u < r.disparity.fixed.cols; ++u) {
        if (truth.object_id(static_cast<int>(v / s), static_cast<int>(u / s)) != -1) continue;
        const std::optional<float> m = r.disparity.At(u, v);
        if (!m || r.disparity.confidence(v, u) < 128) continue;
        ++n;
        ++hist[std::min(7, static_cast<int>(*m))];
      }
    }
    std::printf(
        "  trusted sky px %d: d in [0,1) %d [1,2) %d [2,3) %d [3,4) %d [4,5) %d [5,6) %d "
        ">=6 %d (binned image: x%.2f)\n",
        n, hist[0], hist[1], hist[2], hist[3], hist[4], hist[5], hist[6] + hist[7], s);
  }
  if (r.ground) {
    // Where the fitted plane and the exact ground disparity part (scaled when processed smaller).
    const double s = static_cast<double>(r.disparity.fixed.cols) / truth.disparity_px.cols;
    std::vector<double> dev, err;
    int n_trusted = 0, n_bad = 0;
    for (int v = 0; v < truth.disparity_px.rows; v += 4) {
      for (int u = 0; u < truth.disparity_px.cols; u += 4) {
        if (truth.object_id(v, u) != 0) continue;
        const double t = truth.disparity_px(v, u) * s;
        dev.push_back(r.ground->DisparityAt(u * s, v * s) - t);
        const std::optional<float> m =
            r.disparity.At(static_cast<int>(u * s), static_cast<int>(v * s));
        const bool trusted =
            r.disparity.confidence.empty() ||
            r.disparity.confidence(static_cast<int>(v * s), static_cast<int>(u * s)) >= 128;
        if (m && trusted) err.push_back(*m - t);
        if (m && trusted) ++n_trusted;
        if (m && trusted && std::abs(*m - t) > 3) ++n_bad;
      }
    }
    auto pct = [](std::vector<double> x, double q) {
      if (x.empty()) return 0.0;
      std::sort(x.begin(), x.end());
      return x[static_cast<size_t>(q * (x.size() - 1))];
    };
    std::printf(
        "  ground plane - truth on ground px: p10 %.2f p50 %.2f p90 %.2f; matched - truth: p10 "
        "%.2f p50 %.2f p90 %.2f (n %zu)\n",
        pct(dev, .1), pct(dev, .5), pct(dev, .9), pct(err, .1), pct(err, .5), pct(err, .9),
        err.size());
    std::printf("  trusted ground px off by > 3 px: %.1f %%\n",
                100.0 * n_bad / std::max(1, n_trusted));
  }
  cv::imwrite(stem + "-disparity.png", stereo::ToColour(r.disparity));
  if (!r.disparity.confidence.empty())
    cv::imwrite(stem + "-confidence.png", r.disparity.confidence);
  cv::Mat3b out;
  cv::cvtColor(r.rectified_left, out, cv::COLOR_GRAY2BGR);
  DrawStixels(r, 1, out);
  for (const drivers::ObstacleTruth& o : truth.obstacles) {
    if (o.visible_px <= 0) continue;
    const double k = static_cast<double>(out.cols) / truth.object_id.cols;  // binned
    cv::rectangle(
        out,
        cv::Rect(cv::Point(static_cast<int>(o.bbox.x * k), static_cast<int>(o.bbox.y * k)),
                 cv::Size(static_cast<int>(o.bbox.width * k), static_cast<int>(o.bbox.height * k))),
        {0, 255, 0}, 1);
    std::printf("  truth %-10s %-9s box %3d,%3d %3dx%3d  %6d px  depth %.1f m  disparity %.2f px\n",
                o.name.c_str(), o.kind.c_str(), o.bbox.x, o.bbox.y, o.bbox.width, o.bbox.height,
                o.visible_px, o.depth_m, o.median_disparity_px);
  }
  for (const detection::Detection& d : r.detections) {
    cv::rectangle(out, d.bbox, {0, 0, 255}, 1);
    char label[32];
    std::snprintf(label, sizeof label, "%.1f", d.depth_m);
    cv::putText(out, label, d.bbox.tl() + cv::Point(2, 12), cv::FONT_HERSHEY_SIMPLEX, 0.4,
                {0, 0, 255}, 1);
  }
  cv::imwrite(stem + "-stixels.png", out);
  // The false boxes (on no truth obstacle) by what lies under them in the truth: sky or ground.
  {
    const double k = static_cast<double>(truth.object_id.cols) / out.cols;
    for (const detection::Detection& d : r.detections) {
      const cv::Rect b(
          cv::Point(static_cast<int>(d.bbox.x * k), static_cast<int>(d.bbox.y * k)),
          cv::Size(static_cast<int>(d.bbox.width * k), static_cast<int>(d.bbox.height * k)));
      int sky = 0, ground = 0, object = 0;
      for (int y = b.y; y < b.y + b.height; ++y)
        for (int x = b.x; x < b.x + b.width; ++x) {
          const int id = truth.object_id(y, x);
          (id < 0 ? sky : id == 0 ? ground : object)++;
        }
      if (object * 4 > b.area()) continue;
      std::printf("  FALSE %s d %.2f px (depth %.0f m) %dx%d cols %d\n",
                  sky > ground ? "sky   " : "ground", d.disparity_px, d.depth_m, d.bbox.width,
                  d.bbox.height, d.bbox.width / 8);
    }
  }
  double extract_ms = 0;
  for (const pipeline::StageTiming& t : r.timings) {
    if (t.stage == "extract") extract_ms = t.ms;
  }
  std::printf("%s %llu: %zu detections, ground %s, extract %.1f ms\n", family.c_str(),
              static_cast<unsigned long long>(seed), r.detections.size(), r.ground ? "yes" : "no",
              extract_ms);
  return 0;
}

constexpr char kUsage[] =
    "usage: stevi-stixel-view [--out DIR] [--set path=value]... [--jpeg] "
    "[--synthetic FAMILY SEED]\n";

// --synthetic's SEED: a random family's scene, or the frame of demo or a tracking scenario.
constexpr flags::WholeRange kSeedRange{.lo = 0, .what = "a whole seed or frame"};

struct Options {
  std::string out_dir = "/tmp/stixels";
  std::vector<std::string> settings;  // --set, in order
  std::string synthetic_family;       // --synthetic FAMILY SEED
  uint64_t synthetic_seed = 0;
  bool jpeg = false;  // the KITTI pictures at 0.6 scale as JPEG (for the README)
};

// "" when `family` is one --synthetic takes (a random family, demo or a tracking scenario), else
// the problem.
std::string CheckFamily(const std::string& family) {
  const auto& families = drivers::RandomSceneFamilies();
  const std::vector<drivers::Scenario> tracking = drivers::TrackingScenarios();
  if (family == "demo" || std::find(families.begin(), families.end(), family) != families.end() ||
      std::any_of(tracking.begin(), tracking.end(),
                  [&](const drivers::Scenario& t) { return t.name == family; })) {
    return "";
  }
  return flags::Expected("", "--synthetic",
                         "FAMILY SEED, FAMILY a random family, demo or a tracking scenario",
                         family);
}

// The flags; exits 0 after --help, 2 with the problem and the usage on stderr.
Options ParseOptions(int argc, char** argv) {
  Options o;
  bool help = false;
  bool seed_due = false;  // --synthetic FAMILY was taken, its SEED not yet
  flags::FlagSet set("");
  set.Text("--out", &o.out_dir)
      .Switch("--jpeg", &o.jpeg)
      .Value("--set",
             [&o](const std::string& setting) {
               o.settings.push_back(setting);
               return std::string();
             })
      .Value("--synthetic",
             [&o, &seed_due](const std::string& family) {
               o.synthetic_family = family;
               seed_due = true;
               return CheckFamily(family);
             })
      .Stop("--help", &help);
  // --synthetic takes two values, a FlagSet's flag one: it takes FAMILY, and the walk stops at
  // the SEED right after it (not a "--" flag), which is taken here before the walk goes on.
  const std::vector<std::string> args(argv + 1, argv + argc);
  std::string problem;
  for (std::size_t next = 0; problem.empty() && !help && next < args.size(); ++next) {
    problem = set.ParseLeading(args, next);
    if (!problem.empty() || help || next >= args.size()) break;
    if (!seed_due || next < 2 || args[next - 2] != "--synthetic" ||
        args[next - 1] != o.synthetic_family) {
      problem = "unexpected argument '" + args[next] + "'";
    } else if (const flags::Parsed<std::int64_t> seed = flags::ParseNumber(args[next], kSeedRange);
               !seed.ok()) {
      problem = flags::Expected("", "--synthetic",
                                "FAMILY SEED, SEED " + flags::Describe(kSeedRange), args[next]);
    } else {
      o.synthetic_seed = static_cast<uint64_t>(seed.value);
      seed_due = false;
    }
  }
  if (problem.empty() && !help && seed_due) problem = "--synthetic: needs FAMILY SEED";
  if (!problem.empty()) {
    std::fprintf(stderr, "stevi-stixel-view: %s\n%s", problem.c_str(), kUsage);
    std::exit(2);
  }
  if (help) {
    std::fputs(kUsage, stdout);
    std::exit(0);
  }
  return o;
}

// DIR/PAIR-stixels.png (or .jpg with --jpeg): the pair's left image, its stixels, the truth boxes
// and the scored boxes with their depth.
void WritePicture(const std::string& name, const testing::RealPair& pair,
                  const pipeline::FrameResult& r, const testing::GtScene& scene,
                  const std::vector<testing::ScoredBox>& scored,
                  const testing::DetectionScore& score, const Options& opt) {
  cv::Mat3b out;
  cv::cvtColor(pair.left, out, cv::COLOR_GRAY2BGR);
  DrawStixels(r, r.binning, out);
  for (const testing::GtObstacle& o : scene.obstacles) cv::rectangle(out, o.bbox, {0, 255, 0}, 1);
  for (size_t i = 0; i < scored.size(); ++i) {
    const cv::Scalar c = VerdictColour(score.boxes[i]);
    cv::rectangle(out, scored[i].bbox, c, 2);
    char label[32];
    std::snprintf(label, sizeof label, "%.1f", scored[i].depth_m);
    cv::putText(out, label, scored[i].bbox.tl() + cv::Point(2, 12), cv::FONT_HERSHEY_SIMPLEX, 0.4,
                c, 1);
  }
  if (opt.jpeg) {
    cv::Mat3b small;
    cv::resize(out, small, cv::Size(), 0.6, 0.6, cv::INTER_AREA);
    cv::imwrite(opt.out_dir + "/" + name + "-stixels.jpg", small, {cv::IMWRITE_JPEG_QUALITY, 80});
  } else {
    cv::imwrite(opt.out_dir + "/" + name + "-stixels.png", out);
  }
}

int Run(int argc, char** argv) {
  const Options opt = ParseOptions(argc, argv);
  pipeline::PipelineConfig config = pipeline::ConfigForAlgorithm(pipeline::Algorithm::kStixels);
  // Each setting's own checks, then the whole's, naming every bad field.
  if (const std::vector<std::string> problems = pipeline::ApplySettings(config, opt.settings);
      !problems.empty()) {
    for (const std::string& p : problems)
      std::fprintf(stderr, "stevi-stixel-view: %s\n", p.c_str());
    return 2;
  }
  if (!opt.synthetic_family.empty()) {
    return RunSynthetic(opt.synthetic_family, opt.synthetic_seed, config, opt.out_dir);
  }
  const std::optional<std::string> dir = testing::DataDir();
  if (!dir) {
    std::printf("skipped: no reference data at %s\n", testing::DataDirWanted().c_str());
    return 0;
  }
  int found = 0, truth = 0, fp = 0, boxes = 0, within5 = 0;
  for (const std::string& name : testing::KittiPairNames()) {
    std::string problem;
    const std::optional<testing::RealPair> pair = testing::LoadRealPair(*dir, name, problem);
    if (!pair) {
      std::fprintf(stderr, "%s\n", problem.c_str());
      return 1;
    }
    const auto rig = std::make_shared<const geometry::StereoRig>(geometry::StereoRig::Ideal(
        pair->left.size(), pair->f_px, pair->baseline_m, pair->cx, pair->cy, pair->name));
    const pipeline::Snapshot snapshot{std::make_shared<const pipeline::PipelineConfig>(config),
                                      rig};
    StereoFrame frame;
    frame.left = pair->left;
    frame.right = pair->right;
    frame.rectified = true;
    pipeline::Pipeline pipe;
    Result<pipeline::FrameResult> result = pipe.Process(frame, snapshot);
    if (!result.ok()) {
      std::fprintf(stderr, "%s: %s\n", name.c_str(), result.error().message.c_str());
      return 1;
    }
    const pipeline::FrameResult& r = result.value();
    const int bin = r.binning;
    const testing::GtScene scene = testing::ExtractGtObstacles(
        pair->truth_px, pair->f_px, pair->baseline_m, pair->cx, pair->cy);
    std::vector<testing::ScoredBox> scored;
    for (const detection::Detection& d : r.detections) {
      scored.push_back(
          {cv::Rect(d.bbox.x * bin, d.bbox.y * bin, d.bbox.width * bin, d.bbox.height * bin),
           d.depth_m});
    }
    const testing::DetectionScore score =
        testing::ScoreDetections(scene, pair->f_px, pair->baseline_m, scored);
    int w5 = 0;
    for (const testing::ObstacleResult& o : score.obstacles) {
      if (o.detection >= 0 && std::abs(o.range_error_pct) <= 5) ++w5;
    }
    found += score.found;
    truth += static_cast<int>(scene.obstacles.size());
    fp += score.fp;
    boxes += static_cast<int>(scored.size());
    within5 += w5;
    double ms = 0;
    for (const pipeline::StageTiming& t : r.timings) {
      if (t.stage == "total") ms = t.ms;
    }
    std::printf(
        "%-16s ground %s  boxes %2zu  truth %2zu  found %2d (%d within 5 %%)  frag %2d  FP %2d"
        " (free %d struct %d wrZ %d noGT %d)  %.1f ms\n",
        name.c_str(), r.ground ? "yes" : "no ", scored.size(), scene.obstacles.size(), score.found,
        w5, score.fragments, score.fp, score.fp_free, score.fp_structure, score.fp_wrong_depth,
        score.fp_no_truth, ms);
    WritePicture(name, *pair, r, scene, scored, score, opt);
  }
  std::printf("all: boxes %d  truth %d  found %d (%.0f %%)  within 5 %% %d (%.0f %%)  FP %d\n",
              boxes, truth, found, 100.0 * found / std::max(1, truth), within5,
              100.0 * within5 / std::max(1, truth), fp);
  return 0;
}

}  // namespace
}  // namespace stevi

int main(int argc, char** argv) { return stevi::Run(argc, argv); }
