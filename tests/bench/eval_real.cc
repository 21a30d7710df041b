// stevi-eval-real: the pipeline on REAL stereo pairs with ground truth (the shared reference data,
// tests/testing/data.h; Middlebury 2001/2003/2014 and KITTI 2015). See tests/bench/README.md.
//
// 1. Disparity: the pipeline's own matcher (PipelineConfig::matcher, run through Pipeline::Process
//    with an ideal rig of the pair, so the map is the one the detectors see) against the truth, at
//    the default max_width_px and at 0 (full resolution). A binned map is compared on its own grid:
//    the truth is downsampled by the median of the known values of each block (a block counts
//    when at least half of its pixels are known), the map's disparity multiplied by the binning, so
//    errors are in camera pixels. Middlebury: over the non-occluded mask.
// 2. KITTI obstacles delimited from the truth disparity alone (tests/testing/gt_obstacles.h): a
//    ground plane, pixels standing above it, depth-consistent components.
// 3. Each detector's FrameResult::detections (boxes times FrameResult::binning) against those
//    obstacles: found (IoU >= 0.3 one-to-one), fragments, range error, false positives and what
//    the truth says lies under them.
// 4. The KITTI odometry sequence kitti_odom_seq_b (41 frames, true poses; tests/testing/
//    odometry_sequence.h, odometry_pipeline.h): the pipeline with its tracker, without and with the
//    poses through Snapshot::pose_at; static-world consistency of the confirmed tracks, confirmed
//    tracks on the road (an SGBM reference plane), our labelled cars confirmed; --scenario
//    kitti-odom-seq-b runs this section alone.
//
// Usage: stevi-eval-real [--algorithm canonical|stevie|stevis|stixels|all] [--max-width N]
//                        [--scenario PAIR] [--json FILE] [--dump DIR]
//   --max-width N: only that PipelineConfig::max_width_px (default: the default and 0)
//   --scenario PAIR: one pair (tsukuba, venus, teddy, cones, motorcycle, kitti-000005_10, ...),
//     or kitti-odom-seq-b (section 4 alone)
//   --dump DIR: colourised truth / disparity / error per pair, the truth obstacles of each KITTI
//     pair, and each detector's boxes over them.
// Without the reference data it prints why and exits 0 ("skipped").
#include <algorithm>
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

#include "core/detection/ground.h"
#include "core/pipeline/pipeline.h"
#include "tests/bench/eval_flags.h"
#include "tests/testing/data.h"
#include "tests/testing/gt_obstacles.h"
#include "tests/testing/odometry_pipeline.h"
#include "tests/testing/odometry_sequence.h"
#include "tests/testing/real_pairs.h"
#include "tests/testing/real_pairs_pipeline.h"

namespace {

using namespace stevi;
using testing::BoxVerdict;

std::string Name(pipeline::Algorithm a) { return std::string(pipeline::AlgorithmName(a)); }

// The median (the mean of the two middle values for an even count); "-" when empty.
std::string MedianText(std::vector<double> v) {
  if (v.empty()) return "-";
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  const double m = n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.1f", m);
  return buffer;
}

std::string Fmt(const char* format, double value) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, format, value);
  return buffer;
}

// One pipeline run of one pair.
struct Run {
  pipeline::Algorithm algorithm;
  int max_width_px = 0;
  pipeline::FrameResult result;
  std::vector<testing::ScoredBox> boxes;  // camera pixels
  testing::DetectionScore score;
};

int BinningFor(const testing::RealPair& pair, int max_width_px) {
  return geometry::BinningFactor(pair.left.cols, max_width_px,
                                 pipeline::PipelineConfig{}.range.min_disparity_px);
}

// The selected algorithms grouped by their matcher options (one disparity per group).
std::vector<std::vector<pipeline::Algorithm>> MatcherGroups(
    const std::vector<pipeline::Algorithm>& algorithms) {
  std::vector<std::vector<pipeline::Algorithm>> groups;
  std::vector<stereo::MatcherOptions> options;
  for (pipeline::Algorithm a : algorithms) {
    pipeline::PipelineConfig config = pipeline::ConfigForAlgorithm(a);
    size_t g = 0;
    while (g < options.size() && !(options[g] == config.matcher)) ++g;
    if (g == options.size()) {
      options.push_back(config.matcher);
      groups.emplace_back();
    }
    groups[g].push_back(a);
  }
  return groups;
}

std::string GroupName(const std::vector<pipeline::Algorithm>& group) {
  std::string name;
  for (pipeline::Algorithm a : group) name += (name.empty() ? "" : ",") + Name(a);
  return name;
}

// --- pictures ---------------------------------------------------------------------------------

// Disparity (camera pixels) to colour, 0..top, black where `valid` is 0.
cv::Mat3b Colourise(const cv::Mat1f& d_px, const cv::Mat1b& valid, double top) {
  cv::Mat1b grey(d_px.size());
  for (int y = 0; y < d_px.rows; ++y) {
    for (int x = 0; x < d_px.cols; ++x) {
      grey(y, x) = cv::saturate_cast<uint8_t>(255.0 * d_px(y, x) / top);
    }
  }
  cv::Mat3b colour;
  cv::applyColorMap(grey, colour, cv::COLORMAP_TURBO);
  colour.setTo(cv::Scalar::all(0), valid == 0);
  return colour;
}

void Label(cv::Mat3b& image, const std::string& text, cv::Point at, const cv::Scalar& colour,
           double scale = 0.45) {
  at.y = std::clamp(at.y, 12, image.rows - 3);
  at.x = std::clamp(at.x, 0, std::max(0, image.cols - 8 * static_cast<int>(text.size())));
  cv::putText(image, text, at, cv::FONT_HERSHEY_SIMPLEX, scale, cv::Scalar::all(0), 3);
  cv::putText(image, text, at, cv::FONT_HERSHEY_SIMPLEX, scale, colour, 1);
}

