#include "server/convert.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace stevi::server {
namespace {

using ::testing::HasSubstr;

TEST(MergeFromProto, FullRoundTripKeepsEveryField) {
  pipeline::PipelineConfig original;
  original.matcher.kind = stereo::MatcherKind::kSemiGlobal;
  original.matcher.block_matching.block_size = 21;
  original.matcher.semi_global.p1 = 100;
  original.matcher.semi_global.p2 = 400;
  original.matcher.semi_global.mode = stereo::SemiGlobalOptions::Mode::kHH4;
  original.range.min_disparity_px = 3;
  original.range.max_range_m = 250;
  original.canonical.threshold_range_m = 42;
  original.canonical.open_size_px = 5;

  pipeline::PipelineConfig copy;  // defaults, then everything from the proto
  EXPECT_THAT(MergeFromProto(ToProto(original), copy), ::testing::IsEmpty());
  EXPECT_EQ(ToProto(copy).SerializeAsString(), ToProto(original).SerializeAsString());
  EXPECT_EQ(copy.matcher.kind, stereo::MatcherKind::kSemiGlobal);
  EXPECT_EQ(copy.matcher.semi_global.mode, stereo::SemiGlobalOptions::Mode::kHH4);
  EXPECT_EQ(copy.canonical.threshold_range_m, 42);
}

TEST(MergeFromProto, UnsetFieldsKeepTheirValues) {
  pipeline::PipelineConfig config;
  config.canonical.threshold_range_m = 33;
  config.matcher.block_matching.num_disparities = 96;
  v1::PipelineConfig update;
  update.mutable_canonical()->mutable_blobs()->set_min_area_px(200);
  EXPECT_THAT(MergeFromProto(update, config), ::testing::IsEmpty());
  EXPECT_EQ(config.canonical.blobs.min_area_px, 200);
  EXPECT_EQ(config.canonical.threshold_range_m, 33);
  EXPECT_EQ(config.matcher.block_matching.num_disparities, 96);
  EXPECT_EQ(config.algorithm, pipeline::Algorithm::kCanonical);
}

TEST(MergeFromProto, OutOfRangeEnumsAreNamed) {
  pipeline::PipelineConfig config;
  v1::PipelineConfig update;
  update.set_algorithm(static_cast<v1::Algorithm>(77));
  update.mutable_matcher()->set_kind(static_cast<v1::MatcherKind>(9));
  const std::vector<std::string> problems = MergeFromProto(update, config);
  ASSERT_EQ(problems.size(), 2u);
  EXPECT_THAT(problems[0], HasSubstr("algorithm"));
  EXPECT_THAT(problems[1], HasSubstr("matcher.kind"));
}

TEST(ToTrackFrame, CopiesDetectionsAsPerFrameTracks) {
  pipeline::FrameResult result;
  result.frame_id = 7;
  result.capture_time_ns = 123456789;
  result.source_index = 41;
  result.timings = {{"disparity", 4.5}, {"total", 9.0}};
  detection::Detection d;
  d.bbox = cv::Rect(10, 20, 30, 40);
  d.depth_m = 25;
  d.range_m = 26;
  d.range_sigma_m = 0.4;
  d.position_cam_m = cv::Vec3d(1, -2, 25);
  d.disparity_px = 16.8;
  d.extractor = "canonical";
  result.detections = {d, d};

  const v1::TrackFrame f = ToTrackFrame(result);
  EXPECT_EQ(f.frame_id(), 7u);
  EXPECT_EQ(f.capture_time_ns(), 123456789);
  EXPECT_EQ(f.source_index(), 41);
  EXPECT_EQ(f.algorithm(), v1::ALGORITHM_CANONICAL);
  ASSERT_EQ(f.tracks_size(), 2);
  EXPECT_EQ(f.tracks(0).track_id(), 1u);
  EXPECT_EQ(f.tracks(1).track_id(), 2u);
  EXPECT_EQ(f.tracks(0).bbox().width(), 30);
  EXPECT_DOUBLE_EQ(f.tracks(0).depth_m(), 25);
  EXPECT_DOUBLE_EQ(f.tracks(0).position_cam().y_m(), -2);
  ASSERT_EQ(f.timings_size(), 2);
  EXPECT_EQ(f.timings(1).stage(), "total");
}

TEST(ToJsonLine, UsesProtoFieldNamesOnOneLine) {
  v1::TrackFrame f;
  f.set_frame_id(3);
  f.add_tracks()->set_range_sigma_m(0.5);
  const std::string json = ToJsonLine(f);
  EXPECT_THAT(json, HasSubstr("\"frame_id\""));
  EXPECT_THAT(json, HasSubstr("\"range_sigma_m\""));
  EXPECT_EQ(json.find('\n'), std::string::npos);
}

}  // namespace
}  // namespace stevi::server
