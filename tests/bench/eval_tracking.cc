// stevi-eval-tracking: runs the full pipeline (detection and tracking) over the synthetic tracking
// scenarios and prints CLEAR-MOT against the truth ids: MOTA, mean IoU, false positives, misses, ID
// switches, fragmentations, and the range error of the matched tracks, raw and smoothed.
//
// Rule (tests/testing/mot_metrics.h, tracking_eval.h): an obstacle is ground truth in a frame when
// at least 100 of its pixels are visible and its truth disparity is at least 8 px (as stevi-eval).
// Reported tracks are the confirmed and coasting ones. Per frame, last frame's (truth -> track)
// pairs are kept while their boxes overlap with IoU >= 0.3, the rest are matched one-to-one by
// IoU >= 0.3, best first. A truth matched to another track id than last time is an ID switch. An
// unmatched track on the full projected box of an obstacle that is not ground truth (hidden, cut
// by the border or outside the image) is don't-care, any other one a false positive.
//
// Usage: stevi-eval-tracking [--scenario NAME] [--algorithm canonical|stevie|stevis|stixels]
// [--frames N]
//                            [--trace]
//   --frames caps the frames per scenario (default: each scenario's own length)
//   --trace  prints, per frame, every miss, false positive, ID switch, fragmentation and don't-care
//            with the boxes involved, every measured track whose filtered depth is more than 10 %
//            off its detection's, and for each track without a detection the tracker's gates
//            against every detection of the frame
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/detection/detection.h"
#include "core/geometry/stereo_rig.h"
#include "core/pipeline/config.h"
#include "core/tracking/tracker.h"
#include "drivers/synthetic/synthetic_source.h"
#include "tests/bench/eval_flags.h"
#include "tests/testing/mot_metrics.h"
#include "tests/testing/tracking_eval.h"

namespace {

using namespace stevi;

constexpr pipeline::Algorithm kAlgorithms[] = {
    pipeline::Algorithm::kCanonical, pipeline::Algorithm::kSteViE, pipeline::Algorithm::kSteViS,
    pipeline::Algorithm::kStixels};

// "12.3" or "-" when there are no samples.
std::string RmsOrDash(const std::vector<double>& values, const char* format) {
  if (values.empty()) return "-";
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, format, testing::Rms(values));
  return buffer;
}

std::string Box(const cv::Rect& r) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "[%d,%d %dx%d]", r.x, r.y, r.width, r.height);
  return buffer;
}

// Why a track that got no detection this frame did not take one: the tracker's gates between its
// state of the previous frame, predicted one frame step (constant velocity), and each detection.
void PrintGates(const tracking::Track& before, const std::vector<detection::Detection>& detections,
                const geometry::StereoRig& rig, double dt_s, const tracking::GateOptions& gates) {
  const cv::Vec3d p = before.position_cam_m + before.velocity_cam_mps * dt_s;
  const double u = rig.cx() + rig.f_px() * p[0] / p[2];
  const double v = rig.cy() + rig.f_px() * p[1] / p[2];
  const auto ratio = [](double a, double b) {
    return a > 0 && b > 0 ? std::max(a, b) / std::min(a, b) : 1.0;
  };
  std::printf(
      "    track %llu predicted at (%.0f, %.0f) z %.1f m, v (%.2f, %.2f, %.2f) m/s, last area "
      "%d px:",
      static_cast<unsigned long long>(before.id), u, v, p[2], before.velocity_cam_mps[0],
      before.velocity_cam_mps[1], before.velocity_cam_mps[2], before.detection.area_px);
  for (const detection::Detection& d : detections) {
    const double distance = std::hypot(d.centroid_px.x - u, d.centroid_px.y - v);
    const double depth = ratio(d.position_cam_m[2], p[2]);
    const double area = ratio(d.area_px, before.detection.area_px);
    const double perimeter = ratio(d.perimeter_px, before.detection.perimeter_px);
    std::printf(
        "\n      det %s at (%.0f, %.0f) z %.1f m area %d: distance %.0f px%s, depth %.2f%s, "
        "area %.2f%s, perimeter %.2f%s",
        Box(d.bbox).c_str(), d.centroid_px.x, d.centroid_px.y, d.position_cam_m[2], d.area_px,
        distance, distance > gates.max_distance_px ? " FAIL" : "", depth,
        depth > gates.max_depth_ratio ? " FAIL" : "", area,
        area > gates.max_area_ratio ? " FAIL" : "", perimeter,
        perimeter > gates.max_perimeter_ratio ? " FAIL" : "");
  }
  std::printf("\n");
}

