#include "core/detection/canonical.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "core/geometry/range.h"
#include "core/geometry/stereo_rig.h"
#include "core/stereo/disparity.h"
#include "core/stereo/matcher.h"
#include "drivers/synthetic/synthetic_source.h"
#include "tests/core/detection/disparity_fixtures.h"
#include "tests/testing/truth_match.h"

namespace stevi::detection {
namespace {

using geometry::RangeOptions;
using geometry::StereoRig;
using stereo::DisparityMap;

using namespace fixtures;  // kF, kB, TestRig, EmptyMap, Paint

// The detection whose box overlaps `r` most, if any overlaps.
std::optional<Detection> Overlapping(const std::vector<Detection>& detections, const cv::Rect& r) {
  std::optional<Detection> best;
  int best_overlap = 0;
  for (const Detection& d : detections) {
    const int overlap = (d.bbox & r).area();
    if (overlap > best_overlap) {
      best_overlap = overlap;
      best = d;
    }
  }
  return best;
}

TEST(DetectCanonical, AnalyticMapGivesTheRectanglesAndTheirDepths) {
  const StereoRig rig = TestRig();
  DisparityMap map = EmptyMap(rig.image_size());
  map.fixed(cv::Rect(0, 300, 640, 180)).setTo(cv::Scalar(2 * DisparityMap::kScale));  // far ground
  const cv::Rect near(50, 60, 80, 60);   // d = 42 px: 10 m
  const cv::Rect mid(250, 100, 60, 50);  // d = 21 px: 20 m
  const cv::Rect odd(420, 40, 33, 45);   // d = 16.5 px: 25.45 m
  Paint(map, near, 42.0);
  Paint(map, mid, 21.0);
  Paint(map, odd, 16.5);

  const std::vector<Detection> detections = DetectCanonical(map, rig, RangeOptions{}, {});
  ASSERT_EQ(detections.size(), 3u);
  for (const auto& [rect, d_px] : {std::pair{near, 42.0}, {mid, 21.0}, {odd, 16.5}}) {
    std::optional<Detection> det = Overlapping(detections, rect);
    ASSERT_TRUE(det.has_value()) << rect;
    EXPECT_EQ(det->bbox, rect);
    EXPECT_EQ(det->area_px, rect.area());
    EXPECT_DOUBLE_EQ(det->disparity_px, d_px);
    EXPECT_EQ(det->valid_disparities, rect.area());
    EXPECT_NEAR(det->depth_m, kF * kB / d_px, 1e-9);
    EXPECT_GE(det->range_m, det->depth_m);
    EXPECT_GT(det->range_sigma_m, 0.0);
    EXPECT_NEAR(det->score, 1.0, 1e-12);  // one surface, every pixel valid
    EXPECT_EQ(det->extractor, "canonical");
    EXPECT_NEAR(det->perimeter_px, 2.0 * (rect.width + rect.height), 1e-6);  // the box's
  }
}

TEST(DetectCanonical, DropsWideBlobsBlobsBelowTheFloorAndSmallBlobs) {
  const StereoRig rig = TestRig();
  DisparityMap map = EmptyMap(rig.image_size());
  const cv::Rect kept(300, 300, 40, 40);
  Paint(map, kept, 30.0);
  Paint(map, cv::Rect(20, 20, 540, 30), 30.0);  // 540 > 0.8 * 640: the skyline
  Paint(map, cv::Rect(50, 200, 60, 60), 2.0);   // below the 2.5 px floor
  Paint(map, cv::Rect(200, 200, 60, 60), 4.5);  // 93 m: beyond the automatic threshold
                                                // (20 sigmas = 5 px: 84 m)
  Paint(map, cv::Rect(500, 300, 4, 4), 30.0);   // 16 px < 20 px
  const std::vector<Detection> detections = DetectCanonical(map, rig, RangeOptions{}, {});
  ASSERT_EQ(detections.size(), 1u);
  EXPECT_EQ(detections[0].bbox, kept);

  // A narrower blob of the same disparity is kept when the width limit allows it.
  CanonicalOptions wide_ok;
  wide_ok.blobs.max_width_fraction = 0.9;
  EXPECT_EQ(DetectCanonical(map, rig, RangeOptions{}, wide_ok).size(), 2u);
}

TEST(DetectCanonical, RangeOptionsBoundTheTrustedInterval) {
  const StereoRig rig = TestRig();
  DisparityMap map = EmptyMap(rig.image_size());
  Paint(map, cv::Rect(100, 100, 50, 50), 42.0);  // 10 m
  Paint(map, cv::Rect(300, 100, 50, 50), 14.0);  // 30 m
  Paint(map, cv::Rect(450, 100, 50, 50), 8.0);   // 52.5 m

  RangeOptions range;
  range.max_range_m = 40.0;
  std::vector<Detection> detections = DetectCanonical(map, rig, range, {});
  ASSERT_EQ(detections.size(), 2u);
  for (const Detection& d : detections) EXPECT_LE(d.depth_m, 40.0);

  range = RangeOptions{};
  range.min_disparity_px = 10.0;
  detections = DetectCanonical(map, rig, range, {});
  ASSERT_EQ(detections.size(), 2u);
  for (const Detection& d : detections) EXPECT_GE(d.disparity_px, 10.0);
}

TEST(DetectCanonical, OpeningCutsAThinBridge) {
  const StereoRig rig = TestRig();
  DisparityMap map = EmptyMap(rig.image_size());
  Paint(map, cv::Rect(100, 100, 40, 40), 30.0);
  Paint(map, cv::Rect(200, 100, 40, 40), 30.0);
  Paint(map, cv::Rect(140, 120, 60, 2), 30.0);  // 2 px bridge
  EXPECT_EQ(DetectCanonical(map, rig, RangeOptions{}, {}).size(), 2u);
  CanonicalOptions no_open;
  no_open.open_size_px = 1;
  EXPECT_EQ(DetectCanonical(map, rig, RangeOptions{}, no_open).size(), 1u);
}

TEST(CanonicalOptionsValidate, ListsEveryProblem) {
  EXPECT_TRUE(CanonicalOptions{}.Validate().empty());
  CanonicalOptions bad;
  bad.threshold_range_m = -1;
  bad.blobs.min_area_px = 0;
  bad.blobs.max_width_fraction = 1.5;
  bad.open_size_px = 4;
  bad.blobs.min_valid_fraction = -0.1;
  const std::vector<std::string> problems = bad.Validate();
  ASSERT_EQ(problems.size(), 5u);
  const char* fields[] = {"threshold_range_m: ", "open_size_px: ", "blobs.min_area_px: ",
                          "blobs.max_width_fraction: ", "blobs.min_valid_fraction: "};
  const char* got[] = {"(got -1)", "(got 4)", "(got 0)", "(got 1.5)", "(got -0.1)"};
  for (int i = 0; i < 5; ++i) {
    EXPECT_EQ(problems[i].rfind(fields[i], 0), 0u) << problems[i];
    EXPECT_NE(problems[i].find(got[i]), std::string::npos) << problems[i];
  }
  bad = CanonicalOptions{};
  bad.blobs.max_width_fraction = 0;
  bad.open_size_px = 0;
  EXPECT_EQ(bad.Validate().size(), 2u);
}

TEST(FillRange, UsesQAndScalesTheSigmaToRange) {
  const StereoRig rig = TestRig();
  Detection d;
  d.centroid_px = cv::Point2d(320 + 140, 240 - 70);
  d.disparity_px = 21.0;  // 20 m
  FillRange(d, rig, RangeOptions{});
  EXPECT_NEAR(d.depth_m, 20.0, 1e-9);
  EXPECT_NEAR(d.position_cam_m[0], 140 * 20.0 / kF, 1e-6);
  EXPECT_NEAR(d.position_cam_m[1], -70 * 20.0 / kF, 1e-6);
  EXPECT_NEAR(d.position_cam_m[2], 20.0, 1e-6);
  EXPECT_NEAR(d.range_m, cv::norm(d.position_cam_m), 1e-9);
  const double depth_sigma = 20.0 * 20.0 / (kF * kB) * 0.25;
  EXPECT_NEAR(d.range_sigma_m, depth_sigma * d.range_m / 20.0, 1e-9);
}

// ---- The synthetic scene -------------------------------------------------------------------

DisparityMap FromTruth(const cv::Mat1f& truth) {
  DisparityMap map;
  map.fixed = cv::Mat1s(truth.size());
  for (int y = 0; y < truth.rows; ++y) {
    for (int x = 0; x < truth.cols; ++x) {
      const float d = truth(y, x);
      map.fixed(y, x) = d > 0 ? static_cast<int16_t>(std::lround(d * DisparityMap::kScale))
                              : DisparityMap::kInvalid;
    }
  }
  map.num_disparities = 64;
  return map;
}

// True when a visible pixel of `o` is next to (8-neighbourhood) a visible pixel of another
// obstacle of `near`: their disparities are both above the threshold, so one blob holds both.
bool TouchesAnother(const drivers::FrameTruth& truth, const drivers::ObstacleTruth& o,
                    const std::vector<const drivers::ObstacleTruth*>& near) {
  const cv::Rect image(0, 0, truth.object_id.cols, truth.object_id.rows);
  const cv::Rect box = (o.bbox + cv::Size(2, 2) - cv::Point(1, 1)) & image;
  const cv::Mat1b own = truth.object_id(box) == o.id;
  cv::Mat1b grown;
  cv::dilate(own, grown, cv::Mat1b(3, 3, uchar{1}));
  for (const drivers::ObstacleTruth* other : near) {
    if (other->id == o.id) continue;
    const cv::Mat1b theirs = truth.object_id(box) == other->id;
    if (cv::countNonZero(grown & theirs) > 0) return true;
  }
  return false;
}

struct Tally {
  int eligible = 0;
  int matched = 0;
  int merged = 0;          // touching another near obstacle: a canonical blob may merge them
  int merged_matched = 0;  // ... and matched all the same (IoU >= 0.3)
  double worst_depth_error = 0;
};

// Matches the detections of one frame to its truth; checks depth (within `depth_tol`) for
// obstacles whose truth disparity is at least min_truth_disparity_px.
void Score(const drivers::FrameTruth& truth, const std::vector<Detection>& detections,
           const CanonicalOptions& options, double min_truth_disparity_px, double depth_tol,
           Tally& tally, const char* label) {
  const double fb = kF * kB;
  std::vector<const drivers::ObstacleTruth*> near;
  for (const drivers::ObstacleTruth& o : truth.obstacles) {
    // The automatic threshold: 20 disparity sigmas (5 px, 84 m on this rig).
    const double threshold_m = options.threshold_range_m > 0
                                   ? options.threshold_range_m
                                   : kF * kB / (20 * RangeOptions{}.disparity_sigma_px);
    if (o.visible_px >= options.blobs.min_area_px && !o.bbox.empty() && o.depth_m < threshold_m) {
      near.push_back(&o);
    }
  }
  for (const drivers::ObstacleTruth* o : near) {
    const double truth_d = testing::MedianOverId(truth.object_id, truth.disparity_px, o->id);
    if (truth_d < min_truth_disparity_px) continue;
    const bool touches = TouchesAnother(truth, *o, near);
    const Detection* best = nullptr;
    double best_iou = 0;
    for (const Detection& d : detections) {
      const double iou = testing::IoU(d.bbox, o->bbox);
      if (iou > best_iou) {
        best_iou = iou;
        best = &d;
      }
    }
    const double truth_depth = fb / truth_d;
    std::printf("  %s frame %3lld %-10s truth box %3dx%3d@(%3d,%3d) depth %6.2f m (face %6.2f m)",
                label, static_cast<long long>(truth.index), o->name.c_str(), o->bbox.width,
                o->bbox.height, o->bbox.x, o->bbox.y, truth_depth, o->depth_m);
    if (touches) {
      ++tally.merged;
      if (best && best_iou >= 0.3) ++tally.merged_matched;
      std::printf("  touches another obstacle: not scored%s\n",
                  best && best_iou >= 0.3 ? " (matched anyway)" : "");
      continue;
    }
    ++tally.eligible;
    if (best == nullptr || best_iou < 0.3) {
      std::printf("  MISSED (best IoU %.2f)\n", best_iou);
      continue;
    }
    ++tally.matched;
    const double error = std::abs(best->depth_m - truth_depth) / truth_depth;
    tally.worst_depth_error = std::max(tally.worst_depth_error, error);
    std::printf("  -> IoU %.2f depth %6.2f m error %5.2f %%\n", best_iou, best->depth_m,
                100 * error);
    EXPECT_LE(error, depth_tol) << label << " frame " << truth.index << " " << o->name << ": truth "
                                << truth_depth << " m, measured " << best->depth_m;
  }
}

constexpr int64_t kFrames[] = {0, 7, 15, 23, 31, 40, 55, 70};

TEST(DetectCanonical, TruthDisparityOfTheSyntheticSceneFindsTheNearObstacles) {
  const drivers::SyntheticRenderer renderer{drivers::SyntheticOptions{}};
  const StereoRig rig = renderer.Rig();
  ASSERT_DOUBLE_EQ(rig.f_px() * rig.baseline_m(), kF * kB);
  const CanonicalOptions options;
  Tally tally;
  for (int64_t index : kFrames) {
    drivers::FrameTruth truth;
    renderer.Render(index, &truth);
    const std::vector<Detection> detections =
        DetectCanonical(FromTruth(truth.disparity_px), rig, RangeOptions{}, options);
    Score(truth, detections, options, RangeOptions{}.min_disparity_px, 0.02, tally, "truth");
  }
  std::printf(
      "truth disparity: recall %d/%d isolated obstacles; %d/%d touching ones matched "
      "anyway (not scored); worst depth error %.3f %%\n",
      tally.matched, tally.eligible, tally.merged_matched, tally.merged,
      100 * tally.worst_depth_error);
  ASSERT_GT(tally.eligible, 0);
  EXPECT_EQ(tally.matched, tally.eligible);
}

TEST(DetectCanonical, BlockMatchingOnTheSyntheticSceneMeasuresDepthWithin2Percent) {
  const drivers::SyntheticRenderer renderer{drivers::SyntheticOptions{}};
  const StereoRig rig = renderer.Rig();
  const std::unique_ptr<stereo::DisparityMatcher> matcher =
      stereo::MakeMatcher(stereo::MatcherOptions{});
  const CanonicalOptions options;
  Tally tally;
  for (int64_t index : kFrames) {
    drivers::FrameTruth truth;
    const StereoFrame frame = renderer.Render(index, &truth);
    const DisparityMap disparity = matcher->Compute(frame.left, frame.right);
    const std::vector<Detection> detections =
        DetectCanonical(disparity, rig, RangeOptions{}, options);
    Score(truth, detections, options, 8.0, 0.02, tally, "BM");
  }
  const double recall =
      tally.eligible > 0 ? static_cast<double>(tally.matched) / tally.eligible : 0;
  std::printf(
      "block matching: recall %d/%d = %.0f %% of isolated obstacles; %d/%d touching ones "
      "matched anyway (not scored); worst depth error %.2f %%\n",
      tally.matched, tally.eligible, 100 * recall, tally.merged_matched, tally.merged,
      100 * tally.worst_depth_error);
  ASSERT_GT(tally.eligible, 0);
  EXPECT_GE(recall, 0.8);
}

}  // namespace
}  // namespace stevi::detection