// Truth on the grid, the pipeline's disparity (camera pixels), and the error: green within 1 px,
// yellow 1-3 px, red beyond 3 px, blue unmatched, black no truth.
void DumpDisparity(const testing::RealPair& pair, const pipeline::FrameResult& result,
                   const std::string& path) {
  cv::Mat1f truth;
  cv::Mat1b evaluated;
  testing::TruthOnGrid(pair, result.binning, truth, evaluated);
  const cv::Size size(std::min(truth.cols, result.disparity.fixed.cols),
                      std::min(truth.rows, result.disparity.fixed.rows));
  cv::Mat1f d(size, 0.0f);
  cv::Mat1b matched(size, uint8_t{0});
  cv::Mat3b error(size, cv::Vec3b(0, 0, 0));
  for (int y = 0; y < size.height; ++y) {
    for (int x = 0; x < size.width; ++x) {
      const std::optional<float> v = result.disparity.At(x, y);
      if (v) {
        d(y, x) = *v * static_cast<float>(result.binning);
        matched(y, x) = 255;
      }
      if (!evaluated(y, x)) continue;
      if (!v) {
        error(y, x) = {255, 80, 0};
        continue;
      }
      const double e = std::abs(d(y, x) - truth(y, x));
      error(y, x) = e <= 1   ? cv::Vec3b(0, 200, 0)
                    : e <= 3 ? cv::Vec3b(0, 220, 255)
                             : cv::Vec3b(0, 0, 255);
    }
  }
  double top = 0;
  cv::minMaxLoc(truth, nullptr, &top);
  top = std::max(top, 1.0);
  cv::Mat3b a =
      Colourise(truth(cv::Rect(cv::Point(), size)), evaluated(cv::Rect(cv::Point(), size)), top);
  cv::Mat3b b = Colourise(d, matched, top);
  Label(a, "truth (camera px, grid of binning " + std::to_string(result.binning) + ")", {4, 14},
        cv::Scalar::all(255));
  Label(b, "pipeline disparity x binning", {4, 14}, cv::Scalar::all(255));
  Label(error, "error: green <=1 px, yellow 1-3, red >3, blue unmatched", {4, 14},
        cv::Scalar::all(255));
  cv::Mat3b out;
  cv::vconcat(std::vector<cv::Mat>{a, b, error}, out);
  cv::imwrite(path, out);
}

cv::Scalar ObstacleColour(int id) {
  static const cv::Scalar kColours[] = {{0, 255, 0},     {255, 255, 0},  {0, 255, 255},
                                        {255, 0, 255},   {0, 160, 255},  {255, 128, 0},
                                        {128, 255, 128}, {200, 120, 255}};
  return kColours[static_cast<size_t>(id) % (sizeof kColours / sizeof kColours[0])];
}

// The truth obstacles: ground pixels tinted blue, above-ground pixels of no kept obstacle grey,
// each obstacle's pixels in its colour with its box and median depth.
void DumpTruth(const testing::RealPair& pair, const testing::GtScene& scene,
               const std::string& path) {
  cv::Mat3b out;
  cv::cvtColor(pair.left, out, cv::COLOR_GRAY2BGR);
  for (int y = 0; y < out.rows; ++y) {
    for (int x = 0; x < out.cols; ++x) {
      cv::Vec3b& p = out(y, x);
      const int id = scene.labels(y, x);
      cv::Scalar tint;
      double w = 0.5;
      if (id > 0) {
        tint = ObstacleColour(id);
        w = 0.6;
      } else if (scene.classes(y, x) == testing::kGtGround) {
        tint = {255, 0, 0};
        w = 0.3;
      } else if (scene.classes(y, x) == testing::kGtAbove) {
        tint = {128, 128, 128};
        w = 0.5;
      } else {
        continue;
      }
      for (int c = 0; c < 3; ++c) p[c] = cv::saturate_cast<uint8_t>((1 - w) * p[c] + w * tint[c]);
    }
  }
  for (const testing::GtObstacle& o : scene.obstacles) {
    cv::rectangle(out, o.bbox, ObstacleColour(o.id), 1);
    Label(out, "#" + std::to_string(o.id) + " " + Fmt("%.1fm", o.median_depth_m),
          {o.bbox.x, o.bbox.y - 3}, ObstacleColour(o.id));
  }
  Label(out, "truth: blue ground, grey above ground (not kept), colours: obstacles", {4, 14},
        cv::Scalar::all(255));
  cv::imwrite(path, out);
}

void DumpDetections(const testing::RealPair& pair, const testing::GtScene& scene, const Run& run,
                    const std::string& path) {
  cv::Mat3b out;
  cv::cvtColor(pair.left, out, cv::COLOR_GRAY2BGR);
  const cv::Scalar green(0, 220, 0), red(0, 0, 255), orange(0, 140, 255), magenta(255, 0, 255),
      cyan(255, 255, 0);
  for (const testing::GtObstacle& o : scene.obstacles) {
    cv::rectangle(out, o.bbox, green, 2);
    Label(out, "#" + std::to_string(o.id) + " " + Fmt("%.1fm", o.median_depth_m),
          {o.bbox.x, o.bbox.y + o.bbox.height + 13}, green);
  }
  for (size_t d = 0; d < run.boxes.size(); ++d) {
    const BoxVerdict v = run.score.boxes[d];
    const cv::Scalar colour = v == BoxVerdict::kMatched    ? red
                              : v == BoxVerdict::kFragment ? orange
                              : v == BoxVerdict::kFpFree   ? magenta
                                                           : cyan;
    cv::rectangle(out, run.boxes[d].bbox, colour, 1);
    Label(out, Fmt("%.1fm", run.boxes[d].depth_m), {run.boxes[d].bbox.x, run.boxes[d].bbox.y - 3},
          colour);
  }
  Label(out,
        Name(run.algorithm) + " max_width " + std::to_string(run.max_width_px) +
            ": truth green; red matched, orange fragment, magenta FP on free truth, cyan other FP",
        {4, 14}, cv::Scalar::all(255));
  cv::imwrite(path, out);
}

// --- JSON ----------------------------------------------------------------------------------------

std::string JsonScore(const testing::DisparityScore& s) {
  std::ostringstream j;
  j << "{\"evaluated\": " << s.evaluated << ", \"matched_pct\": " << s.MatchedPct()
    << ", \"bad1_raw_pct\": " << s.Bad1RawPct() << ", \"bad1_matched_pct\": " << s.Bad1MatchedPct()
    << ", \"bad3_raw_pct\": " << s.Bad3RawPct() << ", \"bad3_matched_pct\": " << s.Bad3MatchedPct()
    << ", \"d1_raw_pct\": " << s.D1RawPct() << ", \"d1_matched_pct\": " << s.D1MatchedPct()
    << ", \"mae_matched_px\": " << s.MaeMatched() << ", \"mae_raw_px\": " << s.MaeRaw() << "}";
  return j.str();
}

std::string JsonRect(const cv::Rect& r) {
  std::ostringstream j;
  j << "[" << r.x << ", " << r.y << ", " << r.width << ", " << r.height << "]";
  return j.str();
}

// --- tables --------------------------------------------------------------------------------------

struct DisparityRow {
  std::string pair, group, widths;
  std::vector<int> width_list;  // the max widths that give this binning
  bool kitti = false;
  int binning = 1;
  cv::Size grid;
  testing::DisparityScore score;
};

