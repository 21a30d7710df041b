// SteViE and SteViS on the synthetic evaluation scenarios, against the truth.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <map>

#include "core/pipeline/pipeline.h"
#include "drivers/synthetic/synthetic_source.h"
#include "tests/testing/truth_match.h"

namespace stevi::detection {
namespace {

using ::testing::HasSubstr;

struct Score {
  int expected = 0, matched = 0, detections = 0, depth_within_2pct = 0;
  double recall() const { return expected ? static_cast<double>(matched) / expected : 1; }
  double precision() const { return detections ? static_cast<double>(matched) / detections : 1; }
};

// Every 2nd frame of a scenario through the pipeline with `algorithm`; the matching rule of
// stevi-eval (IoU >= 0.3, one-to-one; expected: >= 100 visible px and >= 8 px of disparity).
Score Evaluate(const drivers::Scenario& scenario, pipeline::Algorithm algorithm) {
  drivers::SyntheticRenderer renderer(scenario.options);
  pipeline::PipelineConfig config;
  config.algorithm = algorithm;
  const pipeline::Snapshot snapshot{std::make_shared<const pipeline::PipelineConfig>(config),
                                    std::make_shared<const geometry::StereoRig>(renderer.Rig())};
  const double fB = scenario.options.f_px * scenario.options.baseline_m;
  pipeline::Pipeline pipe;
  Score score;
  for (int k = 0; k < scenario.frames; k += 2) {
    drivers::FrameTruth truth;
    const StereoFrame frame = renderer.Render(k, &truth);
    Result<pipeline::FrameResult> result = pipe.Process(frame, snapshot);
    EXPECT_TRUE(result.ok());
    if (!result.ok()) return score;
    std::vector<cv::Rect> boxes, truth_boxes;
    std::vector<double> depths;
    for (const Detection& d : result->detections) boxes.push_back(d.bbox);
    for (const drivers::ObstacleTruth& o : truth.obstacles) {
      if (o.visible_px < 100 || fB / o.depth_m < 8) continue;
      truth_boxes.push_back(o.bbox);
      // The obstacle's depth: of the median of its visible pixels' disparities (a box seen from
      // below shows its underside too, beyond its front face).
      depths.push_back(o.median_disparity_px > 0 ? fB / o.median_disparity_px : o.depth_m);
    }
    score.expected += static_cast<int>(truth_boxes.size());
    score.detections += static_cast<int>(boxes.size());
    for (const auto& [d, t] : testing::MatchByIoU(boxes, truth_boxes, 0.3)) {
      ++score.matched;
      if (std::abs(result->detections[d].depth_m - depths[t]) <= 0.02 * depths[t]) {
        ++score.depth_within_2pct;
      }
    }
  }
  return score;
}

class DetectorsOnScenarios : public ::testing::TestWithParam<pipeline::Algorithm> {
 protected:
  static const std::vector<drivers::Scenario>& Scenarios() {
    static const std::vector<drivers::Scenario> scenarios = drivers::EvaluationScenarios();
    return scenarios;
  }
};

TEST_P(DetectorsOnScenarios, ReachRecallAndPrecisionWithAccurateDepth) {
  const pipeline::Algorithm algorithm = GetParam();
  for (const drivers::Scenario& scenario : Scenarios()) {
    const Score s = Evaluate(scenario, algorithm);
    std::printf("%-7s %-16s recall %5.1f %%  precision %5.1f %%  depth within 2 %%: %d/%d\n",
                std::string(pipeline::AlgorithmName(algorithm)).c_str(), scenario.name.c_str(),
                100 * s.recall(), 100 * s.precision(), s.depth_within_2pct, s.matched);
    EXPECT_GE(s.recall(), 0.9) << scenario.name;
    EXPECT_GE(s.precision(), 0.8) << scenario.name;
    EXPECT_GE(s.depth_within_2pct, 0.97 * s.matched) << scenario.name;
  }
}

INSTANTIATE_TEST_SUITE_P(SteViEAndSteViS, DetectorsOnScenarios,
                         ::testing::Values(pipeline::Algorithm::kSteViE,
                                           pipeline::Algorithm::kSteViS),
                         [](const auto& param_info) {
                           return std::string(pipeline::AlgorithmName(param_info.param));
                         });

TEST(SteViE, TwoObstaclesCloseTogetherAtDifferentDepthsAreTwoDetections) {
  for (const drivers::Scenario& scenario : drivers::EvaluationScenarios()) {
    if (scenario.name != "close_pair") continue;
    drivers::SyntheticRenderer renderer(scenario.options);
    pipeline::PipelineConfig config;
    config.algorithm = pipeline::Algorithm::kSteViE;
    const pipeline::Snapshot snapshot{std::make_shared<const pipeline::PipelineConfig>(config),
                                      std::make_shared<const geometry::StereoRig>(renderer.Rig())};
    pipeline::Pipeline pipe;
    int frames_with_both = 0, frames = 0;
    for (int k = 0; k < scenario.frames; k += 3, ++frames) {
      drivers::FrameTruth truth;
      Result<pipeline::FrameResult> result = pipe.Process(renderer.Render(k, &truth), snapshot);
      ASSERT_TRUE(result.ok());
      std::vector<cv::Rect> boxes, truth_boxes;
      for (const Detection& d : result->detections) boxes.push_back(d.bbox);
      for (const drivers::ObstacleTruth& o : truth.obstacles) truth_boxes.push_back(o.bbox);
      if (testing::MatchByIoU(boxes, truth_boxes, 0.3).size() == 2) ++frames_with_both;
    }
    EXPECT_GE(frames_with_both, frames - 1) << frames_with_both << " of " << frames;
  }
}

TEST(SteViEOptions, ValidateNamesEveryProblemWithItsStage) {
  SteViEOptions o;
  o.edges.canny_low = -1;
  o.morphology.close_size = 4;
  o.ground.margin_fraction = 3;
  o.blobs.min_area_px = 0;
  const std::string all = ::testing::PrintToString(o.Validate());
  EXPECT_THAT(all, HasSubstr("edges.canny_low"));
  EXPECT_THAT(all, HasSubstr("morphology.close_size"));
  EXPECT_THAT(all, HasSubstr("ground.margin_fraction"));
  EXPECT_THAT(all, HasSubstr("blobs.min_area_px"));
}

TEST(SteViSOptions, ValidateNamesEveryProblemWithItsStage) {
  SteViSOptions o;
  o.saliency_threshold = 0;
  o.saliency.scales.clear();
  o.graph_level = 9;
  const std::string all = ::testing::PrintToString(o.Validate());
  EXPECT_THAT(all, HasSubstr("saliency_threshold"));
  EXPECT_THAT(all, HasSubstr("saliency.scales"));
  EXPECT_THAT(all, HasSubstr("graph_level"));
}

TEST(SteViSOptions, ValidatesTheGraphOptionsInGraphModeOnly) {
  SteViSOptions o;
  o.graph.k = 0;
  EXPECT_THAT(o.Validate(), ::testing::IsEmpty());
  o.segmentation = SteViSOptions::Segmentation::kGraph;
  EXPECT_THAT(o.Validate(), ::testing::ElementsAre("graph.k: must be > 0 grey levels (got 0)"));
}

}  // namespace
}  // namespace stevi::detection
