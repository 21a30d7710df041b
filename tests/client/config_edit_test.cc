#include "client/config_edit.h"

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
