#include "core/detection/regions.h"

#include <cmath>
#include <cstdio>
#include <optional>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "core/geometry/range.h"
#include "core/geometry/stereo_rig.h"
#include "core/stereo/disparity.h"
#include "core/stereo/matcher.h"
#include "drivers/synthetic/synthetic_source.h"
#include "tests/core/detection/disparity_fixtures.h"

namespace stevi::detection {
namespace {

using geometry::RangeOptions;
using geometry::StereoRig;
using stereo::DisparityMap;

using namespace fixtures;  // kF, kB, TestRig, EmptyMap, Paint

// Hypotheses of an appearance mask over a map, without a ground model.
std::vector<Detection> Hypotheses(const cv::Mat1b& appearance, const DisparityMap& map,
                                  const StereoBlobOptions& options = {}) {
  const StereoRig rig = TestRig();
  const RangeOptions range;
  const cv::Mat1b classes = ClassifyPixels(map, rig, range, std::nullopt, GroundOptions{});
  return RangeRegions(appearance, classes, map, rig, range, options, "test", std::nullopt, nullptr);
}

TEST(RangeRegions, SparseDisparitiesRangeTheWholeAppearanceRegion) {
  // A low-contrast object: its region is whole, but only 5 % of its pixels (its outline, some
  // texture) have a disparity. It is one hypothesis at that disparity, and says how much of its
  // box was matched.
  DisparityMap map = EmptyMap(cv::Size(640, 480));
  const cv::Rect object(200, 150, 120, 40);
  cv::Mat1b appearance(map.fixed.size(), uchar{0});
  appearance(object).setTo(255);
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> x(object.x, object.br().x - 1), y(object.y, object.br().y - 1);
  std::normal_distribution<double> noise(0.0, 0.2);
  const int matched = object.area() / 20;
  for (int i = 0; i < matched; ++i) {
    map.fixed(y(rng), x(rng)) =
        static_cast<int16_t>(std::lround((12.0 + noise(rng)) * DisparityMap::kScale));
  }
  const std::vector<Detection> detections = Hypotheses(appearance, map);
  ASSERT_EQ(detections.size(), 1u);
  EXPECT_NEAR(detections[0].disparity_px, 12.0, 0.1);
  EXPECT_NEAR(detections[0].valid_fraction, 0.05, 0.01);
  // The box is that of the matched pixels, which spread over the whole object.
  EXPECT_GE((detections[0].bbox & object).area(), 0.9 * object.area());
}

TEST(RangeRegions, PiecesAtOneRangeJoinAcrossGapsThatScaleWithTheirSize) {
  DisparityMap map = EmptyMap(cv::Size(640, 480));
  cv::Mat1b appearance(map.fixed.size(), uchar{0});
  // Two halves of one object, 100 px wide each, 20 px apart (0.2 of their size), at 10 px.
  for (const cv::Rect& r : {cv::Rect(100, 100, 100, 30), cv::Rect(220, 100, 100, 30)}) {
    Paint(map, r, 10.0);
    appearance(r).setTo(255);
  }
  // Two small objects at one range, 40 px apart: more than their own size.
  for (const cv::Rect& r : {cv::Rect(100, 300, 20, 20), cv::Rect(160, 300, 20, 20)}) {
    Paint(map, r, 20.0);
    appearance(r).setTo(255);
  }
  const std::vector<Detection> detections = Hypotheses(appearance, map);
  ASSERT_EQ(detections.size(), 3u);
  int joined = 0;
  for (const Detection& d : detections) joined += d.bbox == cv::Rect(100, 100, 220, 30);
  EXPECT_EQ(joined, 1);

  StereoBlobOptions never;
  never.join_gap_fraction = 0;
  EXPECT_EQ(Hypotheses(appearance, map, never).size(), 4u);
}

TEST(RangeRegions, PiecesInOneAppearanceRegionJoinAcrossItsGaps) {
  DisparityMap map = EmptyMap(cv::Size(640, 480));
  cv::Mat1b appearance(map.fixed.size(), uchar{0});
  // A uniform fuselage, 300 x 30 px, matched only at its nose and tail (30 x 30 each, 240 px
  // apart: eight times their size), at 10 px. The appearance region covers it whole.
  const cv::Rect fuselage(100, 100, 300, 30), nose(100, 100, 30, 30), tail(370, 100, 30, 30);
  appearance(fuselage).setTo(255);
  Paint(map, nose, 10.0);
  Paint(map, tail, 10.0);
  // In a second region, a large piece and a small one at one range, 100 px apart.
  const cv::Rect hangar(100, 300, 200, 60), drone(400, 300, 20, 10), strip(100, 300, 320, 60);
  appearance(strip).setTo(255);
  Paint(map, hangar, 8.0);
  Paint(map, drone, 8.0);
  // In a third, two pieces at different ranges (12 and 6 px), 100 px apart.
  const cv::Rect near(100, 400, 30, 30), far(230, 400, 30, 30), band(100, 400, 160, 30);
  appearance(band).setTo(255);
  Paint(map, near, 12.0);
  Paint(map, far, 6.0);
  const auto count_box = [](const std::vector<Detection>& detections, const cv::Rect& box) {
    int n = 0;
    for (const Detection& d : detections) n += d.bbox == box;
    return n;
  };

  // The gap rule alone keeps every piece apart: six hypotheses.
  const std::vector<Detection> apart = Hypotheses(appearance, map);
  EXPECT_EQ(apart.size(), 6u);

  // SteViE's rule (any gap within a region): the fuselage is one object, and so are the hangar
  // and the drone; pieces at different ranges stay apart.
  const std::vector<Detection> any_gap =
      Hypotheses(appearance, map, StereoBlobOptions::JoiningWithinRegions(0.0));
  EXPECT_EQ(any_gap.size(), 4u);
  EXPECT_EQ(count_box(any_gap, fuselage), 1);
  EXPECT_EQ(count_box(any_gap, strip), 1);
  EXPECT_EQ(count_box(any_gap, near), 1);
  EXPECT_EQ(count_box(any_gap, far), 1);

  // SteViS's rule (twice the smaller piece): the drone is 100 px from the hangar, five times its
  // own size, and stays apart; so do the nose and the tail (eight times theirs).
  const std::vector<Detection> scaled =
      Hypotheses(appearance, map, StereoBlobOptions::JoiningWithinRegions(2.0));
  EXPECT_EQ(scaled.size(), 6u);
  EXPECT_EQ(count_box(scaled, drone), 1);
  // ... and with ten times, both join.
  const std::vector<Detection> wide =
      Hypotheses(appearance, map, StereoBlobOptions::JoiningWithinRegions(10.0));
  EXPECT_EQ(count_box(wide, fuselage), 1);
  EXPECT_EQ(count_box(wide, strip), 1);
}

// An aircraft seen from the front: a closed outline 400 px wide (wings) whose stereo matched only
// the fuselage (horizontal wing edges give block matching nothing to match). SteViE's outline is
// one object, so the hypothesis takes the outline's extent; not when the outline also holds
// disparities at another range (then it is not one object as far as the stereo can tell), and
// not with SteViS's rule (a salient blob may hold neighbours).
TEST(RangeRegions, AHypothesisAloneInAClosedOutlineTakesTheOutlinesExtent) {
  DisparityMap map = EmptyMap(cv::Size(640, 480));
  cv::Mat1b appearance(map.fixed.size(), uchar{0});
  const cv::Rect wings(100, 100, 400, 20), fuselage(270, 90, 60, 40);
  appearance(wings).setTo(255);
  appearance(fuselage).setTo(255);
  Paint(map, fuselage, 10.0);

  const std::vector<Detection> outline =
      Hypotheses(appearance, map, StereoBlobOptions::JoiningWithinRegions(0.0));
  ASSERT_EQ(outline.size(), 1u);
  EXPECT_EQ(outline[0].bbox, wings | fuselage);
  EXPECT_NEAR(outline[0].disparity_px, 10.0, 0.2);
  // The box's share of disparities is the new box's.
  EXPECT_NEAR(outline[0].valid_fraction,
              static_cast<double>(outline[0].valid_disparities) / (wings | fuselage).area(), 1e-9);

  const std::vector<Detection> salient =
      Hypotheses(appearance, map, StereoBlobOptions::JoiningWithinRegions(2.0));
  ASSERT_EQ(salient.size(), 1u);
  EXPECT_TRUE((fuselage & salient[0].bbox) == salient[0].bbox) << salient[0].bbox;

  // A wingtip matched at another range (a tower behind it, 6 px): the outline holds two ranges.
  Paint(map, cv::Rect(460, 100, 40, 20), 6.0);
  const std::vector<Detection> two_ranges =
      Hypotheses(appearance, map, StereoBlobOptions::JoiningWithinRegions(0.0));
  ASSERT_FALSE(two_ranges.empty());
  int fuselages = 0;
  for (const Detection& d : two_ranges) {
    EXPECT_NE(d.bbox, wings | fuselage);
    fuselages += d.bbox == fuselage && std::abs(d.disparity_px - 10.0) < 0.2;
  }
  EXPECT_EQ(fuselages, 1);  // the fuselage keeps its own box
}

TEST(StereoBlobOptions, ABadRegionGapFractionIsNamed) {
  for (double bad : {-0.5, 101.0, std::nan("")}) {
    StereoBlobOptions options = StereoBlobOptions::JoiningWithinRegions(bad);
    const std::vector<std::string> problems = options.Validate();
    ASSERT_EQ(problems.size(), 1u) << bad;
    EXPECT_NE(problems[0].find("region_gap_fraction: must be in [0, 100]"), std::string::npos)
        << problems[0];
  }
  EXPECT_TRUE(StereoBlobOptions::JoiningWithinRegions(2.0).Validate().empty());
}

TEST(RangeRegions, PiecesAtDifferentRangesStayApartAndARegionSplitsAtItsDepthModes) {
  DisparityMap map = EmptyMap(cv::Size(640, 480));
  cv::Mat1b appearance(map.fixed.size(), uchar{0});
  // One appearance region over two surfaces that touch: 12 px and 9 px (35 and 47 m).
  const cv::Rect near(100, 100, 60, 40), far(160, 100, 60, 40);
  Paint(map, near, 12.0);
  Paint(map, far, 9.0);
  appearance(near | far).setTo(255);
  std::vector<Detection> detections = Hypotheses(appearance, map);
  ASSERT_EQ(detections.size(), 2u);
  for (const Detection& d : detections) {
    EXPECT_TRUE(d.bbox == near || d.bbox == far) << d.bbox;
    EXPECT_NEAR(d.disparity_px, d.bbox == near ? 12.0 : 9.0, 1e-9);
  }
  // A bridge of a few pixels at intermediate disparities does not join them: the histogram's
  // sparse bins are no mode.
  for (int k = 0; k < 4; ++k) Paint(map, cv::Rect(158 + k, 118, 1, 2), 11.5 - 0.75 * k);
  detections = Hypotheses(appearance, map);
  EXPECT_EQ(detections.size(), 2u);
}

TEST(RangeRegions, LevelGroundAndTerrainLeaningBackAreNotObstacles) {
  // Flat ground seen from 40 m: d(v) = (B / h) (v - 240) below the horizon; a patch of it cut
  // out by an appearance region is dropped, while a vertical face at the same range is kept.
  DisparityMap map = EmptyMap(cv::Size(640, 480));
  cv::Mat1b appearance(map.fixed.size(), uchar{0});
  const cv::Rect patch(100, 360, 120, 60);
  for (int v = patch.y; v < patch.br().y; ++v) {
    Paint(map, cv::Rect(patch.x, v, patch.width, 1), kB / 4.0 * (v - 240));
  }
  appearance(patch).setTo(255);
  const cv::Rect face(400, 360, 60, 60);
  Paint(map, face, kB / 4.0 * 150);
  appearance(face).setTo(255);
  const std::vector<Detection> detections = Hypotheses(appearance, map);
  ASSERT_EQ(detections.size(), 1u);
  EXPECT_EQ(detections[0].bbox, face);
}

TEST(RefineDisparity, MeasuresTheSyntheticDisparityWithAnHonestSigma) {
  // A textured box at known depths, rendered; the fit starts 0.4 px off and must land within its
  // own uncertainty (error / sigma rms about 1) and far better than a block matcher's 0.25 px.
  drivers::SyntheticOptions options;
  options.scene = drivers::Scene{};
  options.scene.camera_height_m = 100.0;
  options.noise_sigma = 2.0;
  double sum_ratio2 = 0, worst = 0;
  int n = 0;
  for (double depth : {15.0, 22.0, 31.0, 47.0, 63.0, 88.0, 120.0}) {
    drivers::Obstacle box;
    box.id = 1;
    box.name = "box";
    box.size_m = cv::Vec3d(0.06 * depth, 0.025 * depth, 0.5);
    box.path.start = cv::Vec3d(0.01 * depth, -0.02 * depth, depth + 0.25);
    options.scene.obstacles = {box};
    const drivers::SyntheticRenderer renderer(options);
    drivers::FrameTruth truth;
    const StereoFrame frame = renderer.Render(0, &truth);
    const drivers::ObstacleTruth& o = truth.obstacles.at(0);
    ASSERT_GT(o.visible_px, 200);
    const cv::Mat1b mask = truth.disparity_px(o.bbox) > 0;
    const double expected = kF * kB / depth;
    const std::optional<RefinedDisparity> refined =
        RefineDisparity(frame.left, frame.right, mask, o.bbox, expected + 0.4);
    ASSERT_TRUE(refined.has_value()) << depth;
    const double error = refined->disparity_px - expected;
    std::printf("depth %6.1f m: d %.3f px, error %+.4f px, sigma %.4f px, %d patches\n", depth,
                expected, error, refined->sigma_px, refined->pixels);
    EXPECT_LT(std::abs(error), 0.08) << depth;
    EXPECT_GT(refined->sigma_px, 0.0);
    sum_ratio2 += (error / refined->sigma_px) * (error / refined->sigma_px);
    worst = std::max(worst, std::abs(error));
    ++n;
  }
  const double ratio_rms = std::sqrt(sum_ratio2 / n);
  std::printf("error / sigma rms %.2f, worst error %.4f px\n", ratio_rms, worst);
  EXPECT_GT(ratio_rms, 0.5);
  EXPECT_LT(ratio_rms, 1.5);
}

TEST(EstimateNoiseSigma, MeasuresGaussianNoiseOnFlatAndTexturedImages) {
  std::mt19937 rng(3);
  for (double sigma : {1.0, 2.0, 4.0, 6.0}) {
    cv::Mat1f flat(480, 640, 120.0f), textured(480, 640);
    for (int y = 0; y < 480; ++y) {
      for (int x = 0; x < 640; ++x) {
        // A smooth gradient and slow waves: texture that a local plane does not explain away.
        textured(y, x) = static_cast<float>(60 + 0.15 * x + 0.1 * y +
                                            20 * std::sin(x / 9.0) * std::cos(y / 13.0));
      }
    }
    std::normal_distribution<float> noise(0.0f, static_cast<float>(sigma));
    cv::Mat1b a, b;
    cv::Mat1f na = flat.clone(), nb = textured.clone();
    for (float& v : na) v += noise(rng);
    for (float& v : nb) v += noise(rng);
    na.convertTo(a, CV_8U);
    nb.convertTo(b, CV_8U);
    EXPECT_NEAR(stereo::EstimateNoiseSigma(a), sigma, 0.1 * sigma + 0.1) << "flat " << sigma;
    EXPECT_NEAR(stereo::EstimateNoiseSigma(b), sigma, 0.15 * sigma + 0.15) << "textured " << sigma;
  }
}

TEST(ScaledKernel, ScalesOddSizesWithTheImageWidth) {
  EXPECT_EQ(ScaledKernel(7, 640), 7);
  EXPECT_EQ(ScaledKernel(7, 1280), 15);
  EXPECT_EQ(ScaledKernel(7, 320), 5);
  EXPECT_EQ(ScaledKernel(3, 320), 3);
  EXPECT_EQ(ScaledKernel(1, 1920), 1);
}

}  // namespace
}  // namespace stevi::detection
