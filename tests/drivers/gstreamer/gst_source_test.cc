// GstStereoSource on videotestsrc pipelines: the errors at the start (each clear, none hanging),
// a live pipeline's times, a lost live pipeline rebuilt, two pipelines paired by capture time
// (within and outside the tolerance, files and live), and Interrupt().
#include "drivers/gstreamer/gst_source.h"

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <future>
#include <string>
#include <thread>

#include <gmock/gmock.h>
#include <gst/gst.h>
#include <gtest/gtest.h>

#include "core/common/format.h"
#include "drivers/gstreamer/gst_capture.h"
#include "tests/testing/status_matchers.h"

using stevi::testing::IsError;

namespace stevi::drivers {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;
using Clock = std::chrono::steady_clock;

GstOptions LiveOptions(const std::string& pipeline) {
  GstOptions options;
  options.pipeline = pipeline;
  options.fps = 30;
  options.timeout = std::chrono::milliseconds(2000);
  options.start_timeout = std::chrono::milliseconds(10000);
  return options;
}

Error OpenError(const GstOptions& options,
                std::shared_ptr<const geometry::StereoRig> rig = nullptr) {
  const auto start = Clock::now();
  Result<std::unique_ptr<GstStereoSource>> source = GstStereoSource::Open(options, rig);
  const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
  EXPECT_FALSE(source.ok());
  if (source.ok()) return Internal("opened");
  std::printf("%.2f s: [%s] %s\n", seconds, std::string(ErrorCodeName(source.error().code)).c_str(),
              source.error().message.c_str());
  return source.error();
}

TEST(GstStartErrors, UnknownElementIsNamed) {
  const Error e = OpenError(LiveOptions("videotestsrc is-live=true ! nosuchelement"));
  EXPECT_EQ(e.code, ErrorCode::kInvalidArgument);
  EXPECT_THAT(e.message, HasSubstr("no GStreamer element 'nosuchelement'"));
  EXPECT_THAT(e.message, HasSubstr("videotest: "));
}

TEST(GstStartErrors, MissingPluginNamesTheDebianPackage) {
  GstElementFactory* factory = (InitGStreamer(), gst_element_factory_find("avdec_h264"));
  if (factory != nullptr) {
    gst_object_unref(factory);
    GTEST_SKIP() << "gstreamer1.0-libav is installed here: avdec_h264 is not missing";
  }
  const Error e = OpenError(LiveOptions("videotestsrc ! avdec_h264"));
  EXPECT_EQ(e.code, ErrorCode::kInvalidArgument);
  EXPECT_THAT(e.message,
              HasSubstr("no GStreamer element 'avdec_h264' (install gstreamer1.0-libav)"));
}

TEST(GstStartErrors, SyntaxErrorIsABadPipeline) {
  const Error e = OpenError(LiveOptions("videotestsrc ! ! fakesink"));
  EXPECT_EQ(e.code, ErrorCode::kInvalidArgument);
  EXPECT_THAT(e.message, HasSubstr("bad pipeline"));
}

TEST(GstStartErrors, MissingDeviceIsNamed) {
  const Error e = OpenError(LiveOptions("v4l2src device=/dev/video-none"));
  EXPECT_TRUE(e.code == ErrorCode::kNotFound || e.code == ErrorCode::kUnavailable)
      << ErrorCodeName(e.code);
  EXPECT_THAT(e.message, HasSubstr("/dev/video-none"));
}

TEST(GstStartErrors, WrongSizeNamesBothSizes) {
  GstOptions options =
      LiveOptions("videotestsrc is-live=true ! video/x-raw,width=640,height=240,framerate=30/1");
  options.width = 640;
  options.height = 480;
  const Error e = OpenError(options);
  EXPECT_EQ(e.code, ErrorCode::kInvalidArgument);
  EXPECT_THAT(e.message, HasSubstr("frame is 640x240 (320x240 views) but width/height say "
                                   "640x480 per view"));
}

TEST(GstStartErrors, CalibrationOfAnotherSize) {
  GstOptions options =
      LiveOptions("videotestsrc is-live=true ! video/x-raw,width=640,height=240,framerate=30/1");
  auto rig = std::make_shared<geometry::StereoRig>(
      geometry::StereoRig::Ideal(cv::Size(640, 480), 500, 0.1, 320, 240));
  const Error e = OpenError(options, rig);
  EXPECT_EQ(e.code, ErrorCode::kInvalidArgument);
  EXPECT_THAT(e.message, HasSubstr("but the calibration's image size is 640x480"));
  options.width = 320;
  options.height = 240;
  EXPECT_THAT(OpenError(options, rig).message,
              HasSubstr("the calibration's image size 640x480 differs from width/height 320x240"));
}

TEST(GstStartErrors, OddWidthSideBySide) {
  const Error e = OpenError(
      LiveOptions("videotestsrc is-live=true ! video/x-raw,width=321,height=240,framerate=30/1"));
  EXPECT_EQ(e.code, ErrorCode::kInvalidArgument);
  EXPECT_THAT(e.message, HasSubstr("frame width 321 (of 321x240) is odd"));
}

TEST(GstStartErrors, OddHeightTopBottom) {
  GstOptions options =
      LiveOptions("videotestsrc is-live=true ! video/x-raw,width=320,height=241,framerate=30/1");
  options.layout = GstLayout::kTopBottom;
  const Error e = OpenError(options);
  EXPECT_EQ(e.code, ErrorCode::kInvalidArgument);
  EXPECT_THAT(e.message, HasSubstr("frame height 241 (of 320x241) is odd"));
}

TEST(GstStartErrors, NoFrameWithinTheStartTimeout) {
  // An appsrc nobody feeds: a pipeline that starts and never delivers.
  GstOptions options = LiveOptions(
      "appsrc is-live=true format=time caps=video/x-raw,format=GRAY8,width=64,height=32,"
      "framerate=30/1");
  options.start_timeout = std::chrono::milliseconds(500);
  const Error e = OpenError(options);
  EXPECT_EQ(e.code, ErrorCode::kUnavailable);
  EXPECT_THAT(e.message, HasSubstr("app: no frame within 0.5 s of starting"));
}

TEST(GstStartErrors, InvalidOptionsFailBeforeStarting) {
  GstOptions options = LiveOptions("videotestsrc ! appsink name=stevi_sink");
  const Error e = OpenError(options);
  EXPECT_EQ(e.code, ErrorCode::kInvalidArgument);
  EXPECT_THAT(e.message, HasSubstr("pipeline: must not name an element stevi_sink"));
}

TEST(GstStartErrors, StreamThatDoesNotNegotiate) {
  // Audio cannot become GRAY8 video.
  const Error e = OpenError(LiveOptions("audiotestsrc is-live=true"));
  EXPECT_EQ(e.code, ErrorCode::kInvalidArgument);
  EXPECT_THAT(e.message, HasSubstr("audiotest: "));
}

TEST(GstLive, StampsCaptureTimesOnBothClocks) {
  GstOptions options = LiveOptions(
      "videotestsrc is-live=true pattern=smpte ! video/x-raw,width=320,height=120,framerate=30/1");
  Result<std::unique_ptr<GstStereoSource>> source = GstStereoSource::Open(options, nullptr);
  ASSERT_TRUE(source.ok()) << source.error().message;
  GstStereoSource& s = *source.value();
  EXPECT_EQ(s.NominalFps(), 0);
  EXPECT_EQ(s.ImageSize(), cv::Size(160, 120));
  EXPECT_EQ(s.Describe(),
            "gst side-by-side 160x120 (videotestsrc is-live=true pattern=smpte ! "
            "video/x-raw,width=...)");
  EXPECT_THAT(s.Notes(), ::testing::Contains(HasSubstr(
                             "videotest: pipeline videotestsrc is-live=true pattern=smpte ! "
                             "video/x-raw,width=320,height=120,framerate=30/1 ! videoconvert")));
  int64_t last_index = -1;
  int64_t last_t = 0;
  for (int k = 0; k < 10; ++k) {
    Result<StereoFrame> frame = s.Next();
    ASSERT_TRUE(frame.ok()) << frame.error().message;
    const int64_t now_mono =
        std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch())
            .count();
    // Captured before it was handed out, and recently (generous under load).
    EXPECT_LE(frame->t_ns, now_mono);
    EXPECT_GT(frame->t_ns, now_mono - 2'000'000'000);
    EXPECT_NEAR(static_cast<double>(frame->unix_time_ns - frame->t_ns),
                static_cast<double>(UnixNowNs() - now_mono), 5e6);
    EXPECT_GT(frame->index, last_index);
    EXPECT_GT(frame->t_ns, last_t);
    last_index = frame->index;
    last_t = frame->t_ns;
    ASSERT_EQ(frame->left.size(), cv::Size(160, 120));
    EXPECT_EQ(frame->pair_skew_ns, 0);
    // SMPTE bars: the two halves of the frame differ.
    EXPECT_GT(cv::norm(frame->left, frame->right, cv::NORM_L1), 0.0);
  }
}

// A live pipeline that ends (num-buffers) is lost, rebuilt, and delivers again.
TEST(GstLive, EndOfStreamIsALossAndTheRebuildDeliversAgain) {
  GstOptions options = LiveOptions(
      "videotestsrc is-live=true num-buffers=15 ! video/x-raw,width=64,height=32,framerate=30/1");
  Result<std::unique_ptr<GstStereoSource>> source = GstStereoSource::Open(options, nullptr);
  ASSERT_TRUE(source.ok()) << source.error().message;
  GstStereoSource& s = *source.value();
  bool lost = false;
  std::string message;
  int frames_after = 0;
  for (int k = 0; k < 200 && frames_after < 5; ++k) {
    Result<StereoFrame> frame = s.Next();
    if (!frame.ok()) {
      EXPECT_THAT(frame, IsError(ErrorCode::kUnavailable));
      if (!lost) message = frame.error().message;
      lost = true;
    } else if (lost) {
      ++frames_after;
    }
  }
  ASSERT_TRUE(lost);
  EXPECT_THAT(message,
              AllOf(HasSubstr("videotest: lost (end of stream)"), HasSubstr("ago; reconnecting")));
  EXPECT_EQ(frames_after, 5);
  EXPECT_GE(s.Counters().reconnects, 1u);
}

TEST(GstLive, InterruptReturnsAtOnce) {
  GstOptions options =
      LiveOptions("videotestsrc is-live=true ! video/x-raw,width=64,height=32,framerate=1/1");
  options.fps = 1;
  options.timeout = std::chrono::milliseconds(30000);
  Result<std::unique_ptr<GstStereoSource>> source = GstStereoSource::Open(options, nullptr);
  ASSERT_TRUE(source.ok()) << source.error().message;
  GstStereoSource& s = *source.value();
  ASSERT_TRUE(s.Next().ok());  // the first frame, taken at the start
  const auto start = Clock::now();
  std::future<Result<StereoFrame>> next = std::async(std::launch::async, [&s] { return s.Next(); });
  s.Interrupt();
  ASSERT_EQ(next.wait_for(std::chrono::seconds(10)), std::future_status::ready);
  Result<StereoFrame> result = next.get();
  // Either the interrupt, or (when the next second's frame won the race) the frame.
  if (!result.ok()) {
    EXPECT_THAT(result, IsError(ErrorCode::kUnavailable, HasSubstr("stopped")));
  }
  EXPECT_FALSE(s.Next().ok());
  EXPECT_LT(Clock::now() - start, std::chrono::seconds(10));
}

// Two videotestsrc, the right one's times `offset_ns` later. Not live: 30 frames each, in order.
// Live: videotestsrc paced by clocksync, whose times (unlike a live videotestsrc's, which
// GstBaseSrc moves to the running time of its start) stay k / fps + offset on the base time both
// share.
GstOptions TwoOptions(bool live, int64_t offset_ns, double tolerance_ms) {
  const std::string common = std::string(live ? "" : " num-buffers=30") +
                             " ! video/x-raw,width=160,height=120,framerate=30/1" +
                             (live ? " ! clocksync" : "");
  GstOptions options;
  options.layout = GstLayout::kTwo;
  options.left_pipeline = "videotestsrc pattern=ball" + common;
  options.right_pipeline =
      "videotestsrc pattern=snow timestamp-offset=" + std::to_string(offset_ns) + common;
  options.live = live;
  options.fps = 30;
  options.pair_tolerance_ms = tolerance_ms;
  options.timeout = std::chrono::milliseconds(1000);
  return options;
}

TEST(GstTwoPipelines, FilesPairEveryFrameAtTheOffset) {
  Result<std::unique_ptr<GstStereoSource>> source =
      GstStereoSource::Open(TwoOptions(false, 5'000'000, 0), nullptr);
  ASSERT_TRUE(source.ok()) << source.error().message;
  GstStereoSource& s = *source.value();
  EXPECT_EQ(s.NominalFps(), 30);
  EXPECT_THAT(s.Describe(), HasSubstr("gst two 160x120 (left: videotestsrc pattern=ball"));
  int pairs = 0;
  Result<StereoFrame> frame = s.Next();
  for (; frame.ok() && pairs < 100; frame = s.Next(), ++pairs) {
    EXPECT_EQ(frame->index, pairs);
    EXPECT_EQ(frame->t_ns, gst_util_uint64_scale(pairs, GST_SECOND, 30));
    EXPECT_EQ(frame->pair_skew_ns, 5'000'000);
    EXPECT_EQ(frame->left.size(), cv::Size(160, 120));
    EXPECT_EQ(frame->right.size(), cv::Size(160, 120));
  }
  ASSERT_FALSE(frame.ok());
  EXPECT_THAT(frame, IsError(ErrorCode::kOutOfRange)) << frame.error().message;
  EXPECT_THAT(frame.error().message, HasSubstr("end of the stream after 30 pairs"));
  EXPECT_EQ(pairs, 30);
  const SourceCounters c = s.Counters();
  std::printf(
      "files, right +5 ms: %llu pairs, %llu unpaired, skew last %lld max %lld mean %.0f ns\n",
      static_cast<unsigned long long>(c.pairs), static_cast<unsigned long long>(c.unpaired_dropped),
      static_cast<long long>(c.last_skew_ns), static_cast<long long>(c.max_abs_skew_ns),
      c.mean_abs_skew_ns);
  EXPECT_EQ(c.pairs, 30u);
  EXPECT_EQ(c.unpaired_dropped, 0u);
  EXPECT_EQ(c.last_skew_ns, 5'000'000);
  EXPECT_EQ(c.max_abs_skew_ns, 5'000'000);
  EXPECT_DOUBLE_EQ(c.mean_abs_skew_ns, 5e6);
}

TEST(GstTwoPipelines, FilesBeyondTheToleranceCountUnpairedFrames) {
  // 16 ms apart at 30 fps: 16 and 17.3 ms from the two nearest partners, both beyond 4 ms.
  Result<std::unique_ptr<GstStereoSource>> source =
      GstStereoSource::Open(TwoOptions(false, 16'000'000, 4), nullptr);
  ASSERT_TRUE(source.ok()) << source.error().message;
  Result<StereoFrame> frame = source.value()->Next();
  ASSERT_FALSE(frame.ok());
  EXPECT_THAT(frame, IsError(ErrorCode::kOutOfRange)) << frame.error().message;
  EXPECT_THAT(frame.error().message, HasSubstr("after 0 pairs"));
  const SourceCounters c = source.value()->Counters();
  std::printf("files, right +16 ms, tolerance 4 ms: %llu pairs, %llu unpaired dropped\n",
              static_cast<unsigned long long>(c.pairs),
              static_cast<unsigned long long>(c.unpaired_dropped));
  EXPECT_EQ(c.pairs, 0u);
  // 60 frames; a side's last frames may still wait for a partner at the end.
  EXPECT_GE(c.unpaired_dropped, 50u);
  EXPECT_LE(c.unpaired_dropped, 60u);
}

// Live: both pipelines get one base time, so the running times pair exactly.
TEST(GstTwoPipelines, LivePairsWithinTheToleranceAtTheOffset) {
  Result<std::unique_ptr<GstStereoSource>> source =
      GstStereoSource::Open(TwoOptions(true, 3'000'000, 0), nullptr);
  ASSERT_TRUE(source.ok()) << source.error().message;
  GstStereoSource& s = *source.value();
  EXPECT_EQ(s.NominalFps(), 0);
  int64_t last_index = -1;
  for (int k = 0; k < 15; ++k) {
    Result<StereoFrame> frame = s.Next();
    ASSERT_TRUE(frame.ok()) << frame.error().message;
    EXPECT_EQ(frame->pair_skew_ns, 3'000'000);
    EXPECT_GT(frame->index, last_index);
    EXPECT_NE(frame->unix_time_ns, 0);
    last_index = frame->index;
  }
  const SourceCounters c = s.Counters();
  std::printf(
      "live, right +3 ms: %llu pairs, %llu unpaired, skew last %lld max %lld mean %.0f ns\n",
      static_cast<unsigned long long>(c.pairs), static_cast<unsigned long long>(c.unpaired_dropped),
      static_cast<long long>(c.last_skew_ns), static_cast<long long>(c.max_abs_skew_ns),
      c.mean_abs_skew_ns);
  EXPECT_GE(c.pairs, 15u);
  EXPECT_EQ(c.last_skew_ns, 3'000'000);
  EXPECT_EQ(c.max_abs_skew_ns, 3'000'000);
}

TEST(GstTwoPipelines, LiveBeyondTheToleranceSaysWhyNoPairComes) {
  Result<std::unique_ptr<GstStereoSource>> source =
      GstStereoSource::Open(TwoOptions(true, 16'000'000, 4), nullptr);
  ASSERT_TRUE(source.ok()) << source.error().message;
  Result<StereoFrame> frame = source.value()->Next();
  ASSERT_FALSE(frame.ok());
  EXPECT_THAT(frame, IsError(ErrorCode::kUnavailable));
  std::printf("%s\n", frame.error().message.c_str());
  EXPECT_THAT(frame.error().message, AllOf(HasSubstr("no pair for 1 s (left: "),
                                           HasSubstr("frames do not pair within 4.0 ms")));
  const SourceCounters c = source.value()->Counters();
  EXPECT_EQ(c.pairs, 0u);
  EXPECT_GE(c.unpaired_dropped, 10u);
}

}  // namespace
}  // namespace stevi::drivers