// A track's filtered depth further than this fraction from the detection it was just updated with
// is reported by the trace (the depth gate is 1.3).
constexpr double kDepthDivergence = 0.1;

// Every event of the run that is not a plain match, frame by frame, with the boxes; for every
// track without a detection, the gates against each detection; and every measured track whose
// filtered depth left its detection's depth by more than kDepthDivergence.
void PrintTrace(const std::string& scenario, const testing::TrackingRun& run,
                const geometry::StereoRig& rig, double dt_s, const tracking::GateOptions& gates) {
  for (size_t k = 0; k < run.frames.size(); ++k) {
    const testing::TrackedFrame& f = run.frames[k];
    const testing::MotFrame& m = f.scored;
    std::string diverged;
    for (const tracking::Track& t : f.tracks) {
      const double measured_z = t.detection.position_cam_m[2];
      if (t.misses > 0 || !(measured_z > 0)) continue;
      if (std::abs(t.position_cam_m[2] - measured_z) > kDepthDivergence * measured_z) {
        char text[160];
        std::snprintf(text, sizeof text, "  DEPTH track %llu filtered z %.1f m, detection z %.1f m",
                      static_cast<unsigned long long>(t.id), t.position_cam_m[2], measured_z);
        diverged += text;
      }
    }
    if (std::getenv("STEVI_TRACE_ALL") != nullptr) {
      std::printf("%s %s frame %zu detections:", scenario.c_str(), run.algorithm.c_str(), k);
      for (const detection::Detection& d : f.detections) {
        std::printf(" %s z %.1f (c %.0f,%.0f)", Box(d.bbox).c_str(), d.depth_m, d.centroid_px.x,
                    d.centroid_px.y);
      }
      std::printf("\n  tracks:");
      for (const tracking::Track& t : f.tracks) {
        std::printf(" %llu%s %s z %.1f vx %.2f vz %.2f;", static_cast<unsigned long long>(t.id),
                    t.misses > 0 ? "c" : "", Box(t.detection.bbox).c_str(), t.position_cam_m[2],
                    t.velocity_cam_mps[0], t.velocity_cam_mps[2]);
      }
      std::printf("\n");
    }
    if (m.misses.empty() && m.false_positives.empty() && m.id_switches.empty() &&
        m.fragmentations.empty() && m.dont_care.empty() && diverged.empty()) {
      continue;
    }
    const auto truth_box = [&](int id) {
      for (const testing::MotTruth& t : f.truths) {
        if (t.id == id) return "truth " + std::to_string(id) + " " + Box(t.box);
      }
      return std::string("?");
    };
    const auto track_box = [&](std::uint64_t id) {
      for (const tracking::Track& t : f.tracks) {
        if (t.id == id) {
          return "track " + std::to_string(id) + " " +
                 std::string(tracking::TrackStateName(t.state)) + " " + Box(t.detection.bbox);
        }
      }
      return std::string("?");
    };
    std::string line;
    for (int id : m.misses) line += "  FN " + truth_box(id);
    for (std::uint64_t id : m.false_positives) line += "  FP " + track_box(id);
    for (int id : m.id_switches) line += "  IDSW " + truth_box(id);
    for (int id : m.fragmentations) line += "  FRAG " + truth_box(id);
    for (const auto& [track, truth] : m.dont_care) {
      line += "  DC " + track_box(track) + " on " + std::to_string(truth);
    }
    line += diverged;
    for (const auto& [truth, track] : m.matches) {
      line += "  (" + std::to_string(truth) + "->" + std::to_string(track) + ")";
    }
    std::printf("%s %s frame %zu:%s\n", scenario.c_str(), run.algorithm.c_str(), k, line.c_str());
    if (k == 0) continue;
    for (const tracking::Track& t : f.tracks) {
      if (t.misses == 0) continue;
      for (const tracking::Track& before : run.frames[k - 1].tracks) {
        if (before.id == t.id) PrintGates(before, f.detections, rig, dt_s, gates);
      }
    }
  }
}

constexpr char kUsage[] =
    "usage: stevi-eval-tracking [--scenario NAME] [--algorithm canonical|stevie|stevis|stixels] "
    "[--frames N] [--trace]\n";

}  // namespace

