// The stixel world through the pipeline, on the synthetic airfield (its truth from the renderer):
// the algorithm's own matcher, one ground plane shared with the range scan, and the tower and
// hangar found at their range.
#include <memory>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "core/pipeline/config.h"
#include "core/pipeline/pipeline.h"
#include "drivers/synthetic/synthetic_source.h"
#include "drivers/truth.h"

namespace stevi::pipeline {
namespace {

double IoU(const cv::Rect& a, const cv::Rect& b) {
  const double inter = (a & b).area();
  const double uni = a.area() + b.area() - inter;
  return uni > 0 ? inter / uni : 0.0;
}

TEST(StixelsPipeline, ConfigForAlgorithmPicksTheDenseMatcher) {
  EXPECT_EQ(ConfigForAlgorithm(Algorithm::kStixels).matcher.kind, stereo::MatcherKind::kDense);
  EXPECT_EQ(ConfigForAlgorithm(Algorithm::kSteViE).matcher.kind,
            stereo::MatcherKind::kBlockMatching);
  EXPECT_EQ(AlgorithmFromName("stixels"), Algorithm::kStixels);
  EXPECT_EQ(AlgorithmName(Algorithm::kStixels), "stixels");
}

TEST(StixelsPipeline, TheAirfieldsLargeObstaclesAtTheirRange) {
  drivers::SyntheticRenderer renderer(drivers::SyntheticOptions{});
  const PipelineConfig config = ConfigForAlgorithm(Algorithm::kStixels);
  ASSERT_TRUE(config.Validate().empty());
  const Snapshot snapshot{std::make_shared<const PipelineConfig>(config),
                          std::make_shared<const geometry::StereoRig>(renderer.Rig())};
  Pipeline pipe;
  drivers::FrameTruth truth;
  Result<FrameResult> result = Internal("not run");
  for (int k = 0; k < 3; ++k) {
    result = pipe.Process(renderer.Render(k, &truth), snapshot);
    ASSERT_TRUE(result.ok()) << result.error().message;
  }
  // The stages: one ground plane for the stixels and the scan.
  std::vector<std::string> stages;
  for (const StageTiming& t : result->timings) stages.push_back(t.stage);
  EXPECT_THAT(stages, ::testing::ElementsAre("rectify", "disparity", "ground", "extract", "scan",
                                             "track", "total"));
  ASSERT_TRUE(result->ground.has_value());
  ASSERT_TRUE(result->stixels.has_value());
  EXPECT_FALSE(result->disparity.confidence.empty());
  ASSERT_FALSE(result->detections.empty());
  for (const detection::Detection& d : result->detections) EXPECT_EQ(d.extractor, "stixels");
  // Every large obstacle standing near the rig (at least 5000 visible pixels) is boxed at IoU >=
  // 0.3 by a detection whose depth is within 5 % of the truth's f B / median disparity.
  const double fb = renderer.Rig().f_px() * renderer.Rig().baseline_m();
  int large = 0, found = 0;
  for (const drivers::ObstacleTruth& o : truth.obstacles) {
    if (o.visible_px < 5000 || o.median_disparity_px < 8) continue;
    ++large;
    const double z = fb / o.median_disparity_px;
    bool hit = false;
    for (const detection::Detection& d : result->detections) {
      if (IoU(d.bbox, o.bbox) >= 0.3 && std::abs(d.depth_m - z) <= 0.05 * z) {
        hit = true;
        break;
      }
    }
    found += hit;
    if (!hit) {
      std::string near;
      for (const detection::Detection& d : result->detections) {
        if (IoU(d.bbox, o.bbox) > 0) {
          near += " [" + std::to_string(d.bbox.x) + "," + std::to_string(d.bbox.y) + " " +
                  std::to_string(d.bbox.width) + "x" + std::to_string(d.bbox.height) + " at " +
                  std::to_string(d.depth_m) + " m]";
        }
      }
      ADD_FAILURE() << o.name << " (" << o.bbox.x << "," << o.bbox.y << " " << o.bbox.width << "x"
                    << o.bbox.height << ", " << z << " m) not boxed; overlapping:" << near;
    }
  }
  EXPECT_GT(large, 0);
  EXPECT_EQ(found, large);
}

}  // namespace
}  // namespace stevi::pipeline
