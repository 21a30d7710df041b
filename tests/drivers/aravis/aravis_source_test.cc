// The Aravis camera wrapper and stereo source, against real Aravis:
// - AravisFakeInterface*: Aravis's in-process fake camera ("Fake_1"), for configuration;
// - AravisGigE*: two arv-fake-gv-camera-0.8 processes on 127.0.0.1 and 127.0.0.2, reached
//   through Aravis's GigE Vision stack. These run in a private network namespace: ctest starts
//   them through tests/drivers/fake_camera_netns.sh.
// - ToGrey*, AravisOptions*: pure functions.
#include "drivers/aravis/aravis_source.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "core/geometry/stereo_rig.h"
#include "tests/testing/data.h"
#include "tests/testing/fake_gv_camera.h"
#include "tests/testing/status_matchers.h"

using stevi::testing::IsError;

namespace stevi::drivers {
namespace {

using Clock = std::chrono::steady_clock;
using std::chrono::milliseconds;

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

bool Contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// The fake cameras fill Mono8 frames with a diagonal ramp, value (x + y + frame) % 255 times a
// scale that is 1 at exposure 10000 us and gain 0. A frame is intact when every pixel follows the
// ramp of its top-left pixel: a lost packet (zeros or an older frame's bytes), a shifted ROI or a
// mix of two frames breaks it.
::testing::AssertionResult IsDiagonalRamp(const cv::Mat& image) {
  if (image.empty() || image.type() != CV_8UC1) {
    return ::testing::AssertionFailure() << "not a CV_8UC1 image (type " << image.type() << ")";
  }
  const int phase = image.at<uint8_t>(0, 0);
  int bad = 0;
  cv::Point first_bad(-1, -1);
  for (int y = 0; y < image.rows; ++y) {
    const uint8_t* row = image.ptr<uint8_t>(y);
    for (int x = 0; x < image.cols; ++x) {
      if (row[x] != (x + y + phase) % 255) {
        if (bad++ == 0) first_bad = cv::Point(x, y);
      }
    }
  }
  if (bad == 0) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure()
         << bad << " of " << image.total() << " pixels break the ramp, first at (" << first_bad.x
         << ", " << first_bad.y << "): " << int(image.at<uint8_t>(first_bad)) << " instead of "
         << (first_bad.x + first_bad.y + phase) % 255;
}

// ---------------------------------------------------------------------------------------------
// Pure functions.

// A scene of flat colour patches (BGR), mosaicked as `format` would deliver it.
cv::Mat Mosaic(const cv::Mat& bgr, PixelFormat format) {
  // Channel (B = 0, G = 1, R = 2) at (row, column) of each GenICam pattern; BayerRG8 is
  // R G / G B.
  const auto pattern = [format](int row, int col) {
    const bool r0 = row % 2 == 0, c0 = col % 2 == 0;
    switch (format) {
      case PixelFormat::kBayerRG8: return r0 && c0 ? 2 : !r0 && !c0 ? 0 : 1;
      case PixelFormat::kBayerBG8: return r0 && c0 ? 0 : !r0 && !c0 ? 2 : 1;
      case PixelFormat::kBayerGR8: return r0 && !c0 ? 2 : !r0 && c0 ? 0 : 1;
      case PixelFormat::kBayerGB8: return r0 && !c0 ? 0 : !r0 && c0 ? 2 : 1;
      case PixelFormat::kMono8: break;
    }
    return 1;
  };
  cv::Mat raw(bgr.size(), CV_8UC1);
  for (int y = 0; y < bgr.rows; ++y) {
    for (int x = 0; x < bgr.cols; ++x) {
      raw.at<uint8_t>(y, x) = bgr.at<cv::Vec3b>(y, x)[pattern(y, x)];
    }
  }
  return raw;
}

TEST(ToGrey, DemosaicsEachBayerPatternToTheScenesGrey) {
  // Saturated red, green and blue patches: a pattern read with red and blue swapped would give
  // 0.114 * 255 = 29 instead of 0.299 * 255 = 76 in the red patch.
  cv::Mat bgr(64, 96, CV_8UC3, cv::Scalar(0, 0, 0));
  bgr(cv::Rect(0, 0, 32, 64)).setTo(cv::Scalar(0, 0, 255));
  bgr(cv::Rect(32, 0, 32, 64)).setTo(cv::Scalar(0, 255, 0));
  bgr(cv::Rect(64, 0, 32, 64)).setTo(cv::Scalar(255, 0, 0));
  cv::Mat want;
  cv::cvtColor(bgr, want, cv::COLOR_BGR2GRAY);
  for (PixelFormat format : {PixelFormat::kBayerRG8, PixelFormat::kBayerBG8, PixelFormat::kBayerGR8,
                             PixelFormat::kBayerGB8}) {
    const cv::Mat raw = Mosaic(bgr, format);
    Result<cv::Mat> grey = ToGrey(raw.data, raw.total(), raw.cols, raw.rows, format);
    ASSERT_TRUE(grey.ok()) << grey.error().message;
    ASSERT_EQ(grey->type(), CV_8UC1);
    ASSERT_EQ(grey->size(), bgr.size());
    // Patch interiors (demosaicing blurs the borders).
    for (int patch = 0; patch < 3; ++patch) {
      const cv::Rect inner(patch * 32 + 4, 4, 24, 56);
      double max_diff = 0;
      cv::minMaxLoc(cv::abs((*grey)(inner)-want(inner)), nullptr, &max_diff);
      EXPECT_LE(max_diff, 2) << PixelFormatName(format) << " patch " << patch << ": "
                             << int(grey->at<uint8_t>(32, patch * 32 + 16)) << " vs "
                             << int(want.at<uint8_t>(32, patch * 32 + 16));
    }
  }
}

TEST(ToGrey, CopiesMono8AndRejectsAWrongSize) {
  std::vector<uint8_t> data(12);
  for (size_t i = 0; i < data.size(); ++i) data[i] = static_cast<uint8_t>(i * 10);
  Result<cv::Mat> grey = ToGrey(data.data(), data.size(), 4, 3, PixelFormat::kMono8);
  ASSERT_TRUE(grey.ok()) << grey.error().message;
  data[5] = 0;  // a copy: the buffer goes back to Aravis
  EXPECT_EQ(grey->at<uint8_t>(1, 1), 50);

  Result<cv::Mat> bad = ToGrey(data.data(), 11, 4, 3, PixelFormat::kMono8);
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad, IsError(ErrorCode::kInvalidArgument));
  EXPECT_EQ(bad.error().message, "a Mono8 image of 4x3 needs 12 bytes (got 11)");
}

TEST(PixelFormats, ParseTheSupportedNamesOnly) {
  EXPECT_EQ(ParsePixelFormat("Mono8"), PixelFormat::kMono8);
  EXPECT_EQ(ParsePixelFormat("BayerGB8"), PixelFormat::kBayerGB8);
  EXPECT_FALSE(ParsePixelFormat("RGB8"));
  EXPECT_FALSE(ParsePixelFormat("Mono16"));
  EXPECT_EQ(SupportedPixelFormats(), "Mono8, BayerRG8, BayerGR8, BayerGB8, BayerBG8");
}

TEST(AravisOptions, ValidateListsEveryProblem) {
  AravisOptions ok;
  ok.left_id = "GV01";
  ok.right_id = "GV02";
  EXPECT_TRUE(ok.Validate().empty());
  EXPECT_EQ(ok.FramePeriodNs(), 33'333'333);
  EXPECT_EQ(ok.PairToleranceNs(), 16'666'666);

  AravisOptions bad;
  bad.left_id = "GV01";
  bad.right_id = "GV01";
  bad.roi_width = 0;
  bad.pixel_format = "RGB8";
  bad.frame_rate_hz = 0;
  bad.exposure_us = -5;
  bad.trigger.mode = TriggerMode::kHardware;
  bad.pair_tolerance_ms = -1;
  bad.buffers = 1;
  bad.timeout = milliseconds(0);
  const std::vector<std::string> problems = bad.Validate();
  const std::vector<std::string> want = {
      "width: must be in [16, 16384] pixels (got 0)",
      "frame_rate_hz: must be in (0, 1000] Hz (got 0)",
      "exposure_us: must be in [0, 100000000) us (got -5)",
      "pair_tolerance_ms: must be in [0, 1000] ms (got -1)",
      "buffers: must be in [2, 64] (got 1)",
      "right_id: must be another camera than the left one (both are 'GV01')",
      "pixel_format: RGB8 is not supported (supported: Mono8, BayerRG8, BayerGR8, BayerGB8, "
      "BayerBG8, or empty for automatic)",
      "trigger_line: a hardware trigger needs the camera's line (e.g. Line0)",
      "timeout: must be > 0 ms (got 0)",
  };
  EXPECT_EQ(problems, want);

  AravisOptions odd = ok;
  odd.pixel_format = "BayerRG8";
  odd.roi_width = 641;
  odd.exposure_us = 40000;  // longer than 33 ms
  odd.pair_tolerance_ms = 20;
  const std::vector<std::string> odd_problems = odd.Validate();
  ASSERT_EQ(odd_problems.size(), 3u);
  EXPECT_EQ(odd_problems[0], "width, height: a Bayer mosaic needs an even size (got 641x480)");
  EXPECT_TRUE(Contains(odd_problems[1], "exposure_us: longer than the frame period 33333 us"));
  EXPECT_TRUE(Contains(odd_problems[2], "pair_tolerance_ms: must be at most half the frame"));
}

// ---------------------------------------------------------------------------------------------
// Aravis's in-process fake camera.

class AravisFakeInterface : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    // In-process only: no discovery on the host's network (and no 1 s discovery wait).
    SetAravisInterfaceEnabled("GigEVision", false);
    SetAravisInterfaceEnabled("USB3Vision", false);
    SetAravisInterfaceEnabled("Fake", true);
  }
  static void TearDownTestSuite() {
    SetAravisInterfaceEnabled("Fake", false);
    SetAravisInterfaceEnabled("GigEVision", true);
    SetAravisInterfaceEnabled("USB3Vision", true);
  }

  // Exposure 10000 us and gain 0 keep the ramp at scale 1.
  static CameraSettings Fake() {
    CameraSettings s;
    s.id = "Fake_1";
    s.exposure_us = 10000;
    s.gain_db = 0;
    s.frame_rate_hz = 50;
    return s;
  }
};

