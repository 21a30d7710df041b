// The pipeline on real stereo pairs with ground truth (the shared reference data, testing/data.h):
// the obstacles delimited from KITTI's truth disparity (testing/gt_obstacles.h) against the data
// README's independent description, and bounds on the pipeline's disparity error and on SteViE's
// ranging that fail when the pipeline gets worse. The full report is stevi-eval-real
// (tests/bench/README.md). The scoring itself is checked on synthetic maps first (no data needed).
#include <cmath>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "core/pipeline/config.h"
#include "tests/testing/data.h"
#include "tests/testing/gt_obstacles.h"
#include "tests/testing/real_pairs.h"
#include "tests/testing/real_pairs_pipeline.h"

namespace stevi::testing {
namespace {

// KITTI's rectified rig (calib_cam_to_cam.txt, P_rect_02 / P_rect_03).
constexpr double kF = 721.5377, kB = 0.5327, kCx = 609.5593, kCy = 172.854;

stereo::DisparityMap MapOf(const cv::Mat1f& d_px) {
  stereo::DisparityMap map;
  map.fixed.create(d_px.size());
  for (int y = 0; y < d_px.rows; ++y) {
    for (int x = 0; x < d_px.cols; ++x) {
      map.fixed(y, x) = d_px(y, x) < 0 ? stereo::DisparityMap::kInvalid
                                       : static_cast<int16_t>(std::lround(d_px(y, x) * 16));
    }
  }
  return map;
}

TEST(RealPairsScoring, DisparityScoreCountsRawAndMatched) {
  RealPair pair;
  pair.truth_px = cv::Mat1f(4, 4, 10.0f);
  pair.truth_px(0, 0) = 0;  // unknown: not evaluated
  pair.evaluated = pair.truth_px > 0;
  cv::Mat1f d(4, 4, 10.5f);
  d(0, 1) = -1;     // unmatched
  d(0, 2) = 12.0f;  // 2 px off: bad1
  d(0, 3) = 14.0f;  // 4 px off: bad3, and > 5 % of 10: D1
  const DisparityScore s = ScoreDisparity(MapOf(d), 1, pair);
  EXPECT_EQ(s.evaluated, 15);
  EXPECT_EQ(s.matched, 14);
  EXPECT_EQ(s.bad1_raw, 3);
  EXPECT_EQ(s.bad1_matched, 2);
  EXPECT_EQ(s.bad3_raw, 2);
  EXPECT_EQ(s.bad3_matched, 1);
  EXPECT_EQ(s.d1_matched, 1);
  EXPECT_NEAR(s.MaeMatched(), (12 * 0.5 + 2 + 4) / 14.0, 1e-6);
  EXPECT_NEAR(s.MaeRaw(), (12 * 0.5 + 2 + 4 + 10) / 15.0, 1e-6);
}

TEST(RealPairsScoring, BinnedTruthIsTheMedianOfKnownBlocks) {
  RealPair pair;
  pair.truth_px = cv::Mat1f::zeros(2, 4);
  // Block 0: 10, 12, 14 and one unknown -> 12. Block 1: one known value of four -> not evaluated.
  pair.truth_px(0, 0) = 10;
  pair.truth_px(0, 1) = 14;
  pair.truth_px(1, 0) = 12;
  pair.truth_px(1, 3) = 30;
  pair.evaluated = pair.truth_px > 0;
  cv::Mat1f truth;
  cv::Mat1b evaluated;
  TruthOnGrid(pair, 2, truth, evaluated);
  ASSERT_EQ(truth.size(), cv::Size(2, 1));
  EXPECT_FLOAT_EQ(truth(0, 0), 12.0f);
  EXPECT_TRUE(evaluated(0, 0));
  EXPECT_FALSE(evaluated(0, 1));
  // A binned map of 6.25 px is 12.5 camera px: 0.5 px off.
  const DisparityScore s = ScoreDisparity(MapOf(cv::Mat1f(1, 2, 6.25f)), 2, pair);
  EXPECT_EQ(s.evaluated, 1);
  EXPECT_NEAR(s.MaeMatched(), 0.5, 1e-6);
}

// A level road seen from 1.65 m and a box 1.8 m wide, 1.5 m tall at 10 m, both as LiDAR-like
// truth: one scan line every 5 rows.
TEST(RealPairsScoring, ObstacleStandingOnTheRoadIsExtracted) {
  cv::Mat1f truth = cv::Mat1f::zeros(375, 1242);
  const double h = 1.65, z_box = 10.0;
  for (int v = 0; v < truth.rows; v += 5) {
    for (int u = 0; u < truth.cols; ++u) {
      // Ground: Y = h, so Z = f h / (v - cy).
      if (v > kCy + 5) truth(v, u) = static_cast<float>(kB * (v - kCy) / h);
      const double x = (u - kCx) * z_box / kF, y = (v - kCy) * z_box / kF;
      if (x > -0.9 && x < 0.9 && y > h - 1.5 && y < h)
        truth(v, u) = static_cast<float>(kF * kB / z_box);
    }
  }
  const GtScene scene = ExtractGtObstacles(truth, kF, kB, kCx, kCy);
  ASSERT_TRUE(scene.ground.has_value());
  EXPECT_NEAR(scene.ground->height_m, h, 0.02);
  EXPECT_NEAR(scene.ground->pitch_deg, 0.0, 0.2);
  ASSERT_EQ(scene.obstacles.size(), 1u);
  const GtObstacle& o = scene.obstacles[0];
  EXPECT_NEAR(o.median_depth_m, z_box, 0.01);
  // Filled between the scan lines: the box's rows from 0.5 m above the road (min_height_m) up.
  EXPECT_NEAR(o.bbox.width, 1.8 * kF / z_box, 2);
  EXPECT_NEAR(o.bbox.height, 1.0 * kF / z_box, 6);
  EXPECT_GT(o.pixels, 0.8 * o.bbox.area());

  // A box matching it is found at its range; one on the road is a false positive on free truth.
  const DetectionScore s =
      ScoreDetections(scene, kF, kB, {{o.bbox, 10.2}, {cv::Rect(600, 320, 40, 20), 5.0}});
  EXPECT_EQ(s.found, 1);
  EXPECT_NEAR(s.obstacles[0].range_error_pct, 2.0, 1e-6);
  EXPECT_EQ(s.fp, 1);
  EXPECT_EQ(s.fp_free, 1);
}

class RealPairs : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::optional<std::string> data = DataDir();
    if (!data) {
      GTEST_SKIP() << "reference data folder not found: " << DataDirWanted()
                   << " (set STEVI_DATA_DIR)";
    }
    data_ = *data;
  }
  // Loads a pair or records why not (the test then skips).
  std::optional<RealPair> Load(const std::string& name) {
    std::string problem;
    std::optional<RealPair> pair = LoadRealPair(data_, name, problem);
    if (!pair) skip_ = name + ": " + problem;
    return pair;
  }
  std::string data_, skip_;
};