int main(int argc, char** argv) {
  const auto usage = [](const std::string& problem) {
    std::fprintf(stderr, "stevi-eval-tracking: %s\n%s", problem.c_str(), kUsage);
    return 2;
  };
  const bench::EvalFlags flags =
      bench::ParseEvalFlagsOrExit("stevi-eval-tracking", kUsage, argc, argv, true, false);
  const int max_frames = flags.max_frames;
  const std::string& only_scenario = flags.scenario;
  const std::string& only_algorithm = flags.algorithm;

  const std::vector<drivers::Scenario> scenarios = drivers::TrackingScenarios();
  if (const std::string problem = bench::UnknownScenario(scenarios, only_scenario);
      !problem.empty()) {
    return usage(problem);
  }
  if (!only_algorithm.empty() && !pipeline::AlgorithmFromName(only_algorithm)) {
    return usage("unknown algorithm '" + only_algorithm + "'");
  }

  std::printf(
      "rule: ground truth = visible >= %d px and disparity >= %.0f px; tracks = confirmed + "
      "coasting\n"
      "      match = last frame's pair kept while IoU >= %.1f, the rest one-to-one by IoU >= %.1f, "
      "best first\n"
      "      don't care = an unmatched track on the full projected box of an obstacle that is not "
      "ground truth\n"
      "      (hidden, cut by the border, outside the image)\n"
      "      range rms: track - truth range over the matches measured this frame (raw and "
      "smoothed)\n"
      "      TTC rms: over the matches with >= %d hits of an obstacle on a collision course "
      "(miss <= %.0f m)\n"
      "      pipeline::ConfigForAlgorithm: the algorithm with its own matcher (stixels: dense, "
      "else BM)\n\n",
      testing::kMinVisiblePx, testing::kMinDisparityPx, testing::kMinIoU, testing::kMinIoU,
      testing::kMinTtcHits, testing::kCollisionCourseM);
  std::printf("%-18s %-9s %6s %5s %6s %6s %6s %5s %4s %4s %4s %4s %4s %9s %9s %7s\n", "scenario",
              "algorithm", "frames", "GT", "traj", "tracks", "MOTA", "IoU", "FP", "FN", "IDSW",
              "frag", "DC", "range raw", "smoothed", "TTC");
  for (const drivers::Scenario& scenario : scenarios) {
    if (!only_scenario.empty() && scenario.name != only_scenario) continue;
    const testing::RenderedScenario rendered = testing::RenderScenario(scenario, max_frames);
    for (pipeline::Algorithm algorithm : kAlgorithms) {
      if (!only_algorithm.empty() && pipeline::AlgorithmName(algorithm) != only_algorithm) continue;
      pipeline::PipelineConfig config = pipeline::ConfigForAlgorithm(algorithm);
      bench::ApplySettingFlags(flags, config);
      Result<testing::TrackingRun> run = testing::RunTracking(rendered, config);
      if (!run.ok()) {
        std::fprintf(stderr, "%s\n", run.error().message.c_str());
        return 1;
      }
      if (flags.trace) {
        PrintTrace(scenario.name, *run, *rendered.rig, 1.0 / scenario.options.fps,
                   config.tracking.gates);
      }
      const testing::MotSummary& s = run->summary;
      int tracked = 0;
      for (const auto& [id, n] : s.expected_frames) {
        if (s.matched_frames.count(id) > 0) ++tracked;
      }
      const std::string trajectories =
          std::to_string(tracked) + "/" + std::to_string(s.expected_frames.size());
      std::printf("%-18s %-9s %6d %5d %6s %6zu %6.3f %5.2f %4d %4d %4d %4d %4d %7s m %7s m %5s s\n",
                  scenario.name.c_str(), run->algorithm.c_str(), s.frames, s.ground_truth,
                  trajectories.c_str(), s.track_ids.size(), s.Mota(), s.MeanIoU(),
                  s.false_positives, s.misses, s.id_switches, s.fragmentations, s.dont_care,
                  RmsOrDash(s.range_errors_m, "%.3f").c_str(),
                  RmsOrDash(s.smoothed_range_errors_m, "%.3f").c_str(),
                  RmsOrDash(s.ttc_errors_s, "%.2f").c_str());
    }
  }
  std::printf(
      "\ntraj = ground-truth trajectories matched at least once / all; tracks = track ids "
      "reported (confirmed at least once);\nIoU = mean IoU of the matches; DC = don't-care "
      "track frames; frag = fragmentations\n");
  return 0;
}