TEST_F(AravisFakeInterface, ConfiguresACentredRoiAndDeliversIntactFrames) {
  Result<std::unique_ptr<AravisCamera>> camera = AravisCamera::Open(Fake());
  ASSERT_TRUE(camera.ok()) << camera.error().message;
  const CameraInfo& info = (*camera)->info();
  EXPECT_EQ(info.device.id, "Fake_1");
  EXPECT_EQ(info.device.protocol, "Fake");
  EXPECT_EQ(info.sensor, cv::Size(2048, 2048));
  // Centred: ((2048 - 640) / 2, (2048 - 480) / 2).
  EXPECT_EQ(info.roi, cv::Rect(704, 784, 640, 480));
  EXPECT_EQ(info.pixel_format, PixelFormat::kMono8);
  EXPECT_FALSE(info.exposure_auto);
  EXPECT_DOUBLE_EQ(info.exposure_us, 10000);
  EXPECT_FALSE(info.gain_auto);
  EXPECT_DOUBLE_EQ(info.gain_db, 0);
  EXPECT_NEAR(info.frame_rate_hz, 50, 0.01);
  EXPECT_EQ(info.trigger, TriggerMode::kFreeRun);

  ASSERT_TRUE((*camera)->StartAcquisition().ok());
  int64_t last_t = 0;
  uint64_t last_id = 0;
  for (int i = 0; i < 5; ++i) {
    Result<std::optional<MonoFrame>> frame = (*camera)->Pop(milliseconds(2000));
    ASSERT_TRUE(frame.ok()) << frame.error().message;
    ASSERT_TRUE(frame->has_value()) << "no frame " << i << " within 2 s";
    const MonoFrame& f = **frame;
    EXPECT_EQ(f.image.size(), cv::Size(640, 480));
    EXPECT_TRUE(IsDiagonalRamp(f.image)) << "frame " << i;
    if (i > 0) {
      EXPECT_GT(f.t_ns, last_t);
      EXPECT_GT(f.frame_id, last_id);
    }
    last_t = f.t_ns;
    last_id = f.frame_id;
  }
  EXPECT_EQ((*camera)->Stats().frames, 5u);
  EXPECT_EQ((*camera)->Stats().incomplete, 0u);
}

