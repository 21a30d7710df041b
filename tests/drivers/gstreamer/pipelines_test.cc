// The pipeline builders, the quoting of user strings (checked against GStreamer's own parser: a
// hostile path or URL must come back unchanged in its one property, and add no element), the
// layout names and GstOptions::Validate().
#include "drivers/gstreamer/pipelines.h"

#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gst/gst.h>
#include <gtest/gtest.h>

#include "drivers/gstreamer/gst_capture.h"
#include "drivers/gstreamer/gst_errors.h"
#include "drivers/gstreamer/gst_ptr.h"
#include "drivers/gstreamer/gst_source.h"
#include "tests/testing/status_matchers.h"

using stevi::testing::IsError;

namespace stevi::drivers {
namespace {

using ::testing::HasSubstr;

TEST(UvcPipeline, BuildsMjpegCapsAndDecoder) {
  Result<std::string> p = UvcPipeline("/dev/video0", 1280, 480, 30);
  ASSERT_TRUE(p.ok()) << p.error().message;
  EXPECT_EQ(p.value(),
            "v4l2src device=\"/dev/video0\" ! image/jpeg,width=1280,height=480,framerate=30/1 ! "
            "jpegdec");
}

TEST(UvcPipeline, RejectsBadNumbers) {
  Result<std::string> p = UvcPipeline("/dev/video0", 8, 480, 0);
  ASSERT_FALSE(p.ok());
  EXPECT_THAT(p, IsError(ErrorCode::kInvalidArgument,
                         HasSubstr("width: must be in [16, 16384] pixels (got 8)")));
  EXPECT_THAT(p.error().message, HasSubstr("fps: must be in [1, 1000] (got 0)"));
  EXPECT_FALSE(UvcPipeline("", 640, 480, 30).ok());
}

TEST(RtspPipeline, BuildsTcpWithLatencyAndDecodebin) {
  Result<std::string> p = RtspPipeline("rtsp://10.0.0.7:8554/stereo", 50);
  ASSERT_TRUE(p.ok()) << p.error().message;
  EXPECT_EQ(p.value(),
            "rtspsrc location=\"rtsp://10.0.0.7:8554/stereo\" protocols=tcp latency=50 ! "
            "application/x-rtp,media=video ! decodebin");
}

TEST(RtspPipeline, RejectsOtherSchemesAndLatencies) {
  EXPECT_THAT(RtspPipeline("http://cam/x", 0).error().message, HasSubstr("url: must start with"));
  EXPECT_THAT(RtspPipeline("/dev/video0", 0).error().message, HasSubstr("rtsp://"));
  EXPECT_THAT(RtspPipeline("rtsp://cam/x", -1).error().message,
              HasSubstr("latency_ms: must be in [0, 10000] ms (got -1)"));
  EXPECT_TRUE(RtspPipeline("rtsps://cam/x", 0).ok());
}

TEST(VideoFilePipeline, QuotesThePath) {
  Result<std::string> p = VideoFilePipeline("/videos/stereo pair.avi");
  ASSERT_TRUE(p.ok()) << p.error().message;
  EXPECT_EQ(p.value(), "filesrc location=\"/videos/stereo pair.avi\" ! decodebin");
}

TEST(GstSinkTail, LiveDropsFilesWait) {
  EXPECT_THAT(GstSinkTail(true), HasSubstr("appsink name=stevi_sink drop=true max-buffers=2"));
  EXPECT_THAT(GstSinkTail(false), HasSubstr("appsink name=stevi_sink drop=false max-buffers=2"));
  EXPECT_THAT(GstSinkTail(true),
              HasSubstr(" ! videoconvert ! video/x-raw,format={GRAY8,I420,YV12,NV12,NV21,Y42B,Y444,"
                        "YUY2,YVYU,UYVY} ! "));
  EXPECT_TRUE(MentionsGstSinkName("videotestsrc ! appsink name=stevi_sink"));
  EXPECT_FALSE(MentionsGstSinkName("videotestsrc ! appsink name=mine"));
}

TEST(QuoteGstValue, RejectsWhatCannotBeQuoted) {
  const std::vector<std::string> bad = {
      "",     "a\"b", "a\\b",         "trailing\\", "line\nbreak", "tab\there",
      "\x01", "\x7f", "bad\xff utf8", "\xc0\xaf",   "NULL",        "\xed\xa0\x80"};
  for (const std::string& value : bad) {
    Result<std::string> q = QuoteGstValue(value, "path");
    EXPECT_FALSE(q.ok()) << "accepted '" << value << "' as " << q.value();
    if (!q.ok()) {
      EXPECT_THAT(q, IsError(ErrorCode::kInvalidArgument, HasSubstr("path: ")));
    }
  }
  EXPECT_THAT(QuoteGstValue("a\\b", "path").error().message, HasSubstr("backslash"));
  EXPECT_THAT(QuoteGstValue("a\nb", "path").error().message,
              HasSubstr("control character at byte 1 (got 'a\\x0ab')"));
}

// Every hostile string that QuoteGstValue accepts must reach its property unchanged through
// gst_parse_launch, and the description must hold exactly the two elements we wrote.
TEST(QuoteGstValue, SurvivesGStreamersParserUnchanged) {
  InitGStreamer();
  const std::vector<std::string> hostile = {
      "/videos/a b.avi",
      "/tmp/x ! fakesink name=evil",
      "/tmp/x\" ! fakesink name=evil",  // rejected (double quote), listed to prove it
      "/tmp/it's here.avi",
      "'single quoted'",
      "/tmp/semi;colon,comma=eq(paren){brace}.dot:colon",
      "/tmp/caps ! video/x-raw,format=GRAY8 ! fakesink",
      "rtsp://user:p@ss!@host:554/stream?x=1&y=2#frag",
      " leading and trailing spaces ",
      "/tmp/$(rm -rf ~)`id`|&<>*?[]",
      "/tmp/%20percent%",
      "a=b",
      "name=evil",
      "( bin )",
      "/tmp/ünïcödé 日本語 🎥.avi",
      "NULLx",
      "!",
      "\"",
      "''",
  };
  int accepted = 0;
  for (const std::string& value : hostile) {
    Result<std::string> q = QuoteGstValue(value, "path");
    if (!q.ok()) continue;
    ++accepted;
    const std::string description = "filesrc name=probe location=" + q.value() + " ! fakesink";
    GError* raw_error = nullptr;
    gst::ElementPtr pipeline = gst::AdoptFloating(gst_parse_launch_full(
        description.c_str(), nullptr, GST_PARSE_FLAG_FATAL_ERRORS, &raw_error));
    const gst::ErrorPtr error(raw_error);
    ASSERT_FALSE(error) << description << ": " << error->message;
    ASSERT_TRUE(pipeline) << description;
    ASSERT_TRUE(GST_IS_BIN(pipeline.get())) << description;
    EXPECT_EQ(GST_BIN(pipeline.get())->numchildren, 2) << description;
    gst::ElementPtr probe(gst_bin_get_by_name(GST_BIN(pipeline.get()), "probe"));
    ASSERT_TRUE(probe) << description;
    gchar* raw_location = nullptr;
    g_object_get(probe.get(), "location", &raw_location, nullptr);
    const gst::CharPtr location(raw_location);
    ASSERT_TRUE(location) << description;
    EXPECT_EQ(std::string(location.get()), value) << description;
    gst::ElementPtr evil(gst_bin_get_by_name(GST_BIN(pipeline.get()), "evil"));
    EXPECT_FALSE(evil) << description;
  }
  EXPECT_EQ(accepted, static_cast<int>(hostile.size()) - 2);  // all but the two with '"'
}

// The builders' output parses, and the user's string lands in its property unchanged.
TEST(Builders, ParseWithTheirValuesUnchanged) {
  InitGStreamer();
  struct Case {
    Result<std::string> description;
    const char* factory;
    const char* property;
    std::string value;
  };
  const std::string device = "/dev/v4l/by-id/usb-Stereo Cam!1-video-index0";
  const std::string path = "/data/flight 7/left ! right (final).avi";
  const std::string url = "rtsp://admin:pa ss!@192.168.1.10:554/Streaming/Channels/101?a=1";
  Case cases[] = {{UvcPipeline(device, 1280, 480, 30), "v4l2src", "device", device},
                  {VideoFilePipeline(path), "filesrc", "location", path},
                  {RtspPipeline(url, 0), "rtspsrc", "location", url}};
  for (Case& c : cases) {
    ASSERT_TRUE(c.description.ok()) << c.description.error().message;
    const std::string description = c.description.value() + " ! fakesink";
    GError* raw_error = nullptr;
    gst::ElementPtr pipeline = gst::AdoptFloating(gst_parse_launch_full(
        description.c_str(), nullptr, GST_PARSE_FLAG_FATAL_ERRORS, &raw_error));
    const gst::ErrorPtr error(raw_error);
    ASSERT_FALSE(error) << description << ": " << error->message;
    GstIterator* it = gst_bin_iterate_elements(GST_BIN(pipeline.get()));
    GValue item = G_VALUE_INIT;
    std::string found;
    while (gst_iterator_next(it, &item) == GST_ITERATOR_OK) {
      auto* element = GST_ELEMENT(g_value_get_object(&item));
      GstElementFactory* factory = gst_element_get_factory(element);
      if (factory != nullptr && std::string(GST_OBJECT_NAME(factory)) == c.factory) {
        gchar* raw = nullptr;
        g_object_get(element, c.property, &raw, nullptr);
        const gst::CharPtr text(raw);
        found = text ? text.get() : "(null)";
      }
      g_value_reset(&item);
    }
    g_value_unset(&item);
    gst_iterator_free(it);
    EXPECT_EQ(found, c.value) << description;
  }
}

TEST(PackageOfElement, NamesTheUsualPackages) {
  EXPECT_EQ(gst::PackageOfElement("v4l2src"), "gstreamer1.0-plugins-good");
  EXPECT_EQ(gst::PackageOfElement("videoconvert"), "gstreamer1.0-plugins-base");
  EXPECT_EQ(gst::PackageOfElement("h264parse"), "gstreamer1.0-plugins-bad");
  EXPECT_EQ(gst::PackageOfElement("avdec_h264"), "gstreamer1.0-libav");
  EXPECT_THAT(std::string(gst::PackageOfElement("nvarguscamerasrc")), HasSubstr("JetPack"));
  EXPECT_EQ(gst::PackageOfElement("nosuchelement"), "");
}

TEST(GstLayout, ParsesConfigAndFlagSpellings) {
  EXPECT_EQ(ParseGstLayout("side_by_side"), GstLayout::kSideBySide);
  EXPECT_EQ(ParseGstLayout("side-by-side"), GstLayout::kSideBySide);
  EXPECT_EQ(ParseGstLayout("top_bottom"), GstLayout::kTopBottom);
  EXPECT_EQ(ParseGstLayout("top-bottom"), GstLayout::kTopBottom);
  EXPECT_EQ(ParseGstLayout("two"), GstLayout::kTwo);
  EXPECT_EQ(ParseGstLayout("sidebyside"), std::nullopt);
  EXPECT_STREQ(GstLayoutName(GstLayout::kTopBottom), "top-bottom");
}

GstOptions ValidOptions() {
  GstOptions o;
  o.pipeline = "videotestsrc is-live=true";
  return o;
}

TEST(GstOptionsValidate, DefaultsWithAPipelineAreValid) {
  EXPECT_THAT(ValidOptions().Validate(), ::testing::IsEmpty());
  GstOptions two;
  two.layout = GstLayout::kTwo;
  two.left_pipeline = "v4l2src device=/dev/video0";
  two.right_pipeline = "v4l2src device=/dev/video2";
  EXPECT_THAT(two.Validate(), ::testing::IsEmpty());
}

TEST(GstOptionsValidate, ListsEveryProblemByField) {
  GstOptions o;
  o.layout = GstLayout::kSideBySide;
  o.left_pipeline = "videotestsrc";
  o.width = 640;
  o.height = 0;
  o.fps = 0;
  o.pair_tolerance_ms = -1;
  o.loop = true;  // with live
  o.timeout = std::chrono::milliseconds(0);
  const std::vector<std::string> problems = o.Validate();
  const auto has = [&](const std::string& text) { return ::testing::Contains(HasSubstr(text)); };
  EXPECT_THAT(problems, has("pipeline: must be a gst-launch pipeline for layout side-by-side"));
  EXPECT_THAT(problems, has("left_pipeline: unused with layout side-by-side (got 'videotestsrc')"));
  EXPECT_THAT(problems, has("width, height: give both or neither (got 640x0)"));
  EXPECT_THAT(problems, has("fps: must be"));
  EXPECT_THAT(problems, has("(got 0)"));
  EXPECT_THAT(problems, has("pair_tolerance_ms: must be"));
  EXPECT_THAT(problems, has("loop: only for files (live = false)"));
  EXPECT_THAT(problems, has("timeout: must be > 0 ms (got 0)"));
}

TEST(GstOptionsValidate, RejectsTheDriversSinkNameAndWideTolerance) {
  GstOptions o;
  o.layout = GstLayout::kTwo;
  o.left_pipeline = "videotestsrc ! appsink name=stevi_sink";
  o.right_pipeline = "videotestsrc";
  o.fps = 30;
  o.pair_tolerance_ms = 20;  // > 16.7 ms
  const std::vector<std::string> problems = o.Validate();
  EXPECT_THAT(problems,
              ::testing::Contains(HasSubstr("left_pipeline: must not name an element stevi_sink")));
  EXPECT_THAT(problems, ::testing::Contains(
                            HasSubstr("pair_tolerance_ms: must be at most half the frame period "
                                      "(16.7 ms at fps)")));
  GstOptions size = ValidOptions();
  size.width = 8;
  size.height = 8;
  EXPECT_THAT(size.Validate(), ::testing::Contains(HasSubstr("width: must be")));
}

TEST(GstOptions, TimesFollowTheFrameRate) {
  GstOptions o = ValidOptions();
  o.fps = 25;
  EXPECT_EQ(o.FramePeriodNs(), 40'000'000);
  EXPECT_EQ(o.PairToleranceNs(), 20'000'000);
  o.pair_tolerance_ms = 5;
  EXPECT_EQ(o.PairToleranceNs(), 5'000'000);
  o.timeout = std::chrono::milliseconds(100);
  EXPECT_EQ(o.LostAfter(), std::chrono::milliseconds(200));  // 5 periods
  o.timeout = std::chrono::milliseconds(1000);
  EXPECT_EQ(o.LostAfter(), std::chrono::milliseconds(1000));
}

TEST(GstOptions, FieldsAssignByName) {
  GstOptions o = ValidOptions();
  EXPECT_EQ(fields::Assign(o, "layout", "top_bottom"), std::nullopt);
  EXPECT_EQ(o.layout, GstLayout::kTopBottom);
  EXPECT_EQ(fields::Assign(o, "width", "320"), std::nullopt);
  EXPECT_EQ(o.width, 320);
  EXPECT_NE(fields::Assign(o, "width", "8"), std::nullopt);
  EXPECT_EQ(fields::Assign(o, "live", "false"), std::nullopt);
  EXPECT_FALSE(o.live);
}

}  // namespace
}  // namespace stevi::drivers