void PrintDisparityHeader() {
  std::printf("%-16s %-8s %3s %8s %7s %6s %6s %6s %6s %6s %6s %6s %6s %6s\n", "pair", "max_w",
              "bin", "grid", "eval", "match%", ">1raw", ">1mat", ">3raw", ">3mat", "D1raw", "D1mat",
              "MAEmat", "MAEraw");
}

void PrintDisparityRow(const std::string& pair, const std::string& widths, int binning,
                       const cv::Size& grid, double evaluated, double matched, double b1r,
                       double b1m, double b3r, double b3m, double d1r, double d1m, double maem,
                       double maer) {
  // binning 0: a mean over pairs (no one grid).
  char size[32] = "-", bin[16] = "-";
  if (binning > 0) {
    std::snprintf(size, sizeof size, "%dx%d", grid.width, grid.height);
    std::snprintf(bin, sizeof bin, "%d", binning);
  }
  std::printf("%-16s %-8s %3s %8s %7.0f %6.1f %6.2f %6.2f %6.2f %6.2f %6.2f %6.2f %6.2f %6.2f\n",
              pair.c_str(), widths.c_str(), bin, size, evaluated, matched, b1r, b1m, b3r, b3m, d1r,
              d1m, maem, maer);
}

// --- 4. the KITTI odometry sequence --------------------------------------------------------------

struct OdoRun {
  pipeline::Algorithm algorithm;
  bool with_poses = false;
  std::vector<testing::OdometryFrame> frames;
  std::vector<testing::OdoTrackFrame> confirmed;  // every frame's confirmed tracks
};

std::string RunName(const OdoRun& run) {
  return Name(run.algorithm) + (run.with_poses ? "+pose" : "");
}

// The figures of one run (printed and written as JSON).
struct OdoFigures {
  int tracks = 0;
  testing::StaticWorldScore world, world_floor, world_static;
  testing::GroundScore ground;
  std::vector<testing::CarScore> cars;
  int pose_ok = 0, georeferenced = 0;
  double geo_mismatch_m = 0;
  double total_ms = 0;
};

OdoFigures ScoreOdoRun(const testing::OdometrySequence& seq, const OdoRun& run,
                       const std::vector<std::optional<testing::GroundPlane>>& planes,
                       const std::vector<cv::Mat1f>& reference_disparity,
                       const std::vector<testing::LabelledBox>& labels) {
  OdoFigures f;
  std::vector<uint64_t> ids;
  for (const testing::OdoTrackFrame& t : run.confirmed) ids.push_back(t.id);
  std::sort(ids.begin(), ids.end());
  f.tracks = static_cast<int>(std::unique(ids.begin(), ids.end()) - ids.begin());
  testing::StaticWorldOptions w;
  f.world = testing::ScoreStaticWorld(run.confirmed, seq.poses, w);
  f.world_static = testing::ScoreStaticWorld(run.confirmed, seq.poses, w, labels);
  w.floor_m = 0.5;
  f.world_floor = testing::ScoreStaticWorld(run.confirmed, seq.poses, w);
  f.ground = testing::ScoreOnGround(run.confirmed, planes, seq.f_px, seq.baseline_m, seq.cx, seq.cy,
                                    0.3, &reference_disparity);
  f.cars = testing::ScoreCars(run.confirmed, labels);
  for (const testing::OdometryFrame& fr : run.frames) {
    f.pose_ok += fr.pose_ok;
    f.georeferenced += fr.georeferenced;
    f.geo_mismatch_m = std::max(f.geo_mismatch_m, fr.geo_mismatch_m);
    f.total_ms += fr.total_ms / static_cast<double>(run.frames.size());
  }
  return f;
}

std::string Pct(int n, int of) { return of ? Fmt("%.1f%%", 100.0 * n / of) : std::string("-"); }

void PrintOdoFrameTable(const testing::OdometrySequence& seq, const std::vector<OdoRun>& runs,
                        const std::vector<std::optional<testing::GroundPlane>>& planes,
                        const std::vector<testing::LabelledBox>& labels) {
  std::printf(
      "\nper frame: dets = FrameResult::detections, conf = tracks in state confirmed; road = "
      "camera height over the reference plane (m); car = labelled cars in the frame\n%5s %5s %4s",
      "frame", "road", "car");
  for (const OdoRun& run : runs) {
    std::printf(" %*s", static_cast<int>(RunName(run).size()) + 10,
                (RunName(run) + " dets/conf").c_str());
  }
  std::printf("\n");
  for (int k = 0; k < seq.frames(); ++k) {
    int cars = 0;
    for (const testing::LabelledBox& b : labels) cars += b.frame == k;
    const auto& plane = planes[static_cast<size_t>(k)];
    std::printf("%5d %5s %4d", k, plane ? Fmt("%.2f", plane->height_m).c_str() : "-", cars);
    for (const OdoRun& run : runs) {
      const testing::OdometryFrame& fr = run.frames[static_cast<size_t>(k)];
      std::printf(
          " %*s", static_cast<int>(RunName(run).size()) + 10,
          (std::to_string(fr.detections) + "/" + std::to_string(fr.confirmed.size())).c_str());
    }
    std::printf("\n");
  }
}

void PrintOdoSummary(const std::vector<OdoRun>& runs, const std::vector<OdoFigures>& figures) {
  std::printf(
      "\nsummary: conf = confirmed track-frames; world = static-world consistency of "
      "track-frames of tracks confirmed >= 2 frames: within max(5 %% of range, 3 |sigma|) of "
      "the track's median world point (target >= 90 %%); +0.5m: with a 0.5 m floor; "
      "static: without the track-frames on the labelled (moving) cars; med dev = median "
      "deviation (m);\n  ground = confirmed track-frames whose box top at their depth is "
      "< 0.3 m above the reference road (target < 2 %%); <road = whose box bottom at their "
      "depth is > 0.5 m under the road (the box reaches over nearer road); roadpx = >= half of "
      "the box's reference disparities on the road plane;\n  pose = frames with a pose; geo "
      "chk = largest distance between a georeferenced track's WGS84 point and its camera point "
      "carried by the true pose; car N = its scored full-view frames confirmed: IoU >= 0.3 or "
      "covering >= 50 %% of it (IoU >= 0.3 alone); its first 2 labelled frames are not scored\n");
  std::printf("%-16s %6s %6s %7s %7s %7s %7s %7s %7s %7s %5s %8s %7s", "run", "tracks", "conf",
              "world", "+0.5m", "static", "med dev", "ground", "<road", "roadpx", "pose", "geo chk",
              "ms/f");
  if (!figures.empty()) {
    for (const testing::CarScore& c : figures.front().cars) {
      std::printf(" %14s", ("car " + std::to_string(c.car) + " (IoU)").c_str());
    }
  }
  std::printf("\n");
  for (size_t i = 0; i < runs.size(); ++i) {
    const OdoFigures& f = figures[i];
    std::vector<double> dev = f.world.deviation_m;
    std::printf("%-16s %6d %6zu %7s %7s %7s %7s %7s %7s %7s %5d %8s %7.1f",
                RunName(runs[i]).c_str(), f.tracks, runs[i].confirmed.size(),
                Pct(f.world.consistent, f.world.track_frames).c_str(),
                Pct(f.world_floor.consistent, f.world_floor.track_frames).c_str(),
                Pct(f.world_static.consistent, f.world_static.track_frames).c_str(),
                MedianText(dev).c_str(), Pct(f.ground.on_ground, f.ground.scored).c_str(),
                Pct(f.ground.below_road, f.ground.scored).c_str(),
                Pct(f.ground.road_box, f.ground.scored).c_str(), f.pose_ok,
                f.georeferenced ? Fmt("%.3fm", f.geo_mismatch_m).c_str() : "-", f.total_ms);
    for (const testing::CarScore& c : f.cars) {
      std::printf(" %14s",
                  (std::to_string(c.confirmed_frames) + "/" + std::to_string(c.scored_frames) +
                   " (" + std::to_string(c.confirmed_iou_frames) + ")")
                      .c_str());
    }
    std::printf("\n");
  }
}