TEST_F(AravisFakeInterface, SetsFixedExposureAndGainAndReadsThemBack) {
  CameraSettings s = Fake();
  s.roi_width = 320;
  s.roi_height = 200;
  s.exposure_us = 20000;
  s.gain_db = 2.5;
  s.frame_rate_hz = 12.5;
  Result<std::unique_ptr<AravisCamera>> camera = AravisCamera::Open(s);
  ASSERT_TRUE(camera.ok()) << camera.error().message;
  const CameraInfo& info = (*camera)->info();
  EXPECT_EQ(info.roi, cv::Rect(864, 924, 320, 200));
  EXPECT_DOUBLE_EQ(info.exposure_us, 20000);
  EXPECT_NEAR(info.gain_db, 2.5, 1.0);  // the fake stores an integer raw gain
  EXPECT_NEAR(info.frame_rate_hz, 12.5, 0.01);
}

TEST_F(AravisFakeInterface, UsesAutomaticModesWhereOfferedAndSaysWhereNot) {
  CameraSettings s = Fake();
  s.exposure_us = 0;
  s.gain_db = -1;
  Result<std::unique_ptr<AravisCamera>> camera = AravisCamera::Open(s);
  ASSERT_TRUE(camera.ok()) << camera.error().message;
  const CameraInfo& info = (*camera)->info();
  // The fake camera has GainAuto but no ExposureAuto.
  EXPECT_TRUE(info.gain_auto);
  EXPECT_FALSE(info.exposure_auto);
  ASSERT_EQ(info.notes.size(), 1u);
  EXPECT_EQ(info.notes[0], "exposure: the camera has no automatic exposure, kept its setting");
}

TEST_F(AravisFakeInterface, RefusesARoiLargerThanTheSensor) {
  CameraSettings s = Fake();
  s.roi_width = 4096;
  Result<std::unique_ptr<AravisCamera>> camera = AravisCamera::Open(s);
  ASSERT_FALSE(camera.ok());
  EXPECT_THAT(camera, IsError(ErrorCode::kInvalidArgument));
  EXPECT_EQ(camera.error().message,
            "camera Fake_1: the region of interest 4096x480 is larger than its sensor "
            "(2048x2048)");
}

TEST_F(AravisFakeInterface, RefusesUnsupportedPixelFormats) {
  for (const char* format : {"RGB8", "Mono16"}) {
    CameraSettings s = Fake();
    s.pixel_format = format;
    Result<std::unique_ptr<AravisCamera>> camera = AravisCamera::Open(s);
    ASSERT_FALSE(camera.ok()) << format;
    EXPECT_THAT(camera, IsError(ErrorCode::kInvalidArgument));
    EXPECT_EQ(camera.error().message,
              std::string("camera Fake_1: pixel format ") + format +
                  " is not supported (supported: Mono8, BayerRG8, BayerGR8, BayerGB8, BayerBG8)");
  }
}

