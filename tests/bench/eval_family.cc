#include "tests/bench/eval_family.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/pipeline/pipeline.h"
#include "drivers/synthetic/random_scenes.h"
#include "drivers/synthetic/synthetic_source.h"
#include "tests/testing/track_level.h"
#include "tests/testing/truth_match.h"

namespace stevi::bench {
namespace {

// Expected obstacles: at least this many visible pixels and this much median truth disparity
// (camera pixels, full resolution).
constexpr int kMinVisiblePx = 100;
constexpr double kMinDisparityPx = 3.0;
constexpr double kMinIoU = 0.3;
constexpr double kInsideFraction = 0.5;
// A missed obstacle "had disparities" when at least this fraction of its truth box holds
// disparities within max(0.5 px, 5 %) of its truth median disparity: the matcher saw it, and the
// detector lost it.
constexpr double kMatchedBoxFraction = 0.05;

// The fraction of `box` (camera pixels) whose disparity lies within max(0.5 px, 5 %) of
// `truth_px` (camera pixels), in a map binned by `bin`.
double MatchedFraction(const stereo::DisparityMap& disparity, const cv::Rect& box, int bin,
                       double truth_px) {
  const cv::Rect b = cv::Rect(box.x / bin, box.y / bin, std::max(1, box.width / bin),
                              std::max(1, box.height / bin)) &
                     cv::Rect(0, 0, disparity.fixed.cols, disparity.fixed.rows);
  if (b.area() == 0) return 0.0;
  const double d = truth_px / bin, tolerance = std::max(0.5, 0.05 * d);
  int near = 0;
  for (int y = b.y; y < b.br().y; ++y) {
    const int16_t* row = disparity.fixed[y];
    for (int x = b.x; x < b.br().x; ++x) {
      near += row[x] >= 0 &&
              std::abs(static_cast<double>(row[x]) / stereo::DisparityMap::kScale - d) <= tolerance;
    }
  }
  return static_cast<double>(near) / b.area();
}

struct Band {
  const char* name;
  double lo_px, hi_px;  // truth median disparity
};
constexpr Band kBands[] = {{">20px", 20.0, 1e9}, {"8-20px", 8.0, 20.0}, {"3-8px", 3.0, 8.0}};
constexpr int kNumBands = 3;

struct Totals {
  int scenes = 0, frames = 0;
  int expected = 0, matched = 0, detections = 0, false_positives = 0, dont_care = 0;
  int found_boxes = 0;  // sum over matched obstacles of 1 + the fragments inside their box
  int fragmented = 0;   // matched obstacles with more than one box
  int missed_none = 0, missed_small = 0, missed_large = 0;  // misses: no box touches it; the
                                                            // box most on it is smaller; larger
  int missed_with_disparity =
      0;  // misses whose truth box the matcher covered (kMatchedBoxFraction)
  std::vector<double> rel_error[kNumBands];  // (depth - truth) / truth, per band
  std::vector<double> normalised;            // (depth - truth) / depth_sigma
  std::map<std::string, double> stage_ms;
  std::map<std::string, std::pair<int, int>> by_kind;  // kind: (expected, matched)

