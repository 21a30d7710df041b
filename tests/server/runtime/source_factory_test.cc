// The source factory (server/runtime/source_factory.h): its table of kinds, each kind's checks
// naming the configuration's fields, and real sources opened from a spec.
#include "server/runtime/source_factory.h"

#include <set>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "drivers/synthetic/scenarios.h"
#include "tests/testing/status_matchers.h"

using stevi::testing::IsError;

namespace stevi::server {
namespace {

using ::testing::AllOf;
using ::testing::Contains;
using ::testing::ElementsAre;
using ::testing::HasSubstr;
using ::testing::IsEmpty;

TEST(SourceKinds, NamesAreUniqueAndTheDefaultIsSynthetic) {
  std::set<std::string_view> names;
  for (const SourceKind& kind : SourceKinds()) {
    EXPECT_TRUE(names.insert(kind.name).second) << kind.name;
    EXPECT_FALSE(kind.description.empty()) << kind.name;
    EXPECT_EQ(FindSourceKind(kind.name), &kind);
  }
  EXPECT_EQ(SourceKinds().front().name, "synthetic");
  EXPECT_EQ(SourceKindNames(), "synthetic, images, aravis, replay, gst, uvc, rtsp, video");
  EXPECT_EQ(FindSourceKind("camera"), nullptr);
}

TEST(CheckSource, NamesWhatEachKindNeeds) {
  SourceSpec spec;
  EXPECT_THAT(CheckSource(spec), IsEmpty());  // the default synthetic rig

  spec.kind = "webcam";
  EXPECT_THAT(CheckSource(spec),
              ElementsAre(AllOf(HasSubstr("source.kind: unknown kind 'webcam'"),
                                HasSubstr("synthetic, images, aravis, replay"))));

  spec.kind = "images";
  EXPECT_THAT(CheckSource(spec), ElementsAre(HasSubstr("source.left"), HasSubstr("source.right"),
                                             HasSubstr("source.calibration")));

  spec.kind = "aravis";
  spec.left = spec.right = "GV01";
  spec.aravis.buffers = 1;
  spec.aravis.trigger.mode = drivers::TriggerMode::kHardware;
  const std::vector<std::string> aravis = CheckSource(spec);
  EXPECT_THAT(aravis, Contains(HasSubstr("source.right: must be another camera")));
  EXPECT_THAT(aravis, Contains("source.aravis.buffers: must be in [2, 64] (got 1)"));
  EXPECT_THAT(aravis,
              Contains(HasSubstr(
                  "source.aravis.trigger_line: a hardware trigger needs the camera's line")));

  // The GStreamer kinds: each names what it needs, and its pipelines are built safely.
  spec = SourceSpec{};
  spec.kind = "video";
  EXPECT_THAT(CheckSource(spec), Contains(HasSubstr("source.gst.file: required")));
  spec.gst_inputs.file = "flight.avi";
  EXPECT_THAT(CheckSource(spec), IsEmpty());
  spec.left = "a.avi";
  EXPECT_THAT(CheckSource(spec),
              Contains(HasSubstr("only with the layout two (one file per view)")));
  spec.gst.layout = drivers::GstLayout::kTwo;
  EXPECT_THAT(CheckSource(spec), Contains(HasSubstr("source.right: required (the file)")));
  spec = SourceSpec{};
  spec.kind = "uvc";
  EXPECT_THAT(CheckSource(spec), Contains(HasSubstr("source.gst.width, height: required for uvc")));
  spec.gst.width = 640;
  spec.gst.height = 480;
  EXPECT_THAT(CheckSource(spec), IsEmpty());
  spec = SourceSpec{};
  spec.kind = "rtsp";
  spec.gst_inputs.url = "rtsp://camera/stream\" quoted";
  EXPECT_THAT(CheckSource(spec), Contains(HasSubstr("source.gst.url")));
  spec.gst_inputs.url = "rtsp://camera/stream";
  spec.gst_inputs.latency_ms = 9000;
  EXPECT_THAT(CheckSource(spec),
              Contains(HasSubstr("source.gst.latency_ms: must be in [0, 5000] ms (got 9000)")));
  spec = SourceSpec{};
  spec.kind = "gst";
  EXPECT_THAT(CheckSource(spec), Contains(HasSubstr("source.gst.pipeline")));
  spec.gst.pipeline = "videotestsrc ! appsink name=stevi_sink";
  EXPECT_THAT(CheckSource(spec), Contains(HasSubstr("stevi_sink")));

  spec = SourceSpec{};
  spec.kind = "replay";
  spec.replay.rate = -1;
  EXPECT_THAT(CheckSource(spec),
              ElementsAre(HasSubstr("source.replay.dir: required"),
                          "source.replay.rate: must be 0 (max) or in (0, 1000] (got -1)"));

  spec = SourceSpec{};
  spec.scene = "airfeld";
  spec.left = "l.png";
  EXPECT_THAT(CheckSource(spec),
              ElementsAre(HasSubstr("are for the images source"),
                          AllOf(HasSubstr("unknown scene 'airfeld'"), HasSubstr("chessboard"))));
}

TEST(OpenSource, OpensTheSyntheticSceneAndTheBoard) {
  SourceSpec spec;
  spec.synthetic.width = 320;
  spec.synthetic.height = 240;
  Result<std::unique_ptr<drivers::StereoSource>> source = OpenSource(spec);
  ASSERT_TRUE(source.ok()) << source.error().message;
  Result<StereoFrame> frame = (*source)->Next();
  ASSERT_TRUE(frame.ok());
  EXPECT_EQ(frame->left.size(), cv::Size(320, 240));

  spec.scene = drivers::kChessboardScene;
  source = OpenSource(spec);
  ASSERT_TRUE(source.ok()) << source.error().message;
  EXPECT_THAT((*source)->Describe(), HasSubstr("chessboard"));
}

TEST(OpenSource, RefusesABadSpecBeforeOpeningAndPrefixesTheDriversErrors) {
  SourceSpec spec;
  spec.kind = "images";
  Result<std::unique_ptr<drivers::StereoSource>> source = OpenSource(spec);
  ASSERT_FALSE(source.ok());
  EXPECT_THAT(source, IsError(ErrorCode::kInvalidArgument, HasSubstr("source.left: required")));

  spec = SourceSpec{};
  spec.synthetic.width = 8;  // the driver's own check, under the config's name
  source = OpenSource(spec);
  ASSERT_FALSE(source.ok());
  EXPECT_THAT(source.error().message, HasSubstr("source.synthetic: width: must be in [16, 8192]"));

  spec = SourceSpec{};
  spec.kind = "replay";
  spec.replay_dir = "/nonexistent/recording";
  source = OpenSource(spec);
  ASSERT_FALSE(source.ok());
  EXPECT_THAT(source.error().message, HasSubstr("source.replay: "));
}

}  // namespace
}  // namespace stevi::server