TEST_F(AravisFakeInterface, DeliversBayerFramesAsGrey) {
  CameraSettings s = Fake();
  s.pixel_format = "BayerGR8";
  s.roi_width = 322;
  s.roi_height = 242;
  Result<std::unique_ptr<AravisCamera>> camera = AravisCamera::Open(s);
  ASSERT_TRUE(camera.ok()) << camera.error().message;
  const CameraInfo& info = (*camera)->info();
  EXPECT_EQ(info.pixel_format, PixelFormat::kBayerGR8);
  // (2048 - 322) / 2 = 863 is odd: a Bayer ROI starts on an even offset to keep its phase.
  EXPECT_EQ(info.roi, cv::Rect(862, 902, 322, 242));
  ASSERT_TRUE((*camera)->StartAcquisition().ok());
  Result<std::optional<MonoFrame>> frame = (*camera)->Pop(milliseconds(2000));
  ASSERT_TRUE(frame.ok()) << frame.error().message;
  ASSERT_TRUE(frame->has_value());
  // The fake does not draw Bayer images; what matters is the conversion to one grey channel.
  EXPECT_EQ((*frame)->image.type(), CV_8UC1);
  EXPECT_EQ((*frame)->image.size(), cv::Size(322, 242));
}

TEST_F(AravisFakeInterface, AcceptsTheSoftwareTrigger) {
  CameraSettings s = Fake();
  s.trigger = TriggerMode::kSoftware;
  Result<std::unique_ptr<AravisCamera>> camera = AravisCamera::Open(s);
  ASSERT_TRUE(camera.ok()) << camera.error().message;
  EXPECT_EQ((*camera)->info().trigger, TriggerMode::kSoftware);
  ASSERT_TRUE((*camera)->StartAcquisition().ok());
  // The in-process fake streams at its trigger poll rate whether triggered or not, so only the
  // calls are checked here; AravisGigE.SoftwareTriggerPairsAtTheTriggerRate checks the pacing
  // on the GigE fake, which does wait for triggers.
  for (int i = 0; i < 3; ++i) {
    ASSERT_TRUE((*camera)->SoftwareTrigger().ok());
    Result<std::optional<MonoFrame>> frame = (*camera)->Pop(milliseconds(2000));
    ASSERT_TRUE(frame.ok()) << frame.error().message;
    ASSERT_TRUE(frame->has_value()) << "no frame for trigger " << i;
    EXPECT_TRUE(IsDiagonalRamp((*frame)->image));
  }
}

TEST_F(AravisFakeInterface, HardwareTriggerNeedsALineTheCameraHas) {
  CameraSettings s = Fake();
  s.trigger = TriggerMode::kHardware;
  s.trigger_line = "Line7";
  Result<std::unique_ptr<AravisCamera>> camera = AravisCamera::Open(s);
  ASSERT_FALSE(camera.ok());
  EXPECT_THAT(camera, IsError(ErrorCode::kInvalidArgument));
  EXPECT_EQ(camera.error().message,
            "camera Fake_1 has no trigger source 'Line7' (it has Line0, Software)");

  s.trigger_line = "Line0";
  camera = AravisCamera::Open(s);
  ASSERT_TRUE(camera.ok()) << camera.error().message;
  EXPECT_EQ((*camera)->info().trigger, TriggerMode::kHardware);
}

TEST_F(AravisFakeInterface, AnUnknownIdListsTheDevicesPresent) {
  CameraSettings s = Fake();
  s.id = "Aravis-Fake-GV09";
  Result<std::unique_ptr<AravisCamera>> camera = AravisCamera::Open(s);
  ASSERT_FALSE(camera.ok());
  EXPECT_THAT(camera, IsError(ErrorCode::kNotFound));
  EXPECT_EQ(camera.error().message,
            "camera 'Aravis-Fake-GV09' not found (matched against device ids, serial numbers "
            "and IP addresses); present: Fake_1 (serial 1)");
}

TEST_F(AravisFakeInterface, OpensBySerialNumber) {
  CameraSettings s = Fake();
  s.id = "1";
  Result<std::unique_ptr<AravisCamera>> camera = AravisCamera::Open(s);
  ASSERT_TRUE(camera.ok()) << camera.error().message;
  EXPECT_EQ((*camera)->id(), "Fake_1");
}

// ---------------------------------------------------------------------------------------------
// Two fake GigE Vision cameras in separate processes.

using testing::FakeGvCamera;

// Both cameras at 30 fps, exposure 10000 us and gain 0 (the ramp's scale 1); the left one by
// serial number, the right one by IP address.
AravisOptions Options() {
  AravisOptions o;
  o.left_id = "GV01";
  o.right_id = "127.0.0.2";
  o.exposure_us = 10000;
  o.gain_db = 0;
  return o;
}

