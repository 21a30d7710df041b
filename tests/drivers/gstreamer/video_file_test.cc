// A video round trip: synthetic stereo pairs (known disparity) written side by side, or one above
// the other, into a Motion-JPEG AVI by a real GStreamer pipeline (appsrc ! jpegenc ! avimux),
// then read back through GstStereoSource as a file: every frame, in order, at its PTS, each view
// within a measured JPEG error of the original.
#include <algorithm>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gst/app/gstappsrc.h>
#include <gst/gst.h>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "drivers/gstreamer/gst_capture.h"
#include "drivers/gstreamer/gst_ptr.h"
#include "drivers/gstreamer/gst_source.h"
#include "drivers/gstreamer/pipelines.h"
#include "drivers/synthetic/synthetic_source.h"
#include "tests/testing/gst_testing.h"
#include "tests/testing/status_matchers.h"

using stevi::testing::IsError;

namespace stevi::drivers {
namespace {

using ::testing::HasSubstr;

constexpr int kFps = 10;
constexpr int kFrames = 30;
// JPEG at quality 95 of the noisy synthetic views measured 41.6-41.8 dB (side by side, 320x240
// views) and 41.7-41.9 dB (top-bottom, 318x240); the bound leaves a margin of about 5 dB.
constexpr double kMinPsnrDb = 36.0;

struct Pair {
  cv::Mat left, right;
};

// `count` rendered pairs of the default scene at `view` size (noise sigma 2, as a camera).
std::vector<Pair> RenderPairs(cv::Size view, int count) {
  SyntheticOptions options;
  options.width = view.width;
  options.height = view.height;
  options.f_px = 0.55 * view.width * 2;
  options.fps = kFps;
  Result<std::unique_ptr<SyntheticSource>> source = OpenSyntheticSource(options);
  EXPECT_TRUE(source.ok()) << source.error().message;
  std::vector<Pair> pairs;
  for (int k = 0; k < count && source.ok(); ++k) {
    Result<StereoFrame> frame = source.value()->Next();
    EXPECT_TRUE(frame.ok());
    if (!frame.ok()) break;
    EXPECT_EQ(frame->left.type(), CV_8UC1);
    pairs.push_back({frame->left, frame->right});
  }
  return pairs;
}

cv::Mat Compose(const Pair& pair, GstLayout layout) {
  cv::Mat whole;
  if (layout == GstLayout::kSideBySide) {
    cv::hconcat(pair.left, pair.right, whole);
  } else {
    cv::vconcat(pair.left, pair.right, whole);
  }
  return whole;
}

// A folder with a space in its name: the path goes through QuoteGstValue.
std::string TempPath(const std::string& name) {
  const std::filesystem::path dir =
      std::filesystem::path(::testing::TempDir()) / "stevi gst video_file_test";
  std::filesystem::create_directories(dir);
  return (dir / name).string();
}

struct Reading {
  std::vector<StereoFrame> frames;
  Error end;
};

// Reads until the first error (the end, kOutOfRange, when all is well), at most `limit` pairs.
Reading ReadAll(GstStereoSource& source, int limit) {
  Reading reading;
  for (int k = 0; k < limit; ++k) {
    Result<StereoFrame> frame = source.Next();
    if (!frame.ok()) {
      reading.end = frame.error();
      return reading;
    }
    reading.frames.push_back(std::move(frame.value()));
  }
  reading.end = Internal("no end after " + std::to_string(limit) + " pairs");
  return reading;
}

GstOptions FileOptions(const std::string& path, GstLayout layout) {
  GstOptions options;
  options.layout = layout;
  Result<std::string> pipeline = VideoFilePipeline(path);
  EXPECT_TRUE(pipeline.ok());
  options.pipeline = pipeline.ok() ? pipeline.value() : "";
  options.live = false;
  options.fps = 25;  // not the file's: NominalFps() must come from the caps
  options.timeout = std::chrono::milliseconds(10000);
  return options;
}

void ExpectRoundTrip(GstLayout layout, cv::Size view, const std::string& name) {
  const std::vector<Pair> pairs = RenderPairs(view, kFrames);
  ASSERT_EQ(pairs.size(), static_cast<size_t>(kFrames));
  std::vector<cv::Mat> whole;
  for (const Pair& p : pairs) whole.push_back(Compose(p, layout));
  const std::string path = TempPath(name);
  testing::WriteMjpegAvi(path, whole, kFps);
  if (::testing::Test::HasFatalFailure()) return;

  GstOptions options = FileOptions(path, layout);
  options.width = view.width;
  options.height = view.height;
  Result<std::unique_ptr<GstStereoSource>> source = GstStereoSource::Open(options, nullptr);
  ASSERT_TRUE(source.ok()) << source.error().message;
  EXPECT_DOUBLE_EQ(source.value()->NominalFps(), kFps);
  EXPECT_EQ(source.value()->ImageSize(), view);
  EXPECT_THAT(
      source.value()->Describe(),
      HasSubstr(std::string("gst ") + GstLayoutName(layout) + " " + std::to_string(view.width) +
                "x" + std::to_string(view.height) + " (filesrc location="));
  const Reading reading = ReadAll(*source.value(), kFrames + 10);
  EXPECT_EQ(reading.end.code, ErrorCode::kOutOfRange) << reading.end.message;
  EXPECT_THAT(reading.end.message, HasSubstr("end of the stream after 30 pairs"));
  ASSERT_EQ(reading.frames.size(), static_cast<size_t>(kFrames));
  double worst_psnr = 1e9;
  double best_psnr = 0;
  for (int k = 0; k < kFrames; ++k) {
    const StereoFrame& f = reading.frames[k];
    EXPECT_EQ(f.index, k);
    EXPECT_EQ(f.t_ns, static_cast<int64_t>(k) * 1'000'000'000 / kFps) << "frame " << k;
    EXPECT_EQ(f.unix_time_ns, 0);  // a file: unknown, the server stamps it
    EXPECT_FALSE(f.rectified);
    ASSERT_EQ(f.left.type(), CV_8UC1);
    ASSERT_EQ(f.left.size(), view);
    ASSERT_EQ(f.right.size(), view);
    const double left = cv::PSNR(f.left, pairs[k].left);
    const double right = cv::PSNR(f.right, pairs[k].right);
    // Each view matches its own original, not the other (frame order and halves not swapped).
    EXPECT_GE(left, kMinPsnrDb) << "frame " << k;
    EXPECT_GE(right, kMinPsnrDb) << "frame " << k;
    EXPECT_LT(cv::PSNR(f.left, pairs[k].right), kMinPsnrDb - 10) << "frame " << k;
    if (k + 1 < kFrames) {
      EXPECT_LT(cv::PSNR(f.left, pairs[k + 1].left), left) << "frame " << k;
    }
    worst_psnr = std::min({worst_psnr, left, right});
    best_psnr = std::max({best_psnr, left, right});
  }
  std::printf("%s %dx%d views: PSNR %.2f..%.2f dB over %d frames\n", GstLayoutName(layout),
              view.width, view.height, worst_psnr, best_psnr, kFrames);
  const SourceCounters counters = source.value()->Counters();
  EXPECT_EQ(counters.pairs, static_cast<uint64_t>(kFrames));
  EXPECT_EQ(counters.reconnects, 0u);
}

TEST(GstVideoFile, SideBySideRoundTripKeepsEveryFrameInOrder) {
  ExpectRoundTrip(GstLayout::kSideBySide, cv::Size(320, 240), "side by side.avi");
}

// 318-pixel rows are padded to 320 in GRAY8 buffers: the copy must honour the stride.
TEST(GstVideoFile, TopBottomRoundTripHonoursTheStride) {
  ExpectRoundTrip(GstLayout::kTopBottom, cv::Size(318, 240), "top bottom.avi");
}

TEST(GstVideoFile, LoopsWithTimesThatKeepIncreasing) {
  const std::vector<Pair> pairs = RenderPairs(cv::Size(160, 120), 5);
  std::vector<cv::Mat> whole;
  for (const Pair& p : pairs) whole.push_back(Compose(p, GstLayout::kSideBySide));
  const std::string path = TempPath("loop.avi");
  testing::WriteMjpegAvi(path, whole, kFps);
  if (::testing::Test::HasFatalFailure()) return;
  GstOptions options = FileOptions(path, GstLayout::kSideBySide);
  options.loop = true;
  Result<std::unique_ptr<GstStereoSource>> source = GstStereoSource::Open(options, nullptr);
  ASSERT_TRUE(source.ok()) << source.error().message;
  for (int k = 0; k < 12; ++k) {  // two laps and a bit
    Result<StereoFrame> frame = source.value()->Next();
    ASSERT_TRUE(frame.ok()) << frame.error().message;
    EXPECT_EQ(frame->index, k);
    EXPECT_EQ(frame->t_ns, static_cast<int64_t>(k) * 100'000'000) << "frame " << k;
    EXPECT_GE(cv::PSNR(frame->left, pairs[k % 5].left), kMinPsnrDb) << "frame " << k;
  }
}

// The appsink takes the luma of a decoder's or a camera's YUV format as it is, without a
// conversion: a lossless video of the views, turned by the pipeline into each format the sink
// takes (videoconvert keeps the luma of a grey image), comes back with the views' pixels exactly.
TEST(GstVideoFile, EachYuvFormatGivesItsLumaExactly) {
  const std::vector<Pair> pairs = RenderPairs(cv::Size(160, 120), 3);
  std::vector<cv::Mat> whole;
  for (const Pair& p : pairs) whole.push_back(Compose(p, GstLayout::kSideBySide));
  const std::string path = TempPath("raw.mkv");
  testing::WriteRawMkv(path, whole, kFps);
  if (::testing::Test::HasFatalFailure()) return;
  for (const char* format :
       {"GRAY8", "I420", "YV12", "NV12", "NV21", "Y42B", "Y444", "YUY2", "YVYU", "UYVY"}) {
    SCOPED_TRACE(format);
    GstOptions options = FileOptions(path, GstLayout::kSideBySide);
    options.pipeline += std::string(" ! videoconvert ! video/x-raw,format=") + format;
    Result<std::unique_ptr<GstStereoSource>> source = GstStereoSource::Open(options, nullptr);
    ASSERT_TRUE(source.ok()) << source.error().message;
    const Reading reading = ReadAll(*source.value(), 10);
    ASSERT_EQ(reading.frames.size(), pairs.size()) << reading.end.message;
    for (size_t k = 0; k < pairs.size(); ++k) {
      EXPECT_EQ(cv::norm(reading.frames[k].left, pairs[k].left, cv::NORM_INF), 0) << "frame " << k;
      EXPECT_EQ(cv::norm(reading.frames[k].right, pairs[k].right, cv::NORM_INF), 0)
          << "frame " << k;
    }
  }
}

// Concatenated JPEGs in multipart/x-mixed-replace framing (multipartdemux's default boundary):
// a stream whose frame size can change in the middle.
void WriteMultipartJpeg(const std::string& path, const std::vector<cv::Mat>& frames) {
  std::ofstream out(path, std::ios::binary);
  for (const cv::Mat& frame : frames) {
    std::vector<uchar> jpeg;
    ASSERT_TRUE(cv::imencode(".jpg", frame, jpeg));
    out << "--ThisRandomString\r\nContent-Type: image/jpeg\r\nContent-Length: " << jpeg.size()
        << "\r\n\r\n";
    out.write(reinterpret_cast<const char*>(jpeg.data()),
              static_cast<std::streamsize>(jpeg.size()));
    out << "\r\n";
  }
  out << "--ThisRandomString--\r\n";
  ASSERT_TRUE(out.good());
}

// A size change after the start is an error too, naming both sizes; the frames before it come.
TEST(GstVideoFile, FrameOfAnotherSizeLaterIsAnError) {
  std::vector<cv::Mat> frames(3, cv::Mat(32, 64, CV_8UC1, cv::Scalar(100)));
  frames.emplace_back(32, 80, CV_8UC1, cv::Scalar(100));
  const std::string path = TempPath("size change.mjpeg");
  WriteMultipartJpeg(path, frames);
  if (::testing::Test::HasFatalFailure()) return;
  Result<std::string> file = QuoteGstValue(path, "path");
  ASSERT_TRUE(file.ok());
  for (const bool sized : {true, false}) {
    GstOptions options;
    options.pipeline = "filesrc location=" + file.value() + " ! multipartdemux ! jpegdec";
    options.live = false;
    options.width = sized ? 32 : 0;
    options.height = sized ? 32 : 0;
    options.timeout = std::chrono::milliseconds(10000);
    Result<std::unique_ptr<GstStereoSource>> source = GstStereoSource::Open(options, nullptr);
    ASSERT_TRUE(source.ok()) << source.error().message;
    const Reading reading = ReadAll(*source.value(), 10);
    EXPECT_EQ(reading.frames.size(), 3u);
    EXPECT_EQ(reading.end.code, ErrorCode::kInvalidArgument) << reading.end.message;
    EXPECT_THAT(reading.end.message,
                HasSubstr(sized ? "frame is 80x32 (40x32 views) but width/height say 32x32 per view"
                                : "frame is 80x32 (40x32 views) but the first frames had 32x32 "
                                  "views"));
  }
}

TEST(GstVideoFile, MissingFileIsNotFound) {
  GstOptions options = FileOptions(TempPath("no such file.avi"), GstLayout::kSideBySide);
  Result<std::unique_ptr<GstStereoSource>> source = GstStereoSource::Open(options, nullptr);
  ASSERT_FALSE(source.ok());
  EXPECT_THAT(source, IsError(ErrorCode::kNotFound)) << source.error().message;
  EXPECT_THAT(source.error().message, HasSubstr("no such file.avi"));
}

}  // namespace
}  // namespace stevi::drivers
