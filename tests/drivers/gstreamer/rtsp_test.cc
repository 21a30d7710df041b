// GstStereoSource reading a live side-by-side MJPEG stream from a real gst-rtsp-server on
// 127.0.0.1 (a free port, its own GMainContext thread) through RtspPipeline: the views match the
// stream's source, the loss of the server is reported by Next() and the source reconnects by
// itself once the server serves again on the same port. Everything waits on events, in bounded
// loops; no sleep is a synchronisation.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include <gmock/gmock.h>
#include <gst/gst.h>
#include <gst/rtsp-server/rtsp-server.h>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "drivers/gstreamer/gst_capture.h"
#include "drivers/gstreamer/gst_source.h"
#include "drivers/gstreamer/pipelines.h"
#include "tests/testing/gst_testing.h"
#include "tests/testing/status_matchers.h"

using stevi::testing::IsError;

namespace stevi::drivers {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;
using Clock = std::chrono::steady_clock;

// 640x240 frames of 75% colour bars (static, unlike smpte's noise corner): two different
// 320x240 views side by side. rtpjpegpay takes only
// 3-component JPEG, so the frames are I420.
constexpr const char* kCaps = "video/x-raw,format=I420,width=640,height=240,framerate=15/1";
// Default jpegenc quality (85) on the flat bars measured 49.0-49.1 dB per view.
constexpr double kMinPsnrDb = 40.0;

double SecondsSince(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

// The bars as the stream's source makes them, before JPEG: the reference views.
StereoFrame ReferenceBars() {
  GstOptions options;
  options.pipeline = std::string("videotestsrc is-live=true pattern=smpte75 ! ") + kCaps;
  options.fps = 15;
  Result<std::unique_ptr<GstStereoSource>> source = GstStereoSource::Open(options, nullptr);
  EXPECT_TRUE(source.ok()) << source.error().message;
  if (!source.ok()) return {};
  Result<StereoFrame> frame = source.value()->Next();
  EXPECT_TRUE(frame.ok()) << frame.error().message;
  return frame.ok() ? frame.value() : StereoFrame{};
}

// Takes `count` pairs, checking each against the reference; false at the first error.
void ExpectBars(GstStereoSource& source, const StereoFrame& reference, int count,
                double* worst_psnr) {
  int64_t last_t = 0;
  for (int k = 0; k < count; ++k) {
    Result<StereoFrame> frame = source.Next();
    ASSERT_TRUE(frame.ok()) << frame.error().message;
    ASSERT_EQ(frame->left.size(), cv::Size(320, 240));
    EXPECT_GT(frame->t_ns, last_t);
    last_t = frame->t_ns;
    const double left = cv::PSNR(frame->left, reference.left);
    const double right = cv::PSNR(frame->right, reference.right);
    EXPECT_GE(left, kMinPsnrDb);
    EXPECT_GE(right, kMinPsnrDb);
    *worst_psnr = std::min({*worst_psnr, left, right});
  }
}

TEST(GstRtsp, ReadsTheStreamSurvivesTheServersLossAndReconnects) {
  const StereoFrame reference = ReferenceBars();
  ASSERT_FALSE(reference.left.empty());
  testing::LoopbackRtspServer server(std::string("( videotestsrc is-live=true pattern=smpte75 ! ") +
                                     kCaps + " ! jpegenc ! rtpjpegpay name=pay0 pt=26 )");
  const int port = server.Serve();
  ASSERT_GT(port, 0);
  const std::string url = "rtsp://127.0.0.1:" + std::to_string(port) + "/stereo";
  Result<std::string> pipeline = RtspPipeline(url, 0);
  ASSERT_TRUE(pipeline.ok()) << pipeline.error().message;

  GstOptions options;
  options.pipeline = pipeline.value();
  options.fps = 15;
  options.width = 320;
  options.height = 240;
  options.timeout = std::chrono::milliseconds(1000);
  const auto opening = Clock::now();
  Result<std::unique_ptr<GstStereoSource>> opened = GstStereoSource::Open(options, nullptr);
  ASSERT_TRUE(opened.ok()) << opened.error().message;
  GstStereoSource& source = *opened.value();
  std::printf("opened in %.2f s: %s\n", SecondsSince(opening), source.Describe().c_str());
  EXPECT_THAT(source.Describe(), HasSubstr("gst side-by-side 320x240 (rtspsrc location="));
  double worst_psnr = 1e9;
  ExpectBars(source, reference, 10, &worst_psnr);
  if (HasFatalFailure()) return;

  // The server goes away: its clients' connections close, nothing listens.
  server.Stop();
  const auto stopped = Clock::now();
  std::string loss;
  for (int k = 0; k < 100 && loss.empty(); ++k) {  // frames still queued may come first
    Result<StereoFrame> frame = source.Next();
    if (!frame.ok()) {
      EXPECT_THAT(frame, IsError(ErrorCode::kUnavailable));
      loss = frame.error().message;
    }
  }
  std::printf("loss seen after %.2f s: %s\n", SecondsSince(stopped), loss.c_str());
  EXPECT_THAT(loss, AllOf(HasSubstr("rtsp: lost ("), HasSubstr("reconnecting")));
  // While it is down, Next() keeps saying so, with the failed attempts.
  std::string down;
  for (int k = 0; k < 10 && down.find("attempt") == std::string::npos; ++k) {
    Result<StereoFrame> frame = source.Next();
    ASSERT_FALSE(frame.ok());
    down = frame.error().message;
  }
  std::printf("while down: %s\n", down.c_str());
  EXPECT_THAT(down, AllOf(HasSubstr("rtsp: lost ("), HasSubstr("; reconnecting, attempt ")));
  EXPECT_EQ(source.Counters().reconnects, 0u);

  // The server comes back on the same port: the source finds it again by itself.
  ASSERT_EQ(server.Serve(), port);
  const auto restarted = Clock::now();
  bool back = false;
  for (int k = 0; k < 60 && !back; ++k) back = source.Next().ok();
  ASSERT_TRUE(back) << "no frame within 60 Next() calls of the server's return";
  std::printf("frames again %.2f s after the server's return\n", SecondsSince(restarted));
  EXPECT_GE(source.Counters().reconnects, 1u);
  ExpectBars(source, reference, 10, &worst_psnr);
  std::printf("views vs the stream's source: worst PSNR %.2f dB\n", worst_psnr);
}

}  // namespace
}  // namespace stevi::drivers