bool Near(double value, double reference, double fraction) {
  return std::abs(value - reference) <= fraction * reference;
}

// The data README describes the two "more" frames independently of this extraction: 000005 "a
// van at about 9 m, another at 17 m, a parked car at 4 m"; 000046 "a car crossing at about 13 m,
// traffic-light and sign poles at about 9 m". Where each is in the picture was checked on the
// overlays (stevi-eval-real --dump): the van at 17 m is in the lane ahead, the one at 9 m on the
// left with its side to the camera, the car at 4 m parked at the right edge; the crossing car is
// ahead, seen from the side. The poles measure 6.8 m (traffic light) and 8.8 m (sign): the sign
// pole is the one near 9 m.
TEST_F(RealPairs, TruthObstaclesMatchTheDataReadme) {
  const std::optional<RealPair> street = Load("kitti-000005_10");
  const std::optional<RealPair> crossing = Load("kitti-000046_10");
  if (!street || !crossing) GTEST_SKIP() << skip_;
  const int centre = street->left.cols / 2;

  const GtScene a = ExtractGtObstacles(street->truth_px, street->f_px, street->baseline_m,
                                       street->cx, street->cy);
  const GtScene b = ExtractGtObstacles(crossing->truth_px, crossing->f_px, crossing->baseline_m,
                                       crossing->cx, crossing->cy);
  // KITTI's cameras sit 1.65 m above the road (the recording platform's description).
  for (const GtScene* s : {&a, &b}) {
    ASSERT_TRUE(s->ground.has_value());
    EXPECT_NEAR(s->ground->height_m, 1.65, 0.1);
  }
  const auto has = [](const GtScene& s, double depth_m, auto where) {
    for (const GtObstacle& o : s.obstacles) {
      if (Near(o.median_depth_m, depth_m, 0.15) && where(o.bbox)) return true;
    }
    return false;
  };
  EXPECT_TRUE(has(a, 4.0, [&](const cv::Rect& r) { return r.x + r.width / 2 > centre; }))
      << "the parked car at 4 m (right half)";
  EXPECT_TRUE(has(a, 9.0, [&](const cv::Rect& r) {
    return r.x + r.width / 2 < centre && r.width > 200;
  })) << "the van at 9 m (left half, its side)";
  EXPECT_TRUE(has(a, 17.0, [&](const cv::Rect& r) { return r.x <= centre && r.br().x > centre; }))
      << "the van at 17 m (ahead)";
  EXPECT_TRUE(has(b, 13.0, [&](const cv::Rect& r) {
    return r.x <= centre + 10 && r.br().x > centre && r.width > 2 * r.height;
  })) << "the car crossing at 13 m (ahead, side on)";
  EXPECT_TRUE(has(b, 9.0, [&](const cv::Rect& r) { return r.height > 2 * r.width; }))
      << "a pole at about 9 m";
}