void DumpOdoFrame(const testing::OdometrySequence& seq, const OdoRun& run, int k,
                  const std::vector<testing::LabelledBox>& labels, const std::string& path) {
  cv::Mat3b out;
  cv::cvtColor(seq.left[static_cast<size_t>(k)], out, cv::COLOR_GRAY2BGR);
  const cv::Scalar green(0, 220, 0), red(0, 0, 255);
  for (const testing::LabelledBox& b : labels) {
    if (b.frame != k) continue;
    cv::rectangle(out, b.box, green, 2);
    Label(out, "car " + std::to_string(b.car), {b.box.x, b.box.y + b.box.height + 13}, green);
  }
  for (const cv::Rect& d : run.frames[static_cast<size_t>(k)].detection_boxes) {
    cv::rectangle(out, d, cv::Scalar(0, 160, 255), 1);
  }
  for (const testing::OdoTrackFrame& t : run.frames[static_cast<size_t>(k)].confirmed) {
    cv::rectangle(out, t.box, red, 2);
    Label(out, "#" + std::to_string(t.id) + " " + Fmt("%.1fm", cv::norm(t.position_cam_m)),
          {t.box.x, t.box.y - 3}, red);
  }
  const testing::OdometryFrame& fr = run.frames[static_cast<size_t>(k)];
  Label(out,
        RunName(run) + " frame " + std::to_string(k) + ": " + std::to_string(fr.detections) +
            " detections (thin orange), confirmed tracks red (#id range), labelled cars green",
        {4, 14}, cv::Scalar::all(255));
  cv::imwrite(path, out);
  // A JPEG beside it, small enough for a README.
  cv::imwrite(path.substr(0, path.rfind('.')) + ".jpg", out, {cv::IMWRITE_JPEG_QUALITY, 80});
}

std::string JsonOdometry(const testing::OdometrySequence& seq, const std::vector<OdoRun>& runs,
                         const std::vector<OdoFigures>& figures,
                         const std::vector<std::optional<testing::GroundPlane>>& planes) {
  std::ostringstream j;
  j << "{\"sequence\": \"" << seq.name << "\", \"frames\": " << seq.frames()
    << ", \"reference_camera_height_m\": [";
  for (size_t k = 0; k < planes.size(); ++k) {
    j << (k ? ", " : "") << (planes[k] ? Fmt("%.3f", planes[k]->height_m) : "null");
  }
  j << "], \"runs\": [";
  for (size_t i = 0; i < runs.size(); ++i) {
    const OdoFigures& f = figures[i];
    j << (i ? ", " : "") << "{\"algorithm\": \"" << Name(runs[i].algorithm)
      << "\", \"with_poses\": " << (runs[i].with_poses ? "true" : "false")
      << ", \"confirmed_tracks\": " << f.tracks
      << ", \"confirmed_track_frames\": " << runs[i].confirmed.size()
      << ", \"static_world\": {\"track_frames\": " << f.world.track_frames
      << ", \"consistent_pct\": " << f.world.Pct()
      << ", \"consistent_pct_floor_0_5m\": " << f.world_floor.Pct()
      << ", \"consistent_pct_without_labelled_cars\": " << f.world_static.Pct()
      << "}, \"on_ground\": {\"scored\": " << f.ground.scored
      << ", \"on_ground\": " << f.ground.on_ground << ", \"pct\": " << f.ground.Pct()
      << ", \"below_road_pct\": " << f.ground.BelowRoadPct()
      << ", \"road_box_pct\": " << f.ground.RoadBoxPct() << "}, \"pose_frames\": " << f.pose_ok
      << ", \"georeferenced_track_frames\": " << f.georeferenced
      << ", \"mean_total_ms\": " << f.total_ms << ", \"cars\": [";
    for (size_t c = 0; c < f.cars.size(); ++c) {
      const testing::CarScore& s = f.cars[c];
      j << (c ? ", " : "") << "{\"car\": " << s.car
        << ", \"labelled_frames\": " << s.labelled_frames
        << ", \"scored_frames\": " << s.scored_frames
        << ", \"confirmed_frames\": " << s.confirmed_frames << ", \"pct\": " << s.Pct()
        << ", \"confirmed_iou_frames\": " << s.confirmed_iou_frames
        << ", \"iou_pct\": " << s.IoUPct() << "}";
    }
    j << "], \"per_frame\": [";
    for (size_t k = 0; k < runs[i].frames.size(); ++k) {
      const testing::OdometryFrame& fr = runs[i].frames[k];
      j << (k ? ", " : "") << "{\"detections\": " << fr.detections
        << ", \"confirmed\": " << fr.confirmed.size() << "}";
    }
    j << "]}";
  }
  j << "]}";
  return j.str();
}