class AravisGigE : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    // Undo the in-process suite's choice when both run in one process.
    SetAravisInterfaceEnabled("Fake", false);
    SetAravisInterfaceEnabled("GigEVision", true);
  }

  void SetUp() override {
    ASSERT_NO_FATAL_FAILURE(testing::ExpectFakeCameraNetwork());
    dir_ = testing::MakeTempDir("aravis_gige");
  }

  // Starts the two cameras (the right one dropping packets if asked) and waits until Aravis
  // discovers both.
  void StartCameras(int right_lost_per_thousand = 0) {
    left_ = std::make_unique<FakeGvCamera>("127.0.0.1", "GV01", dir_ + "/GV01.log");
    right_ = std::make_unique<FakeGvCamera>("127.0.0.2", "GV02", dir_ + "/GV02.log",
                                            right_lost_per_thousand);
    ASSERT_NO_FATAL_FAILURE(left_->Start());
    ASSERT_NO_FATAL_FAILURE(right_->Start());
    ASSERT_NO_FATAL_FAILURE(
        testing::WaitDiscoverable({left_->id(), right_->id()}, {left_.get(), right_.get()}));
  }

  std::string dir_;
  std::unique_ptr<FakeGvCamera> left_, right_;
};

// What `seconds` of Next() calls gave. The source forms pairs at the cameras' rate; Next()
// hands out the newest, so a consumer slower than the cameras (a loaded machine, a sanitizer
// build) sees fewer than were formed: the acquisition rate is the formed one.
struct Acquisition {
  int delivered = 0;    // pairs Next() returned, each checked
  uint64_t formed = 0;  // pairs the source formed meanwhile (Counters().pairs)
  int errors = 0;
  double seconds = 0;
  std::string last_error;

  double fps() const { return static_cast<double>(formed) / seconds; }
};

// Checks every delivered pair: intact ramp images of `size`, skew within the tolerance,
// increasing times and indices.
Acquisition Collect(AravisStereoSource& source, double seconds, int64_t tolerance_ns,
                    cv::Size size) {
  Acquisition run;
  int64_t last_t = 0, last_index = -1;
  const uint64_t formed_before = source.Counters().pairs;
  const auto start = Clock::now();
  while (SecondsSince(start) < seconds) {
    Result<StereoFrame> pair = source.Next();
    if (!pair.ok()) {
      ++run.errors;
      run.last_error = pair.error().message;
      continue;
    }
    ++run.delivered;
    EXPECT_EQ(pair->left.size(), size);
    EXPECT_EQ(pair->right.size(), size);
    EXPECT_FALSE(pair->rectified);
    EXPECT_TRUE(IsDiagonalRamp(pair->left)) << "left of pair " << pair->index;
    EXPECT_TRUE(IsDiagonalRamp(pair->right)) << "right of pair " << pair->index;
    EXPECT_LE(std::llabs(pair->pair_skew_ns), tolerance_ns) << "pair " << pair->index;
    EXPECT_GT(pair->t_ns, last_t);
    EXPECT_GT(pair->index, last_index);
    EXPECT_GT(pair->unix_time_ns, 0);
    last_t = pair->t_ns;
    last_index = pair->index;
  }
  run.seconds = SecondsSince(start);
  run.formed = source.Counters().pairs - formed_before;
  // The hand-off loses little even to a slow consumer.
  EXPECT_GE(run.delivered, 0.7 * static_cast<double>(run.formed))
      << run.delivered << " of " << run.formed << " pairs delivered";
  return run;
}

