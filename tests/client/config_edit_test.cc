#include "client/lib/config_edit.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "stevi/v1/config.pb.h"

namespace stevi::client {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;

TEST(SetFieldByPath, SetsNestedScalarsAndShortEnumNames) {
  v1::PipelineConfig config;
  EXPECT_EQ(SetFieldByPath(config, "algorithm", "canonical"), "");
  EXPECT_EQ(config.algorithm(), v1::ALGORITHM_CANONICAL);
  EXPECT_EQ(SetFieldByPath(config, "algorithm", "ALGORITHM_STEVIS"), "");
  EXPECT_EQ(config.algorithm(), v1::ALGORITHM_STEVIS);
  EXPECT_EQ(SetFieldByPath(config, "matcher.kind", "semi_global"), "");
  EXPECT_EQ(config.matcher().kind(), v1::MATCHER_KIND_SEMI_GLOBAL);
  EXPECT_EQ(SetFieldByPath(config, "matcher.semi_global.mode", "three_way"), "");
  EXPECT_EQ(config.matcher().semi_global().mode(), v1::SEMI_GLOBAL_MODE_THREE_WAY);
  EXPECT_EQ(SetFieldByPath(config, "canonical.threshold_range_m", "62.5"), "");
  EXPECT_DOUBLE_EQ(config.canonical().threshold_range_m(), 62.5);
  EXPECT_TRUE(config.canonical().has_threshold_range_m());
  EXPECT_FALSE(config.canonical().blobs().has_min_area_px()) << "only what was set is sent";
  EXPECT_EQ(SetFieldByPath(config, "matcher.block_matching.pad_left", "false"), "");
  EXPECT_TRUE(config.matcher().block_matching().has_pad_left());
}

TEST(SetFieldByPath, SetsStevieAndStevisFields) {
  v1::PipelineConfig config;
  EXPECT_EQ(SetFieldByPath(config, "algorithm", "stevie"), "");
  EXPECT_EQ(config.algorithm(), v1::ALGORITHM_STEVIE);
  EXPECT_EQ(SetFieldByPath(config, "stevie.edges.canny_high", "150"), "");
  EXPECT_DOUBLE_EQ(config.stevie().edges().canny_high(), 150);
  EXPECT_TRUE(config.stevie().edges().has_canny_high());
  EXPECT_FALSE(config.stevie().edges().has_canny_low()) << "only what was set is sent";
  EXPECT_EQ(SetFieldByPath(config, "stevie.morphology.shape", "cross"), "");
  EXPECT_EQ(config.stevie().morphology().shape(), v1::STRUCTURING_SHAPE_CROSS);
  EXPECT_EQ(SetFieldByPath(config, "stevie.ground.enabled", "false"), "");
  EXPECT_TRUE(config.stevie().ground().has_enabled());
  EXPECT_EQ(SetFieldByPath(config, "stevis.segmentation", "graph"), "");
  EXPECT_EQ(config.stevis().segmentation(), v1::SEGMENTATION_GRAPH);
  EXPECT_EQ(SetFieldByPath(config, "stevis.saliency_threshold", "0.2"), "");
  EXPECT_DOUBLE_EQ(config.stevis().saliency_threshold(), 0.2);
  EXPECT_EQ(SetFieldByPath(config, "stevis.graph.min_size", "80"), "");
  EXPECT_EQ(config.stevis().graph().min_size(), 80);
  EXPECT_EQ(SetFieldByPath(config, "stevis.blobs.min_area_px", "40"), "");
  EXPECT_EQ(config.stevis().blobs().min_area_px(), 40);
  EXPECT_FALSE(config.stevie().blobs().has_min_area_px());

  EXPECT_THAT(SetFieldByPath(config, "stevis.segmentation", "magic"),
              AllOf(HasSubstr("stevis.segmentation"), HasSubstr("SEGMENTATION_THRESHOLD")));
  EXPECT_THAT(SetFieldByPath(config, "stevis.saliency.scales", "2"), HasSubstr("repeated"));
}

TEST(SetFieldByPath, NamesTheKeyAndWhatIsValid) {
  v1::PipelineConfig config;
  EXPECT_THAT(SetFieldByPath(config, "canonical.nope", "1"),
              AllOf(HasSubstr("canonical.nope"), HasSubstr("threshold_range_m")));
  EXPECT_THAT(SetFieldByPath(config, "algorithm", "magic"),
              AllOf(HasSubstr("algorithm"), HasSubstr("ALGORITHM_CANONICAL")));
  EXPECT_THAT(SetFieldByPath(config, "canonical.blobs.min_area_px", "lots"),
              AllOf(HasSubstr("canonical.blobs.min_area_px"), HasSubstr("lots")));
  EXPECT_THAT(SetFieldByPath(config, "matcher", "1"), HasSubstr("group of settings"));
  EXPECT_THAT(SetFieldByPath(config, "algorithm.x", "1"), HasSubstr("is a value"));
}

}  // namespace
}  // namespace stevi::client