// Section 4. Returns the JSON (empty when skipped), or nullopt on a pipeline error.
std::optional<std::string> RunOdometryEval(const std::string& data_dir,
                                           const std::vector<pipeline::Algorithm>& algorithms,
                                           const bench::EvalFlags& flags) {
  std::string problem;
  std::optional<testing::OdometrySequence> seq = testing::LoadOdometrySequence(data_dir, problem);
  if (!seq) {
    std::printf("\n4. %s: skipped (%s)\n", testing::kKittiOdomSeqB, problem.c_str());
    return std::string();
  }
  const std::vector<testing::LabelledBox> labels =
      testing::LoadCarLabels(testing::CarLabelPath(), problem);
  if (labels.empty()) std::printf("car labels: none (%s)\n", problem.c_str());
  std::printf(
      "\n4. KITTI ODOMETRY SEQUENCE %s (%d frames, %s; f %.3f, B %.4f m): the pipeline with its "
      "tracker (default config but the algorithm), without and with the true poses "
      "(Snapshot::pose_at); reference road = SGBM 3-way + the RANSAC plane of gt_obstacles.h; "
      "%zu labelled car boxes (%s)\n",
      seq->name.c_str(), seq->frames(), seq->folder.c_str(), seq->f_px, seq->baseline_m,
      labels.size(), testing::CarLabelPath().c_str());
  std::vector<std::optional<testing::GroundPlane>> planes;
  std::vector<cv::Mat1f> reference_disparity;
  std::vector<double> heights;
  for (int k = 0; k < seq->frames(); ++k) {
    const auto g = testing::FitReferenceGround(seq->left[static_cast<size_t>(k)],
                                               seq->right[static_cast<size_t>(k)], seq->f_px,
                                               seq->baseline_m, seq->cx, seq->cy);
    planes.push_back(g ? std::optional<testing::GroundPlane>(g->plane) : std::nullopt);
    reference_disparity.push_back(g ? g->disparity_px : cv::Mat1f());
    if (g) heights.push_back(g->plane.height_m);
  }
  std::sort(heights.begin(), heights.end());
  std::printf(
      "reference road: a plane in %zu of %d frames; camera height over it median %s m "
      "(min %.2f, max %.2f; KITTI: 1.65 m)\n",
      heights.size(), seq->frames(),
      Fmt("%.2f", heights.empty() ? 0.0 : heights[heights.size() / 2]).c_str(),
      heights.empty() ? 0.0 : heights.front(), heights.empty() ? 0.0 : heights.back());
  std::vector<OdoRun> runs;
  for (pipeline::Algorithm a : algorithms) {
    for (const bool with_poses : {false, true}) {
      testing::OdometryRunOptions o;
      o.algorithm = a;
      o.max_width_px = flags.max_width_px;
      o.with_poses = with_poses;
      o.settings = flags.settings;
      Result<std::vector<testing::OdometryFrame>> frames = testing::RunOdometrySequence(*seq, o);
      if (!frames.ok()) {
        std::fprintf(stderr, "%s (%s): %s\n", seq->name.c_str(), Name(a).c_str(),
                     frames.error().message.c_str());
        return std::nullopt;
      }
      OdoRun run{a, with_poses, std::move(*frames), {}};
      for (const testing::OdometryFrame& fr : run.frames) {
        run.confirmed.insert(run.confirmed.end(), fr.confirmed.begin(), fr.confirmed.end());
      }
      runs.push_back(std::move(run));
    }
  }
  std::vector<OdoFigures> figures;
  for (const OdoRun& run : runs)
    figures.push_back(ScoreOdoRun(*seq, run, planes, reference_disparity, labels));
  PrintOdoFrameTable(*seq, runs, planes, labels);
  PrintOdoSummary(runs, figures);
  if (!flags.dump.empty()) {
    std::filesystem::create_directories(flags.dump);
    for (const OdoRun& run : runs) {
      if (!run.with_poses) continue;
      for (int k = 0; k < seq->frames(); ++k) {
        DumpOdoFrame(*seq, run, k, labels,
                     flags.dump + "/" + seq->name + "-" + Name(run.algorithm) + "-f" +
                         Fmt("%02.0f", k) + ".png");
      }
    }
  }
  return JsonOdometry(*seq, runs, figures, planes);
}

constexpr char kUsage[] =
    "usage: stevi-eval-real [--algorithm canonical|stevie|stevis|stixels|all] [--max-width N] "
    "[--scenario PAIR] [--json FILE] [--dump DIR]\n";

}  // namespace