// The rate of pairs is judged against what the two camera processes delivered in the same
// window, not against the clock: on a loaded 2-core machine (ctest -j2 beside the load test)
// a fake camera process is itself kept off the CPU and sends fewer frames, late (one CI run:
// 24 fps). What the source answers for is pairing the frames it got.
TEST_F(AravisGigE, PairsTheFramesBothCamerasDeliverWithinTheTolerance) {
  ASSERT_NO_FATAL_FAILURE(StartCameras());
  const AravisOptions options = Options();
  auto rig = std::make_shared<const geometry::StereoRig>(
      geometry::StereoRig::Ideal(cv::Size(640, 480), 700, 0.5, 320, 240));
  Result<std::unique_ptr<AravisStereoSource>> source = AravisStereoSource::Open(options, rig);
  ASSERT_TRUE(source.ok()) << source.error().message;
  AravisStereoSource& s = **source;
  EXPECT_EQ(s.Describe(), "aravis Aravis-Fake-GV01 + Aravis-Fake-GV02 640x480 30 fps");
  EXPECT_EQ(s.Rig(), rig);
  EXPECT_EQ(s.NominalFps(), 0);
  for (Side side : {Side::kLeft, Side::kRight}) {
    const CameraInfo info = s.camera_info(side);
    EXPECT_EQ(info.roi, cv::Rect(704, 784, 640, 480)) << SideName(side);
    EXPECT_NEAR(info.frame_rate_hz, 30, 0.01) << SideName(side);
    EXPECT_EQ(info.device.protocol, "GigEVision");
  }
  EXPECT_EQ(s.camera_info(Side::kLeft).device.address, "127.0.0.1");
  EXPECT_EQ(s.camera_info(Side::kRight).device.serial, "GV02");

  // The first pair, then 3 s of steady acquisition.
  Result<StereoFrame> first = s.Next();
  ASSERT_TRUE(first.ok()) << first.error().message;
  const uint64_t left_before = s.camera_stats(Side::kLeft).frames;
  const uint64_t right_before = s.camera_stats(Side::kRight).frames;
  const Acquisition run = Collect(s, 3.0, options.PairToleranceNs(), cv::Size(640, 480));
  const uint64_t left_frames = s.camera_stats(Side::kLeft).frames - left_before;
  const uint64_t right_frames = s.camera_stats(Side::kRight).frames - right_before;
  const double fps = run.fps();
  const SourceCounters c = s.Counters();
  std::cout << "[ measured ] " << run.formed << " pairs in " << run.seconds << " s = " << fps
            << " fps (" << run.delivered << " delivered and checked) from " << left_frames
            << " left and " << right_frames << " right frames; skew last " << c.last_skew_ns / 1e6
            << " ms, max |skew| " << c.max_abs_skew_ns / 1e6 << " ms, mean |skew| "
            << c.mean_abs_skew_ns / 1e6 << " ms; unpaired dropped " << c.unpaired_dropped
            << ", incomplete " << c.incomplete_dropped << "\n";
  EXPECT_EQ(run.errors, 0) << run.last_error;
  // Nearly every frame of the slower camera finds its partner. A frame whose camera process
  // was held up past half a period legitimately has none (the failing CI run paired 72 of
  // about 83), so the bar is three in four, not all.
  const uint64_t slower = std::min(left_frames, right_frames);
  EXPECT_GE(static_cast<double>(run.formed), 0.75 * static_cast<double>(slower))
      << run.formed << " pairs from " << slower << " frames of the slower camera";
  // A gross floor in time: the cameras run at 30 fps, and even starved they deliver more than
  // half of that; below it something else (a stalled stream, a lost camera) is wrong.
  EXPECT_GE(static_cast<double>(slower) / run.seconds, 15.0);
  EXPECT_GE(c.pairs, run.formed + 1);
  EXPECT_LE(std::llabs(c.last_skew_ns), options.PairToleranceNs());
  EXPECT_LE(c.max_abs_skew_ns, options.PairToleranceNs());
  EXPECT_GT(c.max_abs_skew_ns, 0) << "two processes never capture at the same nanosecond";
  EXPECT_GT(c.mean_abs_skew_ns, 0);
  EXPECT_LE(c.mean_abs_skew_ns, static_cast<double>(c.max_abs_skew_ns));
  // Aravis enlarges the socket buffer when the first frame comes, so on loopback (where a
  // frame arrives in one burst) the very first one may overflow the default buffer; on a loaded
  // machine (ctest -j2 on 2 cores) a receive thread kept off the CPU loses a frame now and then
  // (3 in one CI run). Loss at a steady rate is the packet-loss test's subject: here, at most
  // 5 % of the frames.
  EXPECT_LE(c.incomplete_dropped, 2u + static_cast<uint64_t>(0.05 * 2 * run.formed));
  EXPECT_EQ(c.reconnects, 0u);
}

TEST_F(AravisGigE, PacketLossOnOneCameraDropsAndCountsTheIncompleteFrames) {
  // 50 packets in 1000 lost on the right camera. The fake camera cannot resend, so a frame is
  // complete only when all its packets arrive: at 160x120 (about 17 packets of ~1.4 kB) that is
  // 0.95^17 = 42 % of them.
  ASSERT_NO_FATAL_FAILURE(StartCameras(50));
  AravisOptions options = Options();
  options.roi_width = 160;
  options.roi_height = 120;
  Result<std::unique_ptr<AravisStereoSource>> source = AravisStereoSource::Open(options, nullptr);
  ASSERT_TRUE(source.ok()) << source.error().message;
  AravisStereoSource& s = **source;
  const Acquisition run = Collect(s, 3.0, options.PairToleranceNs(), cv::Size(160, 120));
  const SourceCounters c = s.Counters();
  const CameraStats left = s.camera_stats(Side::kLeft);
  const CameraStats right = s.camera_stats(Side::kRight);
  std::cout << "[ measured ] " << run.formed << " pairs in " << run.seconds << " s = " << run.fps()
            << " fps (" << run.delivered
            << " delivered, all intact); right camera: " << right.frames << " complete frames, "
            << right.incomplete << " incomplete dropped, " << right.missing_packets
            << " packets missing, " << right.resent_packets
            << " resent; left camera: " << left.frames << " frames, " << left.incomplete
            << " incomplete; unpaired dropped " << c.unpaired_dropped << "\n";
  // Pairs still flow, every one intact (Collect checks each image), and the losses are counted.
  EXPECT_GE(run.fps(), 5.0);
  EXPECT_GT(right.incomplete, 10u);
  EXPECT_EQ(c.incomplete_dropped, left.incomplete + right.incomplete);
  EXPECT_LE(left.incomplete, 1u);  // at most its first frame (see the test above)
  // Left frames whose right partner was lost have nobody to pair with.
  EXPECT_GT(c.unpaired_dropped, 10u);
}