// The pipeline's own disparity (default configuration, default max_width_px: what the detectors
// see) on one Middlebury and one KITTI pair. Bounds are about 1.5x what was measured (OpenCV 4.6,
// this commit), so a change that makes the matcher clearly worse fails here:
//   cones (450x375, not binned): matched 63.4 %, > 1 px 4.23 % of matched, 39.3 % raw (unmatched
//     count as bad: the texture gate leaves Middlebury's flat areas unmatched), MAE 0.49 px.
//   kitti-000005_10 (binned 2x2 to 621x187): matched 41.4 %, > 3 px 5.39 % of matched, 60.8 % raw
//     (the texture gate drops most of the road), MAE 1.23 px.
TEST_F(RealPairs, PipelineDisparityStaysWithinMeasuredBounds) {
  const std::optional<RealPair> cones = Load("cones");
  const std::optional<RealPair> street = Load("kitti-000005_10");
  if (!cones || !street) GTEST_SKIP() << skip_;
  const int max_width = pipeline::PipelineConfig{}.max_width_px;

  Result<pipeline::FrameResult> c =
      RunPipelineOnPair(*cones, pipeline::Algorithm::kSteViE, max_width);
  ASSERT_TRUE(c.ok()) << c.error().message;
  ASSERT_EQ(c->binning, 1);
  const DisparityScore sc = ScoreDisparity(c->disparity, c->binning, *cones);
  std::printf("cones: matched %.1f %%, >1 px %.2f %% of matched, %.2f %% raw, MAE %.2f px\n",
              sc.MatchedPct(), sc.Bad1MatchedPct(), sc.Bad1RawPct(), sc.MaeMatched());
  EXPECT_GT(sc.evaluated, 100000);
  EXPECT_GE(sc.MatchedPct(), 63.4 / 1.5);
  EXPECT_LE(sc.Bad1MatchedPct(), 4.23 * 1.5);
  EXPECT_LE(sc.Bad1RawPct(), 39.3 * 1.5);
  EXPECT_LE(sc.MaeMatched(), 0.49 * 1.5);

  Result<pipeline::FrameResult> k =
      RunPipelineOnPair(*street, pipeline::Algorithm::kSteViE, max_width);
  ASSERT_TRUE(k.ok()) << k.error().message;
  ASSERT_EQ(k->binning, 2);
  const DisparityScore sk = ScoreDisparity(k->disparity, k->binning, *street);
  std::printf(
      "kitti-000005_10: matched %.1f %%, >3 px %.2f %% of matched, %.2f %% raw, MAE %.2f px\n",
      sk.MatchedPct(), sk.Bad3MatchedPct(), sk.Bad3RawPct(), sk.MaeMatched());
  EXPECT_GT(sk.evaluated, 20000);
  EXPECT_GE(sk.MatchedPct(), 41.4 / 1.5);
  EXPECT_LE(sk.Bad3MatchedPct(), 5.39 * 1.5);
  EXPECT_LE(sk.Bad3RawPct(), 60.8 * 1.5);
  EXPECT_LE(sk.MaeMatched(), 1.23 * 1.5);
}

// SteViE at the default max_width_px on the five KITTI pairs: truth obstacles found (IoU >= 0.3)
// with a range error under 5 %. Measured: 10 of 64 (14 found at any error). The bound leaves a
// margin of 3.
TEST_F(RealPairs, SteViERangesKittiObstacles) {
  int found = 0, within5 = 0, truths = 0;
  for (const std::string& name : KittiPairNames()) {
    const std::optional<RealPair> pair = Load(name);
    if (!pair) GTEST_SKIP() << skip_;
    const GtScene scene =
        ExtractGtObstacles(pair->truth_px, pair->f_px, pair->baseline_m, pair->cx, pair->cy);
    Result<pipeline::FrameResult> r = RunPipelineOnPair(*pair, pipeline::Algorithm::kSteViE,
                                                        pipeline::PipelineConfig{}.max_width_px);
    ASSERT_TRUE(r.ok()) << r.error().message;
    const DetectionScore s = ScoreDetections(scene, pair->f_px, pair->baseline_m, CameraBoxes(*r));
    truths += static_cast<int>(scene.obstacles.size());
    found += s.found;
    for (const ObstacleResult& o : s.obstacles)
      within5 += o.detection >= 0 && std::abs(o.range_error_pct) < 5.0;
  }
  std::printf("SteViE: %d truth obstacles, %d found, %d within 5 %%\n", truths, found, within5);
  EXPECT_GE(within5, 10 - 3);
}

}  // namespace
}  // namespace stevi::testing