int main(int argc, char** argv) {
  const auto usage = [](const std::string& problem) {
    std::fprintf(stderr, "stevi-eval-real: %s\n%s", problem.c_str(), kUsage);
    return 2;
  };
  const bench::EvalFlags flags =
      bench::ParseEvalFlagsOrExit("stevi-eval-real", kUsage, argc, argv, false, true, true);
  if (!flags.family.empty() || !flags.seeds.empty() || flags.max_frames > 0 || flags.width > 0) {
    return usage("--family, --seeds, --frames and --size do not apply to real pairs");
  }
  std::vector<pipeline::Algorithm> algorithms;
  if (flags.algorithm.empty() || flags.algorithm == "all") {
    // Every algorithm the pipeline knows by name.
    for (const auto& choice : pipeline::PipelineConfig::kAlgorithmNames) {
      algorithms.push_back(choice.value);
    }
  } else if (const std::optional<pipeline::Algorithm> a =
                 pipeline::AlgorithmFromName(flags.algorithm)) {
    algorithms = {*a};
  } else {
    return usage("--algorithm: expected an algorithm's name or all, got '" + flags.algorithm + "'");
  }
  std::vector<int> widths = {pipeline::PipelineConfig{}.max_width_px, 0};
  if (flags.max_width_px) widths = {*flags.max_width_px};
  {
    pipeline::PipelineConfig check;
    for (int w : widths) {
      check.max_width_px = w;
      if (!check.Validate().empty()) return usage("--max-width: " + check.Validate().front());
    }
  }

  const std::optional<std::string> data_dir = testing::DataDir();
  if (!data_dir) {
    std::printf(
        "stevi-eval-real: reference data folder not found: %s (set STEVI_DATA_DIR); "
        "skipped\n",
        testing::DataDirWanted().c_str());
    return 0;
  }
  if (flags.scenario == testing::kKittiOdomSeqB) {
    const std::optional<std::string> odometry = RunOdometryEval(*data_dir, algorithms, flags);
    if (!odometry) return 1;
    if (!flags.json.empty()) {
      std::ofstream json(flags.json);
      json << "{\"data_dir\": \"" << *data_dir
           << "\", \"odometry\": " << (odometry->empty() ? "null" : *odometry) << "}\n";
      if (!json) {
        std::fprintf(stderr, "stevi-eval-real: could not write %s\n", flags.json.c_str());
        return 1;
      }
    }
    return 0;
  }
  std::vector<std::string> names = testing::MiddleburyPairNames(true);
  for (const std::string& k : testing::KittiPairNames()) names.push_back(k);
  if (!flags.scenario.empty()) {
    if (std::find(names.begin(), names.end(), flags.scenario) == names.end()) {
      std::string all;
      for (const std::string& n : names) all += " " + n;
      return usage("--scenario: unknown pair '" + flags.scenario + "' (one of:" + all + " " +
                   testing::kKittiOdomSeqB + ")");
    }
    names = {flags.scenario};
  }
  std::vector<testing::RealPair> pairs;
  for (const std::string& name : names) {
    std::string problem;
    std::optional<testing::RealPair> pair = testing::LoadRealPair(*data_dir, name, problem);
    if (!pair) {
      std::printf("%s: skipped (%s)\n", name.c_str(), problem.c_str());
      continue;
    }
    pairs.push_back(std::move(*pair));
  }
  if (pairs.empty()) {
    std::printf("stevi-eval-real: no pair found under %s; skipped\n", data_dir->c_str());
    return 0;
  }
  if (!flags.dump.empty()) std::filesystem::create_directories(flags.dump);
  const auto groups = MatcherGroups(algorithms);
  const pipeline::PipelineConfig defaults;

  std::printf("data: %s\n", data_dir->c_str());
  std::printf(
      "matcher: PipelineConfig::matcher defaults (%s, block %d, %d disparities); one "
      "matcher for",
      std::string(stereo::MatcherKindName(defaults.matcher.kind)).c_str(),
      defaults.matcher.block_matching.block_size, defaults.matcher.num_disparities());
  for (const auto& g : groups) std::printf(" [%s]", GroupName(g).c_str());
  std::printf(" (the disparity does not depend on the algorithm)\n");
  std::printf("max_width_px: ");
  for (int w : widths) std::printf("%d%s ", w, w == 0 ? " (never bin)" : "");
  std::printf("\n\n");

  // Runs: per pair, per max width, per algorithm (Middlebury: the first algorithm of each matcher
  // group only; its disparity is all that is scored there).
  std::map<std::string, std::vector<Run>> runs;
  for (const testing::RealPair& pair : pairs) {
    for (int w : widths) {
      for (const auto& group : groups) {
        for (pipeline::Algorithm a : group) {
          if (!pair.kitti && a != group.front()) continue;
          Result<pipeline::FrameResult> result = testing::RunPipelineOnPair(pair, a, w);
          if (!result.ok()) {
            std::fprintf(stderr, "%s (%s, max_width %d): %s\n", pair.name.c_str(), Name(a).c_str(),
                         w, result.error().message.c_str());
            return 1;
          }
          Run run{a, w, std::move(*result), {}, {}};
          run.boxes = testing::CameraBoxes(run.result);
          runs[pair.name].push_back(std::move(run));
        }
      }
    }
  }

  // 1. Disparity.
  std::printf(
      "1. DISPARITY of the pipeline's matcher against the truth (camera px; binned maps "
      "on their grid against the median of each block's known truth)\n");
  std::printf(
      "   eval = evaluated pixels of the grid (Middlebury: non-occluded; KITTI: known); "
      "match%% = with a disparity; >1 / >3 = |error| > 1 / 3 px; D1 = KITTI's outlier "
      "(> 3 px and > 5 %%);\n   raw: unmatched count as bad, mat: matched pixels only; "
      "MAE (px): mat over matched, raw with unmatched taken as d = 0\n");
  std::vector<DisparityRow> rows;
  for (const testing::RealPair& pair : pairs) {
    for (const auto& group : groups) {
      std::map<int, std::vector<int>> width_list;  // binning -> the max widths that give it
      for (int w : widths) width_list[BinningFor(pair, w)].push_back(w);
      for (const auto& [bin, list] : width_list) {
        std::string text;
        for (int w : list) text += (text.empty() ? "" : ",") + std::to_string(w);
        for (const Run& run : runs[pair.name]) {
          if (run.algorithm != group.front() || run.result.binning != bin) continue;
          DisparityRow row{pair.name,
                           GroupName(group),
                           text,
                           list,
                           pair.kitti,
                           bin,
                           run.result.disparity.fixed.size(),
                           testing::ScoreDisparity(run.result.disparity, bin, pair)};
          rows.push_back(row);
          if (!flags.dump.empty()) {
            DumpDisparity(
                pair, run.result,
                flags.dump + "/" + pair.name + "-disparity-bin" + std::to_string(bin) + ".png");
          }
          break;
        }
      }
    }
  }
  for (const auto& group : groups) {
    if (groups.size() > 1) std::printf("matcher of [%s]\n", GroupName(group).c_str());
    PrintDisparityHeader();
    for (const bool kitti : {false, true}) {
      // Per max width: the mean over the set's pairs.
      std::map<int, std::vector<const DisparityRow*>> by_width;
      for (const DisparityRow& r : rows) {
        if (r.kitti != kitti || r.group != GroupName(group)) continue;
        const testing::DisparityScore& s = r.score;
        PrintDisparityRow(r.pair, r.widths, r.binning, r.grid, static_cast<double>(s.evaluated),
                          s.MatchedPct(), s.Bad1RawPct(), s.Bad1MatchedPct(), s.Bad3RawPct(),
                          s.Bad3MatchedPct(), s.D1RawPct(), s.D1MatchedPct(), s.MaeMatched(),
                          s.MaeRaw());
        for (int w : r.width_list) by_width[w].push_back(&r);
      }
      // One mean row per distinct set of rows (the max widths that give the same maps share it).
      std::vector<std::pair<std::vector<const DisparityRow*>, std::string>> means;
      for (const auto& [w, list] : by_width) {
        if (!means.empty() && means.back().first == list) {
          means.back().second += "," + std::to_string(w);
        } else {
          means.emplace_back(list, std::to_string(w));
        }
      }
      for (const auto& [list, text] : means) {
        double v[10] = {};
        for (const DisparityRow* r : list) {
          const testing::DisparityScore& s = r->score;
          const double x[10] = {static_cast<double>(s.evaluated),
                                s.MatchedPct(),
                                s.Bad1RawPct(),
                                s.Bad1MatchedPct(),
                                s.Bad3RawPct(),
                                s.Bad3MatchedPct(),
                                s.D1RawPct(),
                                s.D1MatchedPct(),
                                s.MaeMatched(),
                                s.MaeRaw()};
          for (int i = 0; i < 10; ++i) v[i] += x[i] / static_cast<double>(list.size());
        }
        PrintDisparityRow(
            std::string(kitti ? "mean KITTI " : "mean Midd. ") + std::to_string(list.size()), text,
            0, cv::Size(), v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8], v[9]);
      }
    }
  }

  // 2. KITTI truth obstacles.
  const testing::GtObstacleOptions gt_options;
  std::map<std::string, testing::GtScene> scenes;
  bool any_kitti = false;
  for (const testing::RealPair& pair : pairs) any_kitti = any_kitti || pair.kitti;
  if (any_kitti) {
    std::printf(
        "\n2. KITTI OBSTACLES FROM THE TRUTH DISPARITY (no labels): ground plane d = a u + "
        "b v + c by RANSAC (normal within %.0f deg of down), truth filled between scan "
        "lines (gaps <= %d rows), obstacle pixels >= %.2f m above the plane, components joining "
        "pixels within %d px whose disparities differ <= "
        "%.1f px + %.0f %%; kept: >= %d px, box >= %d px tall, median depth <= %.0f m\n",
        gt_options.max_ground_tilt_deg, gt_options.fill_gap_px, gt_options.min_height_m,
        gt_options.join_radius_px, gt_options.join_px, 100 * gt_options.join_fraction,
        gt_options.min_pixels, gt_options.min_box_height_px, gt_options.max_depth_m);
  }
  for (const testing::RealPair& pair : pairs) {
    if (!pair.kitti) continue;
    testing::GtScene scene = testing::ExtractGtObstacles(pair.truth_px, pair.f_px, pair.baseline_m,
                                                         pair.cx, pair.cy, gt_options);
    if (scene.ground) {
      const testing::GroundPlane& g = *scene.ground;
      std::printf(
          "%s: ground d = %.4f u + %.4f v %+.2f (%d inlier px): camera %.2f m up, pitch "
          "%+.2f deg, roll %+.2f deg; %d components, %zu kept\n",
          pair.name.c_str(), g.a, g.b, g.c, g.inliers, g.height_m, g.pitch_deg, g.roll_deg,
          scene.components, scene.obstacles.size());
    } else {
      std::printf("%s: no ground plane found\n", pair.name.c_str());
    }
    for (const testing::GtObstacle& o : scene.obstacles) {
      std::printf(
          "  #%-2d box x %4d-%4d y %3d-%3d  %6d px  d %6.2f px  Z %5.1f m (p10-p90 "
          "%5.1f-%5.1f)  top %4.1f m above ground\n",
          o.id, o.bbox.x, o.bbox.x + o.bbox.width - 1, o.bbox.y, o.bbox.y + o.bbox.height - 1,
          o.pixels, o.median_disparity_px, o.median_depth_m, o.depth_p10_m, o.depth_p90_m,
          o.height_top_m);
    }
    // The detectors' own ground model (SteViE and SteViS fit it to the pipeline's disparity), to
    // set beside the truth's plane.
    for (int w : widths) {
      for (const Run& run : runs[pair.name]) {
        if (run.max_width_px != w) continue;
        const std::optional<detection::GroundModel> model =
            detection::FitGround(run.result.disparity, defaults.stevie.ground);
        const int bin = std::max(1, run.result.binning);
        if (model) {
          std::printf(
              "  detectors' ground model (max width %d): camera %.2f m up, horizon row %.1f "
              "(camera px), %d support rows\n",
              w, model->CameraHeight(pair.baseline_m), model->horizon_row * bin + (bin - 1) / 2.0,
              model->support_rows);
        } else {
          std::printf(
              "  detectors' ground model (max width %d): none found (every disparity "
              "stands out)\n",
              w);
        }
        break;
      }
    }
    if (!flags.dump.empty()) DumpTruth(pair, scene, flags.dump + "/" + pair.name + "-truth.png");
    scenes[pair.name] = std::move(scene);
  }

  // 3. Detections on KITTI.
  struct Totals {
    int truth = 0, found = 0, found5 = 0, fragments = 0, detections = 0, fp = 0, fp_free = 0,
        fp_structure = 0, fp_wrong_depth = 0, fp_no_truth = 0;
    std::vector<double> errors;
  };
  std::map<std::pair<int, int>, Totals> totals;  // (algorithm, max width)
  if (any_kitti) {
    std::printf(
        "\n3. DETECTIONS ON KITTI (FrameResult::detections of one frame, boxes x binning) "
        "against the truth obstacles: found = IoU >= 0.3 one-to-one; frag = unmatched "
        "boxes >= 50 %% inside a truth box;\n   FP = the rest: free = on known truth that "
        "is ground, struct = on above-ground truth at its depth (+-15 %%: a real thing not "
        "kept, e.g. far, small, a wall), wrongZ = on above-ground truth at another depth, "
        "noGT = < 10 %% of the box has truth\n");
    std::printf("%-16s %-9s %5s %3s %4s %4s %5s %5s %4s %4s %5s %6s %4s %4s %10s\n", "pair",
                "algorithm", "max_w", "bin", "dets", "GT", "found", "<5%", "frag", "FP", "free",
                "struct", "wrZ", "noGT", "|err| med");
  }
  for (const testing::RealPair& pair : pairs) {
    if (!pair.kitti) continue;
    const testing::GtScene& scene = scenes[pair.name];
    for (Run& run : runs[pair.name]) {
      run.score = testing::ScoreDetections(scene, pair.f_px, pair.baseline_m, run.boxes);
      const testing::DetectionScore& s = run.score;
      Totals& t = totals[{static_cast<int>(run.algorithm), run.max_width_px}];
      std::vector<double> errors;
      int found5 = 0;
      for (const testing::ObstacleResult& r : s.obstacles) {
        if (r.detection < 0) continue;
        errors.push_back(std::abs(r.range_error_pct));
        found5 += std::abs(r.range_error_pct) < 5.0;
      }
      t.truth += static_cast<int>(scene.obstacles.size());
      t.found += s.found;
      t.found5 += found5;
      t.fragments += s.fragments;
      t.detections += static_cast<int>(run.boxes.size());
      t.fp += s.fp;
      t.fp_free += s.fp_free;
      t.fp_structure += s.fp_structure;
      t.fp_wrong_depth += s.fp_wrong_depth;
      t.fp_no_truth += s.fp_no_truth;
      t.errors.insert(t.errors.end(), errors.begin(), errors.end());
      std::printf("%-16s %-9s %5d %3d %4zu %4zu %5d %5d %4d %4d %5d %6d %4d %4d %9s%%\n",
                  pair.name.c_str(), Name(run.algorithm).c_str(), run.max_width_px,
                  run.result.binning, run.boxes.size(), scene.obstacles.size(), s.found, found5,
                  s.fragments, s.fp, s.fp_free, s.fp_structure, s.fp_wrong_depth, s.fp_no_truth,
                  MedianText(errors).c_str());
      if (!flags.dump.empty()) {
        DumpDetections(pair, scene, run,
                       flags.dump + "/" + pair.name + "-" + Name(run.algorithm) + "-mw" +
                           std::to_string(run.max_width_px) + ".png");
      }
    }
  }
  if (any_kitti) {
    std::printf("all KITTI pairs (|err| med: median |range error| of the found obstacles)\n");
    for (const auto& [key, t] : totals) {
      std::printf("%-16s %-9s %5d %3s %4d %4d %5d %5d %4d %4d %5d %6d %4d %4d %9s%%\n", "  total",
                  Name(static_cast<pipeline::Algorithm>(key.first)).c_str(), key.second, "",
                  t.detections, t.truth, t.found, t.found5, t.fragments, t.fp, t.fp_free,
                  t.fp_structure, t.fp_wrong_depth, t.fp_no_truth, MedianText(t.errors).c_str());
    }
    // Per obstacle: one column per run.
    std::printf(
        "\nper truth obstacle: range error of the matched box (%%) and [+fragments]; "
        "'-' missed\n");
    for (const testing::RealPair& pair : pairs) {
      if (!pair.kitti) continue;
      const std::vector<Run>& list = runs[pair.name];
      std::printf("%-16s %-24s", pair.name.c_str(), "obstacle");
      for (const Run& run : list) {
        std::printf(" %12s",
                    (Name(run.algorithm) + "/" + std::to_string(run.max_width_px)).c_str());
      }
      std::printf("\n");
      const testing::GtScene& scene = scenes[pair.name];
      for (size_t k = 0; k < scene.obstacles.size(); ++k) {
        const testing::GtObstacle& o = scene.obstacles[k];
        char what[64];
        std::snprintf(what, sizeof what, "#%d %.1f m %dx%d", o.id, o.median_depth_m, o.bbox.width,
                      o.bbox.height);
        std::printf("%-16s %-24s", "", what);
        for (const Run& run : list) {
          const testing::ObstacleResult& r = run.score.obstacles[k];
          std::string cell = r.detection < 0 ? "-" : Fmt("%+.1f", r.range_error_pct);
          if (r.fragments > 0) cell += " [+" + std::to_string(r.fragments) + "]";
          std::printf(" %12s", cell.c_str());
        }
        std::printf("\n");
      }
    }
  }

  // 4. The KITTI odometry sequence (with every pair; alone with --scenario kitti-odom-seq-b).
  std::string odometry;
  if (flags.scenario.empty()) {
    const std::optional<std::string> o = RunOdometryEval(*data_dir, algorithms, flags);
    if (!o) return 1;
    odometry = *o;
  }

  if (!flags.json.empty()) {
    std::ofstream json(flags.json);
    json << "{\"data_dir\": \"" << *data_dir << "\", \"max_width_px\": [";
    for (size_t i = 0; i < widths.size(); ++i) json << (i ? ", " : "") << widths[i];
    json << "], \"disparity\": [";
    for (size_t i = 0; i < rows.size(); ++i) {
      const DisparityRow& r = rows[i];
      json << (i ? ", " : "") << "{\"pair\": \"" << r.pair << "\", \"algorithms\": \"" << r.group
           << "\", \"max_width_px\": \"" << r.widths << "\", \"binning\": " << r.binning
           << ", \"score\": " << JsonScore(r.score) << "}";
    }
    json << "], \"kitti\": [";
    bool first_pair = true;
    for (const testing::RealPair& pair : pairs) {
      if (!pair.kitti) continue;
      const testing::GtScene& scene = scenes[pair.name];
      json << (first_pair ? "" : ", ") << "{\"pair\": \"" << pair.name << "\", \"ground\": ";
      first_pair = false;
      if (scene.ground) {
        const testing::GroundPlane& g = *scene.ground;
        json << "{\"a\": " << g.a << ", \"b\": " << g.b << ", \"c\": " << g.c
             << ", \"inliers\": " << g.inliers << ", \"height_m\": " << g.height_m
             << ", \"pitch_deg\": " << g.pitch_deg << ", \"roll_deg\": " << g.roll_deg << "}";
      } else {
        json << "null";
      }
      json << ", \"obstacles\": [";
      for (size_t k = 0; k < scene.obstacles.size(); ++k) {
        const testing::GtObstacle& o = scene.obstacles[k];
        json << (k ? ", " : "") << "{\"id\": " << o.id << ", \"bbox\": " << JsonRect(o.bbox)
             << ", \"pixels\": " << o.pixels
             << ", \"median_disparity_px\": " << o.median_disparity_px
             << ", \"median_depth_m\": " << o.median_depth_m
             << ", \"depth_p10_m\": " << o.depth_p10_m << ", \"depth_p90_m\": " << o.depth_p90_m
             << "}";
      }
      json << "], \"runs\": [";
      const std::vector<Run>& list = runs[pair.name];
      for (size_t i = 0; i < list.size(); ++i) {
        const Run& run = list[i];
        const testing::DetectionScore& s = run.score;
        json << (i ? ", " : "") << "{\"algorithm\": \"" << Name(run.algorithm)
             << "\", \"max_width_px\": " << run.max_width_px
             << ", \"binning\": " << run.result.binning << ", \"found\": " << s.found
             << ", \"fragments\": " << s.fragments << ", \"fp\": " << s.fp
             << ", \"fp_free\": " << s.fp_free << ", \"fp_structure\": " << s.fp_structure
             << ", \"fp_wrong_depth\": " << s.fp_wrong_depth
             << ", \"fp_no_truth\": " << s.fp_no_truth << ", \"obstacles\": [";
        for (size_t k = 0; k < s.obstacles.size(); ++k) {
          const testing::ObstacleResult& r = s.obstacles[k];
          json << (k ? ", " : "") << "{\"id\": " << scene.obstacles[k].id
               << ", \"found\": " << (r.detection >= 0 ? "true" : "false") << ", \"iou\": " << r.iou
               << ", \"range_error_pct\": "
               << (r.detection >= 0 ? Fmt("%.3f", r.range_error_pct) : "null")
               << ", \"fragments\": " << r.fragments << "}";
        }
        json << "], \"detections\": [";
        for (size_t d = 0; d < run.boxes.size(); ++d) {
          json << (d ? ", " : "") << "{\"bbox\": " << JsonRect(run.boxes[d].bbox)
               << ", \"depth_m\": " << run.boxes[d].depth_m << ", \"verdict\": \""
               << testing::BoxVerdictName(s.boxes[d]) << "\"}";
        }
        json << "]}";
      }
      json << "]}";
    }
    json << "], \"odometry\": " << (odometry.empty() ? "null" : odometry) << "}\n";
    if (!json) {
      std::fprintf(stderr, "stevi-eval-real: could not write %s\n", flags.json.c_str());
      return 1;
    }
  }
  return 0;
}