  void Add(const Totals& o) {
    scenes += o.scenes;
    frames += o.frames;
    expected += o.expected;
    matched += o.matched;
    detections += o.detections;
    false_positives += o.false_positives;
    dont_care += o.dont_care;
    found_boxes += o.found_boxes;
    fragmented += o.fragmented;
    missed_none += o.missed_none;
    missed_small += o.missed_small;
    missed_large += o.missed_large;
    missed_with_disparity += o.missed_with_disparity;
    for (int b = 0; b < kNumBands; ++b) {
      rel_error[b].insert(rel_error[b].end(), o.rel_error[b].begin(), o.rel_error[b].end());
    }
    normalised.insert(normalised.end(), o.normalised.begin(), o.normalised.end());
    for (const auto& [stage, ms] : o.stage_ms) stage_ms[stage] += ms;
    for (const auto& [kind, c] : o.by_kind) {
      by_kind[kind].first += c.first;
      by_kind[kind].second += c.second;
    }
  }
  double Recall() const { return expected ? 100.0 * matched / expected : 0.0; }
  double Precision() const {
    return matched + false_positives ? 100.0 * matched / (matched + false_positives) : 0.0;
  }
  double BoxesPerFound() const { return matched ? static_cast<double>(found_boxes) / matched : 0; }
  double StageMs(const std::string& stage) const {
    const auto it = stage_ms.find(stage);
    return it == stage_ms.end() || frames == 0 ? 0.0 : it->second / frames;
  }
};

double Rms(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x * x;
  return v.empty() ? 0.0 : std::sqrt(s / static_cast<double>(v.size()));
}

double MedianAbs(std::vector<double> v) {
  if (v.empty()) return 0.0;
  for (double& x : v) x = std::abs(x);
  auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

// One frame's verdict, also used to draw it.
struct FrameScore {
  std::vector<cv::Rect> boxes;  // detections, camera pixels
  std::vector<int> verdict;     // per detection: 1 match, 0 don't care, -1 false positive
  std::vector<const drivers::ObstacleTruth*> expected, ignored;
};

FrameScore Score(const pipeline::FrameResult& result, const drivers::FrameTruth& truth, double fB,
                 Totals& totals) {
  FrameScore s;
  const int bin = std::max(1, result.binning);
  for (const detection::Detection& d : result.detections) {
    s.boxes.emplace_back(d.bbox.x * bin, d.bbox.y * bin, d.bbox.width * bin, d.bbox.height * bin);
  }
  std::vector<cv::Rect> truth_boxes;
  for (const drivers::ObstacleTruth& o : truth.obstacles) {
    if (o.visible_px >= kMinVisiblePx && o.median_disparity_px >= kMinDisparityPx) {
      s.expected.push_back(&o);
      truth_boxes.push_back(o.bbox);
      ++totals.by_kind[o.kind].first;
    } else if (o.visible_px > 0) {
      s.ignored.push_back(&o);
    }
  }
  totals.expected += static_cast<int>(s.expected.size());
  totals.detections += static_cast<int>(s.boxes.size());
  s.verdict.assign(s.boxes.size(), -1);
  const auto matches = testing::MatchByIoU(s.boxes, truth_boxes, kMinIoU);
  for (const auto& [d, t] : matches) {
    s.verdict[static_cast<size_t>(d)] = 1;
    ++totals.matched;
    ++totals.by_kind[s.expected[static_cast<size_t>(t)]->kind].second;
  }
  // Why each missed obstacle was missed.
  {
    std::vector<bool> found(s.expected.size(), false);
    for (const auto& [d, t] : matches) found[static_cast<size_t>(t)] = true;
    for (size_t t = 0; t < s.expected.size(); ++t) {
      if (found[t]) continue;
      const cv::Rect& truth_box = s.expected[t]->bbox;
      int best = -1, best_overlap = 0;
      for (size_t d = 0; d < s.boxes.size(); ++d) {
        const int overlap = (s.boxes[d] & truth_box).area();
        if (overlap > best_overlap) {
          best_overlap = overlap;
          best = static_cast<int>(d);
        }
      }
      if (MatchedFraction(result.disparity, truth_box, bin, s.expected[t]->median_disparity_px) >=
          kMatchedBoxFraction) {
        ++totals.missed_with_disparity;
      }
      if (best < 0) {
        ++totals.missed_none;
      } else if (s.boxes[static_cast<size_t>(best)].area() < truth_box.area()) {
        ++totals.missed_small;
      } else {
        ++totals.missed_large;
      }
    }
  }
  // Unmatched detections on an obstacle that is not expected: don't care.
  for (size_t d = 0; d < s.boxes.size(); ++d) {
    if (s.verdict[d] == 1) continue;
    for (const drivers::ObstacleTruth* o : s.ignored) {
      if (testing::IoU(s.boxes[d], o->bbox) >= kMinIoU ||
          testing::InsideFraction(s.boxes[d], o->bbox) >= kInsideFraction) {
        s.verdict[d] = 0;
        break;
      }
    }
    if (s.verdict[d] == 0) {
      ++totals.dont_care;
    } else {
      ++totals.false_positives;
    }
  }
  for (const auto& [d, t] : matches) {
    const drivers::ObstacleTruth& o = *s.expected[static_cast<size_t>(t)];
    int boxes = 1;
    for (size_t k = 0; k < s.boxes.size(); ++k) {
      if (s.verdict[k] == 1) continue;  // matched to an obstacle (this one or another)
      if (testing::InsideFraction(s.boxes[k], o.bbox) >= kInsideFraction) ++boxes;
    }
    totals.found_boxes += boxes;
    if (boxes > 1) ++totals.fragmented;
    const detection::Detection& det = result.detections[static_cast<size_t>(d)];
    const double truth_depth = fB / o.median_disparity_px;
    const double rel = (det.depth_m - truth_depth) / truth_depth;
    for (int b = 0; b < kNumBands; ++b) {
      if (o.median_disparity_px >= kBands[b].lo_px && o.median_disparity_px < kBands[b].hi_px) {
        totals.rel_error[b].push_back(rel);
      }
    }
    if (det.range_m > 0 && det.range_sigma_m > 0) {
      const double depth_sigma = det.range_sigma_m * det.depth_m / det.range_m;
      totals.normalised.push_back((det.depth_m - truth_depth) / depth_sigma);
    }
  }
  for (const pipeline::StageTiming& t : result.timings) totals.stage_ms[t.stage] += t.ms;
  ++totals.frames;
  return s;
}

void Draw(const StereoFrame& frame, const pipeline::FrameResult& result, double fB,
          const FrameScore& s, const std::string& path) {
  cv::Mat3b out;
  cv::cvtColor(frame.left, out, cv::COLOR_GRAY2BGR);
  const int thick = std::max(1, frame.left.cols / 640);
  const double font = 0.4 * thick;
  const cv::Scalar green(0, 220, 0), dark_green(0, 120, 60), red(0, 0, 255), orange(0, 140, 255);
  auto label = [&](const std::string& text, cv::Point at, const cv::Scalar& colour) {
    at.y = std::max(at.y, 12 * thick);
    cv::putText(out, text, at, cv::FONT_HERSHEY_SIMPLEX, font, colour, thick);
  };
  for (const drivers::ObstacleTruth* o : s.ignored) {
    cv::rectangle(out, o->bbox, dark_green, thick);
  }
  for (const drivers::ObstacleTruth* o : s.expected) {
    cv::rectangle(out, o->bbox, green, thick);
    std::ostringstream t;
    t.precision(3);
    t << o->kind << " d=" << o->median_disparity_px << " Z=" << fB / o->median_disparity_px;
    label(t.str(), {o->bbox.x, o->bbox.y + o->bbox.height + 12 * thick}, green);
  }
  for (size_t d = 0; d < s.boxes.size(); ++d) {
    const cv::Scalar colour = s.verdict[d] == 0 ? orange : red;
    cv::rectangle(out, s.boxes[d], colour, thick);
    std::ostringstream t;
    t.precision(3);
    t << result.detections[d].depth_m << "m";
    label(t.str(), {s.boxes[d].x, s.boxes[d].y - 3}, colour);
  }
  cv::imwrite(path, out);
}

void PrintHeader() {
  std::printf("%-11s %-13s %6s %6s %6s %7s %6s %5s %5s %7s %5s", "family", "algorithm", "scenes",
              "frames", "expect", "recall", "prec", "FP", "dc", "box/obj", "frag");
  for (const Band& b : kBands) std::printf(" %14s", (std::string("err ") + b.name).c_str());
  std::printf(" %7s %8s %8s %8s %s\n", "err/sig", "disp ms", "extr ms", "total ms",
              "missed: none/smaller/larger (with disparity)");
}

void PrintRow(const std::string& family, const std::string& variant, const Totals& t) {
  std::printf("%-11s %-13s %6d %6d %6d %6.1f%% %5.1f%% %5d %5d %7.2f %5d", family.c_str(),
              variant.c_str(), t.scenes, t.frames, t.expected, t.Recall(), t.Precision(),
              t.false_positives, t.dont_care, t.BoxesPerFound(), t.fragmented);
  for (int b = 0; b < kNumBands; ++b) {
    if (t.rel_error[b].empty()) {
      std::printf(" %14s", "-");
    } else {
      char cell[32];
      std::snprintf(cell, sizeof cell, "%.1f/%.1f%%(%zu)", 100 * MedianAbs(t.rel_error[b]),
                    100 * Rms(t.rel_error[b]), t.rel_error[b].size());
      std::printf(" %14s", cell);
    }
  }
  std::printf(" %7.2f %8.1f %8.1f %8.1f %d/%d/%d (%d)\n", Rms(t.normalised), t.StageMs("disparity"),
              t.StageMs("extract"), t.StageMs("total"), t.missed_none, t.missed_small,
              t.missed_large, t.missed_with_disparity);
}

std::string JsonTotals(const Totals& t) {
  std::ostringstream j;
  j << "{\"scenes\": " << t.scenes << ", \"frames\": " << t.frames
    << ", \"expected\": " << t.expected << ", \"matched\": " << t.matched
    << ", \"detections\": " << t.detections << ", \"false_positives\": " << t.false_positives
    << ", \"dont_care\": " << t.dont_care << ", \"recall_pct\": " << t.Recall()
    << ", \"precision_pct\": " << t.Precision() << ", \"boxes_per_found\": " << t.BoxesPerFound()
    << ", \"fragmented\": " << t.fragmented << ", \"missed\": {\"none\": " << t.missed_none
    << ", \"smaller\": " << t.missed_small << ", \"larger\": " << t.missed_large
    << ", \"with_disparity\": " << t.missed_with_disparity << "}, \"range_error\": {";
  for (int b = 0; b < kNumBands; ++b) {
    j << (b ? ", " : "") << "\"" << kBands[b].name << "\": {\"n\": " << t.rel_error[b].size()
      << ", \"median_abs_pct\": " << 100 * MedianAbs(t.rel_error[b])
      << ", \"rms_pct\": " << 100 * Rms(t.rel_error[b]) << "}";
  }
  j << "}, \"error_over_sigma_rms\": " << Rms(t.normalised) << ", \"recall_by_kind\": {";
  bool first = true;
  for (const auto& [kind, c] : t.by_kind) {
    j << (first ? "" : ", ") << "\"" << kind << "\": {\"expected\": " << c.first
      << ", \"matched\": " << c.second << "}";
    first = false;
  }
  j << "}, \"ms_per_frame\": {";
  first = true;
  for (const auto& [stage, ms] : t.stage_ms) {
    j << (first ? "" : ", ") << "\"" << stage << "\": " << (t.frames ? ms / t.frames : 0.0);
    first = false;
  }
  j << "}}";
  return j.str();
}

// Track level (tests/testing/track_level.h): an obstacle is measurable when at least
// kMinVisiblePx of it are visible and its truth median disparity is at least
// kMeasurableSigmas disparity sigmas (PipelineConfig::range.disparity_sigma_px, camera pixels).
constexpr double kMeasurableSigmas = 3.0;

testing::TlFrame TrackLevelFrame(const pipeline::FrameResult& result,
                                 const drivers::FrameTruth& truth, double fB,
                                 double disparity_sigma_px) {
  testing::TlFrame f;
  const int bin = std::max(1, result.binning);
  for (const drivers::ObstacleTruth& o : truth.obstacles) {
    testing::TlTruth t;
    t.id = o.id;
    t.box = o.bbox;
    t.visible = o.visible_px > 0;
    t.expected = o.visible_px >= kMinVisiblePx &&
                 o.median_disparity_px >= kMeasurableSigmas * disparity_sigma_px;
    t.depth_m = o.median_disparity_px > 0 ? fB / o.median_disparity_px : 0.0;
    f.truths.push_back(t);
  }
  for (const tracking::Track& track : result.tracks) {
    const cv::Rect& b = track.detection.bbox;
    f.tracks.push_back({track.id, track.state == tracking::TrackState::kConfirmed,
                        cv::Rect(b.x * bin, b.y * bin, b.width * bin, b.height * bin),
                        track.position_cam_m[2], track.position_sigma_m[2]});
  }
  return f;
}

void PrintTrackLevelHeader(const FamilyEvalOptions& options) {
  std::printf(
      "\nTRACK LEVEL (tracker, confirmed tracks): measurable = visible >= %d px and truth "
      "median disparity >= %.0f x the disparity sigma (PipelineConfig::range.disparity_sigma_px);"
      "\n  conf@%d = measurable obstacles confirmed (a track in state confirmed, box IoU >= %.1f) "
      "within %d frames of becoming measurable (target 95 %%), over those whose window fits "
      "the scene (cens = not confirmed and the scene ended first);\n  ftc = median frames from "
      "measurable to confirmed (confirmed at all: ever); false/1k = confirmed tracks matching "
      "no expected or don't-care obstacle in any confirmed frame, per 1000 frames (target <= "
      "1); err/sig = rms (depth - truth) / depth sigma of confirmed track-frames (target "
      "0.7..1.4)\n",
      kMinVisiblePx, kMeasurableSigmas, options.confirm_window, kMinIoU, options.confirm_window);
  std::printf("%-11s %-13s %6s %6s %5s %5s %8s %5s %5s %7s %5s %6s %8s %7s\n", "family",
              "algorithm", "scenes", "frames", "sigma", "obst", "conf@N", "cens", "ever", "ftc",
              "conf", "false", "false/1k", "err/sig");
}

void PrintTrackLevelRow(const std::string& family, const std::string& variant,
                        const testing::TrackLevelTotals& t, double sigma_px) {
  char conf[32];
  std::snprintf(conf, sizeof conf, "%.1f%%", t.ConfirmedPct());
  std::printf("%-11s %-13s %6d %6d %5.2f %5d %8s %5d %5d %7.1f %5d %6d %8.2f %7.2f\n",
              family.c_str(), variant.c_str(), t.sequences, t.frames, sigma_px, t.obstacles, conf,
              t.censored, t.confirmed_ever, t.MedianFramesToConfirm(), t.confirmed_tracks,
              t.false_tracks, t.FalsePer1000Frames(), t.ErrorOverSigmaRms());
}

std::string JsonTrackLevel(const testing::TrackLevelTotals& t, int window, double sigma_px) {
  std::ostringstream j;
  j << "{\"window_frames\": " << window << ", \"disparity_sigma_px\": " << sigma_px
    << ", \"measurable_sigmas\": " << kMeasurableSigmas << ", \"frames\": " << t.frames
    << ", \"obstacles\": " << t.obstacles << ", \"scored\": " << t.scored
    << ", \"censored\": " << t.censored << ", \"confirmed_in_window\": " << t.confirmed_in_window
    << ", \"confirmed_in_window_pct\": " << t.ConfirmedPct()
    << ", \"confirmed_ever\": " << t.confirmed_ever
    << ", \"median_frames_to_confirm\": " << t.MedianFramesToConfirm()
    << ", \"confirmed_tracks\": " << t.confirmed_tracks << ", \"false_tracks\": " << t.false_tracks
    << ", \"false_tracks_per_1000_frames\": " << t.FalsePer1000Frames()
    << ", \"error_over_sigma_rms\": " << t.ErrorOverSigmaRms()
    << ", \"error_over_sigma_n\": " << t.normalised_error.size() << "}";
  return j.str();
}

}  // namespace

bool ParseSeedRange(const std::string& text, uint64_t& first, uint64_t& last) {
  const size_t dash = text.find('-');
  try {
    size_t used = 0;
    if (dash == std::string::npos) {
      first = last = std::stoull(text, &used);
      return used == text.size();
    }
    const std::string a = text.substr(0, dash), b = text.substr(dash + 1);
    first = std::stoull(a, &used);
    if (used != a.size() || a.empty()) return false;
    last = std::stoull(b, &used);
    if (used != b.size() || b.empty()) return false;
  } catch (const std::exception&) {
    return false;
  }
  return first <= last;
}

namespace {

using TrackTable = std::map<std::string, std::map<std::string, testing::TrackLevelTotals>>;

struct FamilyTables {
  std::map<std::string, std::map<std::string, Totals>> frames;  // family -> variant -> totals
  TrackTable tracks;                                            // family -> variant -> totals
  double render_s = 0;
  int rendered_frames = 0;
};

int SceneFrames(const FamilyEvalOptions& options, const drivers::Scenario& scenario) {
  if (options.scene_frames > 0) return options.scene_frames;
  return options.max_frames > 0 ? std::min(options.max_frames, scenario.frames) : scenario.frames;
}

// Renders one scene and runs every variant over it. False on a pipeline error (printed).
bool RunScene(const FamilyEvalOptions& options, const std::vector<EvalVariant>& variants,
              const std::string& family, uint64_t seed, FamilyTables& tables) {
  const drivers::Scenario scenario = drivers::RandomScenario(family, seed);
  const drivers::SyntheticRenderer renderer(scenario.options);
  const auto rig = std::make_shared<const geometry::StereoRig>(renderer.Rig());
  const double fB = scenario.options.f_px * scenario.options.baseline_m;
  const int frames = SceneFrames(options, scenario);
  std::vector<StereoFrame> images;
  std::vector<drivers::FrameTruth> truths(static_cast<size_t>(frames));
  const auto r0 = std::chrono::steady_clock::now();
  for (int k = 0; k < frames; ++k) {
    drivers::FrameTruth& truth = truths[static_cast<size_t>(k)];
    images.push_back(renderer.Render(k, &truth));
    truth.disparity_px.release();  // the scores read the obstacles only
    truth.object_id.release();
  }
  tables.render_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - r0).count();
  tables.rendered_frames += frames;
  const bool dump = !options.dump_dir.empty() && seed < options.seed_first + options.dump_scenes;
  for (const EvalVariant& variant : variants) {
    pipeline::Pipeline pipe;
    pipeline::PipelineConfig config = variant.config;
    if (options.max_width_px) config.max_width_px = *options.max_width_px;
    const pipeline::Snapshot snapshot{std::make_shared<const pipeline::PipelineConfig>(config),
                                      rig};
    Totals totals;
    totals.scenes = 1;
    std::vector<testing::TlFrame> track_frames;
    for (int k = 0; k < frames; ++k) {
      Result<pipeline::FrameResult> result = pipe.Process(images[static_cast<size_t>(k)], snapshot);
      if (!result.ok()) {
        std::fprintf(stderr, "%s frame %d (%s): %s\n", scenario.name.c_str(), k,
                     variant.name.c_str(), result.error().message.c_str());
        return false;
      }
      const FrameScore s = Score(*result, truths[static_cast<size_t>(k)], fB, totals);
      track_frames.push_back(TrackLevelFrame(*result, truths[static_cast<size_t>(k)], fB,
                                             config.range.disparity_sigma_px));
      if (dump && k == frames - 1) {
        Draw(images[static_cast<size_t>(k)], *result, fB, s,
             options.dump_dir + "/" + scenario.name + "-" + variant.name + "-f" +
                 std::to_string(k) + ".png");
      }
    }
    tables.frames[family][variant.name].Add(totals);
    testing::TrackLevelOptions tl;
    tl.min_iou = kMinIoU;
    tl.inside_fraction = kInsideFraction;
    tl.window_frames = options.confirm_window;
    tables.tracks[family][variant.name].Add(testing::ScoreTrackLevel(track_frames, tl));
  }
  return true;
}

double SigmaOf(const EvalVariant& variant) { return variant.config.range.disparity_sigma_px; }

void PrintTables(const FamilyEvalOptions& options, const std::vector<EvalVariant>& variants,
                 FamilyTables& tables, std::map<std::string, Totals>& all,
                 std::map<std::string, testing::TrackLevelTotals>& all_tracks) {
  std::printf("\n");
  PrintHeader();
  for (const std::string& family : options.families) {
    for (const EvalVariant& variant : variants) {
      const Totals& t = tables.frames[family][variant.name];
      PrintRow(family, variant.name, t);
      all[variant.name].Add(t);
      all_tracks[variant.name].Add(tables.tracks[family][variant.name]);
    }
  }
  if (options.families.size() > 1) {
    for (const EvalVariant& variant : variants) PrintRow("all", variant.name, all[variant.name]);
  }
  std::printf("\nrecall by kind (all families):");
  for (const EvalVariant& variant : variants) {
    std::printf("\n  %-13s", variant.name.c_str());
    for (const auto& [kind, c] : all[variant.name].by_kind) {
      std::printf(" %s %.0f%% (%d/%d)", kind.c_str(), c.first ? 100.0 * c.second / c.first : 0.0,
                  c.second, c.first);
    }
  }
  std::printf("\n");
  PrintTrackLevelHeader(options);
  for (const std::string& family : options.families) {
    for (const EvalVariant& variant : variants) {
      PrintTrackLevelRow(family, variant.name, tables.tracks[family][variant.name],
                         SigmaOf(variant));
    }
  }
  if (options.families.size() > 1) {
    for (const EvalVariant& variant : variants) {
      PrintTrackLevelRow("all", variant.name, all_tracks[variant.name], SigmaOf(variant));
    }
  }
}

bool WriteJson(const FamilyEvalOptions& options, const std::vector<EvalVariant>& variants,
               FamilyTables& tables, const std::map<std::string, Totals>& all,
               const std::map<std::string, testing::TrackLevelTotals>& all_tracks) {
  std::ofstream json(options.json_path);
  json << "{\"seeds\": [" << options.seed_first << ", " << options.seed_last << "], \"split\": \""
       << (options.seed_first > 1000 ? "test" : "tuning")
       << "\", \"scene_frames\": " << options.scene_frames
       << ", \"confirm_window\": " << options.confirm_window << ", \"families\": {";
  bool first_family = true;
  auto emit = [&](const std::string& name, const std::map<std::string, Totals>& by_variant,
                  const std::map<std::string, testing::TrackLevelTotals>& tracks) {
    json << (first_family ? "" : ", ") << "\"" << name << "\": {";
    first_family = false;
    bool first = true;
    for (const EvalVariant& variant : variants) {
      const auto it = by_variant.find(variant.name);
      const auto tt = tracks.find(variant.name);
      if (it == by_variant.end() || tt == tracks.end()) continue;
      std::string per_frame = JsonTotals(it->second);
      per_frame.pop_back();  // the closing brace: the track level goes inside
      json << (first ? "" : ", ") << "\"" << variant.name << "\": " << per_frame
           << ", \"track_level\": "
           << JsonTrackLevel(tt->second, options.confirm_window, SigmaOf(variant)) << "}";
      first = false;
    }
    json << "}";
  };
  for (const std::string& family : options.families) {
    emit(family, tables.frames[family], tables.tracks[family]);
  }
  emit("all", all, all_tracks);
  json << "}}\n";
  return static_cast<bool>(json);
}

}  // namespace

int RunFamilyEval(const FamilyEvalOptions& options, const std::vector<EvalVariant>& variants) {
  const auto start = std::chrono::steady_clock::now();
  std::printf(
      "random scene families, seeds %llu-%llu%s\n",
      static_cast<unsigned long long>(options.seed_first),
      static_cast<unsigned long long>(options.seed_last),
      options.seed_first > 1000 ? " (the TEST split: never tune on it)" : " (tuning split)");
  if (options.scene_frames > 0) {
    std::printf(
        "scene frames: %d per scene (--scene-frames; past its own 4-6 frames each obstacle "
        "continues on its straight path)\n",
        options.scene_frames);
  }
  std::printf(
      "rule: expected = visible >= %d px and truth median disparity >= %.0f px; a "
      "detection matches at IoU >= %.1f one-to-one; unmatched detections on a "
      "non-expected obstacle (IoU >= %.1f or >= 50 %% inside it) are don't care (dc), "
      "others false positives (FP); prec = matched / (matched + FP)\n",
      kMinVisiblePx, kMinDisparityPx, kMinIoU, kMinIoU);
  std::printf(
      "box/obj = mean boxes per found obstacle (1 + unmatched detections >= 50 %% inside "
      "its truth box), frag = found obstacles with > 1 box; err = |depth - fB / truth "
      "median disparity| / truth: median/rms (n) by truth disparity band; err/sig = rms "
      "of (depth - truth) / depth sigma\n");
  if (!options.dump_dir.empty()) std::filesystem::create_directories(options.dump_dir);

  FamilyTables tables;
  for (const std::string& family : options.families) {
    for (uint64_t seed = options.seed_first; seed <= options.seed_last; ++seed) {
      if (!RunScene(options, variants, family, seed, tables)) return 1;
    }
  }
  std::map<std::string, Totals> all;
  std::map<std::string, testing::TrackLevelTotals> all_tracks;
  PrintTables(options, variants, tables, all, all_tracks);
  const double wall_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("\nrendering: %d frames, %.3f s a frame; wall time %.1f s\n", tables.rendered_frames,
              tables.rendered_frames ? tables.render_s / tables.rendered_frames : 0.0, wall_s);
  if (!options.json_path.empty() && !WriteJson(options, variants, tables, all, all_tracks)) {
    std::fprintf(stderr, "stevi-eval: could not write %s\n", options.json_path.c_str());
    return 1;
  }
  return 0;
}

}  // namespace stevi::bench