// Kills the left camera (a power cut), checks that Next() names it, keeps it down for
// `outage_s` more seconds, restarts it and measures how long pairs take to resume.
void ExpectRecoveryAfterOutage(FakeGvCamera& left, double outage_s) {
  const AravisOptions options = Options();
  Result<std::unique_ptr<AravisStereoSource>> source = AravisStereoSource::Open(options, nullptr);
  ASSERT_TRUE(source.ok()) << source.error().message;
  AravisStereoSource& s = **source;
  Result<StereoFrame> first = s.Next();
  ASSERT_TRUE(first.ok()) << first.error().message;
  // The rate before the outage, the reference for the rate after it (a ratio measured in the same
  // run: a busy machine slows both).
  const Acquisition before = Collect(s, 2.0, options.PairToleranceNs(), cv::Size(640, 480));
  ASSERT_EQ(before.errors, 0) << before.last_error;

  left.Kill();
  const auto killed = Clock::now();
  std::string lost_message;
  while (lost_message.empty() && SecondsSince(killed) < 10) {
    Result<StereoFrame> pair = s.Next();
    if (!pair.ok()) {
      EXPECT_THAT(pair, IsError(ErrorCode::kUnavailable));
      if (Contains(pair.error().message, "lost")) lost_message = pair.error().message;
    }
  }
  const double detect_s = SecondsSince(killed);
  ASSERT_FALSE(lost_message.empty()) << "no loss reported within 10 s";
  EXPECT_TRUE(Contains(lost_message, "camera Aravis-Fake-GV01 (left) lost")) << lost_message;

  // While it is down, every Next() says which camera is missing (and why reopening fails).
  std::string down_message;
  const auto down_since = Clock::now();
  do {
    Result<StereoFrame> down = s.Next();
    ASSERT_FALSE(down.ok()) << "a pair while the left camera is dead";
    EXPECT_THAT(down, IsError(ErrorCode::kUnavailable));
    EXPECT_TRUE(Contains(down.error().message, "camera Aravis-Fake-GV01 (left) lost"))
        << down.error().message;
    down_message = down.error().message;
  } while (SecondsSince(down_since) < outage_s);

  // The camera comes back: pairs resume within 5 s.
  ASSERT_NO_FATAL_FAILURE(left.Start());
  const auto restarted = Clock::now();
  std::optional<double> recovery_s;
  std::string errors;  // what Next() said meanwhile, for a failure's diagnosis
  while (!recovery_s && SecondsSince(restarted) < 10) {
    Result<StereoFrame> pair = s.Next();
    if (pair.ok()) {
      recovery_s = SecondsSince(restarted);
    } else {
      errors += "\n  at " + std::to_string(SecondsSince(restarted)) + " s: " + pair.error().message;
    }
  }
  ASSERT_TRUE(recovery_s) << "no pair within 10 s of the restart; Next() said:" << errors;
  std::cout << "[ measured ] loss reported " << detect_s << " s after the kill: \"" << lost_message
            << "\"; down " << SecondsSince(killed) - *recovery_s << " s, last report \""
            << down_message << "\"; pairs resumed " << *recovery_s << " s after the restart\n";
  EXPECT_LT(*recovery_s, 5.0) << "Next() said:" << errors;
  EXPECT_EQ(s.Counters().reconnects, 1u) << "Next() said:" << errors;

  // And they flow as before.
  const Acquisition run = Collect(s, 2.0, options.PairToleranceNs(), cv::Size(640, 480));
  std::cout << "[ measured ] before the outage: " << before.fps()
            << " fps; after recovery: " << run.fps() << " fps\n";
  EXPECT_EQ(run.errors, 0) << run.last_error;
  EXPECT_GE(run.fps(),
            0.7 * before.fps());  // slack for a busy machine; a failed recovery gives none
}

TEST_F(AravisGigE, ReportsALostCameraAndRecoversAfterItsRestart) {
  ASSERT_NO_FATAL_FAILURE(StartCameras());
  ExpectRecoveryAfterOutage(*left_, 0.0);
}

TEST_F(AravisGigE, RecoversAfterALongerOutage) {
  // Down for 3 s more: reopening has failed a few times (discovery finds nothing) when the
  // camera returns.
  ASSERT_NO_FATAL_FAILURE(StartCameras());
  ExpectRecoveryAfterOutage(*left_, 3.0);
}

TEST_F(AravisGigE, SoftwareTriggerPairsAtTheTriggerRate) {
  ASSERT_NO_FATAL_FAILURE(StartCameras());
  AravisOptions options = Options();
  options.trigger.mode = TriggerMode::kSoftware;
  options.frame_rate_hz = 10;
  Result<std::unique_ptr<AravisStereoSource>> source = AravisStereoSource::Open(options, nullptr);
  ASSERT_TRUE(source.ok()) << source.error().message;
  AravisStereoSource& s = **source;
  EXPECT_EQ(s.Describe(),
            "aravis Aravis-Fake-GV01 + Aravis-Fake-GV02 640x480 10 fps software trigger");
  Result<StereoFrame> first = s.Next();
  ASSERT_TRUE(first.ok()) << first.error().message;
  const Acquisition run = Collect(s, 2.0, options.PairToleranceNs(), cv::Size(640, 480));
  const double fps = run.fps();
  const SourceCounters c = s.Counters();
  std::cout << "[ measured ] software trigger: " << fps << " fps, max |skew| "
            << c.max_abs_skew_ns / 1e6 << " ms\n";
  EXPECT_EQ(run.errors, 0) << run.last_error;
  // The host's 10 Hz, not the fake's own 25 Hz trigger poll nor the 30 fps of free run. Below
  // 10 only by what a loaded machine loses (a trigger thread or camera process held up).
  EXPECT_LE(fps, 11.5);
  EXPECT_GE(fps, 6.0);
  EXPECT_LE(c.max_abs_skew_ns, options.PairToleranceNs());
}

TEST_F(AravisGigE, AnIdleHardwareTriggerIsNoLoss) {
  // Nothing pulses Line0: no frames, but the cameras answer, so they are not reopened.
  ASSERT_NO_FATAL_FAILURE(StartCameras());
  AravisOptions options = Options();
  options.trigger.mode = TriggerMode::kHardware;
  options.trigger.line = "Line0";
  options.timeout = milliseconds(500);
  Result<std::unique_ptr<AravisStereoSource>> source = AravisStereoSource::Open(options, nullptr);
  ASSERT_TRUE(source.ok()) << source.error().message;
  AravisStereoSource& s = **source;
  EXPECT_EQ(s.Describe(),
            "aravis Aravis-Fake-GV01 + Aravis-Fake-GV02 640x480 30 fps hardware "
            "trigger on Line0");
  // Past the loss time (max(0.5 s, 5 frame periods)) several times over.
  for (int i = 0; i < 4; ++i) {
    Result<StereoFrame> pair = s.Next();
    ASSERT_FALSE(pair.ok());
    EXPECT_THAT(pair, IsError(ErrorCode::kUnavailable));
    EXPECT_EQ(pair.error().message,
              "no pair from Aravis-Fake-GV01/Aravis-Fake-GV02 for 0.5 s (left: 0 frames, right: "
              "0 frames)");
  }
  EXPECT_EQ(s.Counters().reconnects, 0u);
  EXPECT_EQ(s.camera_stats(Side::kLeft).frames, 0u);
}

TEST_F(AravisGigE, AnUnknownIdNamesItAndListsTheCamerasPresent) {
  ASSERT_NO_FATAL_FAILURE(StartCameras());
  AravisOptions options = Options();
  options.right_id = "Aravis-Fake-GV09";
  Result<std::unique_ptr<AravisStereoSource>> source = AravisStereoSource::Open(options, nullptr);
  ASSERT_FALSE(source.ok());
  EXPECT_THAT(source, IsError(ErrorCode::kNotFound));
  const std::string& m = source.error().message;
  EXPECT_TRUE(Contains(m, "right: camera 'Aravis-Fake-GV09' not found")) << m;
  EXPECT_TRUE(Contains(m, "Aravis-Fake-GV01 (serial GV01, 127.0.0.1)")) << m;
  EXPECT_TRUE(Contains(m, "Aravis-Fake-GV02 (serial GV02, 127.0.0.2)")) << m;
}

TEST_F(AravisGigE, RefusesOptionsTheCamerasCannotTake) {
  ASSERT_NO_FATAL_FAILURE(StartCameras());
  AravisOptions large = Options();
  large.roi_width = 4096;
  Result<std::unique_ptr<AravisStereoSource>> source = AravisStereoSource::Open(large, nullptr);
  ASSERT_FALSE(source.ok());
  EXPECT_THAT(source, IsError(ErrorCode::kInvalidArgument));
  EXPECT_EQ(source.error().message,
            "left: camera Aravis-Fake-GV01: the region of interest 4096x480 is larger than its "
            "sensor (2048x2048)");

  AravisOptions rgb = Options();
  rgb.pixel_format = "RGB8";
  source = AravisStereoSource::Open(rgb, nullptr);
  ASSERT_FALSE(source.ok());
  EXPECT_THAT(source, IsError(ErrorCode::kInvalidArgument));
  EXPECT_TRUE(Contains(source.error().message, "pixel_format: RGB8 is not supported"))
      << source.error().message;

  AravisOptions short_exposure = Options();
  short_exposure.exposure_us = 5;
  source = AravisStereoSource::Open(short_exposure, nullptr);
  ASSERT_FALSE(source.ok());
  EXPECT_THAT(source, IsError(ErrorCode::kInvalidArgument));
  EXPECT_EQ(source.error().message,
            "left: camera Aravis-Fake-GV01: exposure_us 5 is outside its range 10..10000000 us");

  auto rig = std::make_shared<const geometry::StereoRig>(
      geometry::StereoRig::Ideal(cv::Size(1280, 960), 700, 0.5, 640, 480));
  source = AravisStereoSource::Open(Options(), rig);
  ASSERT_FALSE(source.ok());
  EXPECT_EQ(source.error().message,
            "the calibration's image size 1280x960 differs from the region of interest 640x480");
}

}  // namespace
}  // namespace stevi::drivers
