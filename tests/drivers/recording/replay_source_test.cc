#include "drivers/recording/replay_source.h"

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "core/geometry/calibration_io.h"
#include "drivers/recording/recorder.h"
#include "drivers/synthetic/synthetic_source.h"
#include "tests/drivers/recording/scaled_synthetic.h"
#include "tests/testing/data.h"
#include "tests/testing/image_match.h"
#include "tests/testing/status_matchers.h"

using stevi::testing::IsError;

namespace stevi::drivers {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

using testing::ImagesIdentical;

// The replayed rig must be the recorded one, down to the bit: results depend on every number.
::testing::AssertionResult SameRig(const geometry::StereoRig& expected,
                                   const geometry::StereoRig& actual) {
  if (RigsIdentical(expected, actual)) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure()
         << "rigs differ: f " << expected.f_px() << " vs " << actual.f_px() << ", B "
         << expected.baseline_m() << " vs " << actual.baseline_m() << ", c (" << expected.cx()
         << ", " << expected.cy() << ") vs (" << actual.cx() << ", " << actual.cy() << "), size "
         << expected.image_size() << " vs " << actual.image_size() << ", remap "
         << expected.needs_remap() << " vs " << actual.needs_remap() << ", id '"
         << expected.calibration_id() << "' vs '" << actual.calibration_id() << "'";
}

SyntheticOptions SmallSynthetic(int width = 64, int height = 48) {
  return fixtures::ScaledSynthetic(width, height);
}

geo::VehicleState State(int k) {
  geo::VehicleState s;
  s.t_ns = 1'700'000'000'000'000'000 + k * 50'000'000;
  s.lat_deg = 43.7 + 1e-5 * k;
  s.lon_deg = 10.4;
  s.alt_m = 100 + k;
  s.yaw_deg = 90;
  s.velocity_ned_mps = Eigen::Vector3d(0, 5, 0);
  return s;
}

std::unique_ptr<Recorder> StartOrDie(const std::string& dir, const StereoSource& source,
                                     int queue_frames = 64) {
  RecorderOptions options;
  options.queue_frames = queue_frames;
  RecordingInfo info;
  info.source = source.Describe();
  info.rig = source.Rig();
  Result<std::unique_ptr<Recorder>> r = Recorder::Start(dir, options, std::move(info));
  EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().message);
  return r.ok() ? std::move(r.value()) : nullptr;
}

std::unique_ptr<ReplaySource> OpenOrDie(const std::string& dir, double rate, bool loop = false) {
  ReplayOptions options;
  options.rate = rate;
  options.loop = loop;
  Result<std::unique_ptr<ReplaySource>> r = ReplaySource::Open(dir, options);
  EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().message);
  return r.ok() ? std::move(r.value()) : nullptr;
}

// Records `count` frames whose capture times are `period_ns` apart (starting at t0_ns).
std::vector<StereoFrame> RecordTimed(const std::string& dir, int count, int64_t period_ns,
                                     int64_t t0_ns = 5'000'000'000) {
  SyntheticSource source(SmallSynthetic());
  std::unique_ptr<Recorder> recorder = StartOrDie(dir, source);
  std::vector<StereoFrame> frames;
  if (!recorder) return frames;
  for (int k = 0; k < count; ++k) {
    StereoFrame frame = *source.Next();
    frame.t_ns = t0_ns + k * period_ns;
    frame.unix_time_ns = 1'700'000'000'000'000'000 + k * period_ns;
    frame.pair_skew_ns = 250 * k - 500;
    EXPECT_TRUE(recorder->AddFrame(frame).ok());
    frames.push_back(frame);
  }
  EXPECT_TRUE(recorder->Stop().ok());
  return frames;
}

// ---- Options and errors -------------------------------------------------------------------------

TEST(ReplayOptions, ValidateListsEveryProblem) {
  ReplayOptions o;
  EXPECT_TRUE(o.Validate().empty());
  o.rate = 0;
  EXPECT_TRUE(o.Validate().empty());
  o.rate = -1;
  ASSERT_EQ(o.Validate().size(), 1u);
  EXPECT_EQ(o.Validate()[0], "rate: must be 0 (max) or in (0, 1000] (got -1)");
  o.rate = std::nan("");
  EXPECT_EQ(o.Validate().size(), 1u);

  Result<std::unique_ptr<ReplaySource>> r = ReplaySource::Open("/nonexistent", o);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r, IsError(ErrorCode::kInvalidArgument)) << "options are checked first";
}

TEST(ReplaySource, OpenNamesTheMissingOrBadFile) {
  const std::string root = testing::MakeTempDir("stevi-replay-errors");
  Result<std::unique_ptr<ReplaySource>> r = ReplaySource::Open(root + "/missing", ReplayOptions{});
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r, IsError(ErrorCode::kNotFound));
  EXPECT_EQ(r.error().message, "recording " + root + "/missing: no such directory");

  r = ReplaySource::Open(root, ReplayOptions{});
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r, IsError(ErrorCode::kNotFound));
  EXPECT_EQ(r.error().message,
            root + "/manifest.json: not found (" + root + " is not a recording directory)");

  const std::string dir = root + "/rec";
  RecordTimed(dir, 2, 100'000'000);
  fs::remove(dir + "/records.bin");
  r = ReplaySource::Open(dir, ReplayOptions{});
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r, IsError(ErrorCode::kNotFound));
  EXPECT_EQ(r.error().message, dir + "/records.bin: not found");
}

// ---- Content ------------------------------------------------------------------------------------

TEST(ReplaySource, ReplaysFramesRigStatesAndCalibrationExactly) {
  const std::string dir = testing::MakeTempDir("stevi-replay-exact") + "/rec";
  SyntheticSource source(SmallSynthetic());
  std::unique_ptr<Recorder> recorder = StartOrDie(dir, source);
  ASSERT_TRUE(recorder);
  const geometry::StereoCalibration changed_calibration =
      geometry::IdealCalibration(cv::Size(64, 48), 71.25, 0.55, 31.5, 23.5);
  Result<std::string> changed_yaml = geometry::CalibrationYamlText(changed_calibration);
  ASSERT_TRUE(changed_yaml.ok());
  std::vector<StereoFrame> frames;
  std::vector<geo::VehicleState> states;
  for (int k = 0; k < 10; ++k) {
    states.push_back(State(k));
    ASSERT_TRUE(recorder->AddVehicleState(states.back()).ok());
    if (k == 6) {
      ASSERT_TRUE(recorder->SetCalibration("cal-000009", *changed_yaml).ok());
    }
    StereoFrame frame = *source.Next();
    frame.unix_time_ns = 1'700'000'000'000'000'000 + k * 100'000'000;
    frame.pair_skew_ns = -1234 + k;
    ASSERT_TRUE(recorder->AddFrame(frame).ok());
    frames.push_back(frame);
  }
  ASSERT_TRUE(recorder->Stop().ok());

  std::unique_ptr<ReplaySource> replay = OpenOrDie(dir, 0);
  ASSERT_TRUE(replay);
  EXPECT_EQ(replay->Describe(), "replay " + dir + " (10 frames, rate max)");
  EXPECT_EQ(replay->NominalFps(), 0);
  EXPECT_EQ(replay->frame_count(), 10u);
  EXPECT_TRUE(replay->notes().empty());
  EXPECT_EQ(replay->vehicle_states(), states);
  EXPECT_EQ(replay->calibration_id(), "synthetic");
  ASSERT_EQ(replay->calibration_changes().size(), 1u);
  EXPECT_EQ(replay->calibration_changes()[0].frames_before, 6u);
  EXPECT_EQ(replay->calibration_changes()[0].change.calibration_id, "cal-000009");
  // The recorded rig, bit for bit: f, B, cx, cy, image size, no remap (rectified frames).
  const std::shared_ptr<const geometry::StereoRig> original = source.Rig();
  EXPECT_TRUE(SameRig(*original, *replay->Rig()));
  EXPECT_EQ(replay->Rig()->f_px(), original->f_px());
  EXPECT_EQ(replay->Rig()->baseline_m(), original->baseline_m());
  EXPECT_EQ(replay->Rig()->cx(), original->cx());
  EXPECT_EQ(replay->Rig()->cy(), original->cy());
  EXPECT_EQ(replay->Rig()->image_size(), original->image_size());
  EXPECT_FALSE(replay->Rig()->needs_remap());

  Result<geometry::StereoRig> changed_rig =
      geometry::StereoRig::FromCalibration(changed_calibration, "cal-000009");
  ASSERT_TRUE(changed_rig.ok());
  for (int k = 0; k < 10; ++k) {
    Result<StereoFrame> frame = replay->Next();
    ASSERT_TRUE(frame.ok()) << frame.error().message;
    EXPECT_EQ(frame->index, frames[k].index);
    EXPECT_EQ(frame->t_ns, frames[k].t_ns);
    EXPECT_EQ(frame->unix_time_ns, frames[k].unix_time_ns);
    EXPECT_EQ(frame->pair_skew_ns, frames[k].pair_skew_ns);
    EXPECT_TRUE(frame->rectified);
    EXPECT_TRUE(ImagesIdentical(frames[k].left, frame->left)) << "frame " << k;
    EXPECT_TRUE(ImagesIdentical(frames[k].right, frame->right)) << "frame " << k;
    // From frame 6 on the frames follow the changed calibration.
    if (k < 6) {
      EXPECT_EQ(replay->calibration_id(), "synthetic") << "frame " << k;
      EXPECT_TRUE(SameRig(*original, *replay->Rig())) << "frame " << k;
    } else {
      EXPECT_EQ(replay->calibration_id(), "cal-000009") << "frame " << k;
      EXPECT_TRUE(SameRig(*changed_rig, *replay->Rig())) << "frame " << k;
    }
  }
  const SourceCounters counters = replay->Counters();
  EXPECT_EQ(counters.pairs, 10u);
  EXPECT_EQ(counters.last_skew_ns, -1234 + 9);
  EXPECT_EQ(counters.max_abs_skew_ns, 1234);

  Result<StereoFrame> end = replay->Next();
  ASSERT_FALSE(end.ok());
  EXPECT_THAT(end, IsError(ErrorCode::kOutOfRange));
  EXPECT_EQ(end.error().message, "end of the recording " + dir + " after 10 frames");
}

TEST(ReplaySource, CalibratedRigWithRemapReplaysIdentically) {
  geometry::StereoCalibration c;
  c.image_size = cv::Size(64, 48);
  c.M1 = cv::Matx33d(80.123, 0, 31.7, 0, 80.456, 24.2, 0, 0, 1);
  c.M2 = cv::Matx33d(79.987, 0, 32.4, 0, 80.012, 23.9, 0, 0, 1);
  c.D1 = (cv::Mat_<double>(1, 5) << -0.05, 0.01, 1e-4, -2e-4, 0);
  c.D2 = (cv::Mat_<double>(1, 5) << -0.04, 0.02, -1e-4, 1e-4, 0);
  c.R = cv::Matx33d::eye();
  c.T = cv::Vec3d(-0.4, 0.002, 0.001);
  Result<geometry::StereoRig> rig = geometry::StereoRig::FromCalibration(c, "cal-000003");
  ASSERT_TRUE(rig.ok()) << rig.error().message;
  ASSERT_TRUE(rig->needs_remap());
  const auto shared = std::make_shared<const geometry::StereoRig>(std::move(rig.value()));

  const std::string dir = testing::MakeTempDir("stevi-replay-raw") + "/rec";
  RecordingInfo info;
  info.source = "test camera pair";
  info.rig = shared;
  Result<std::unique_ptr<Recorder>> recorder = Recorder::Start(dir, RecorderOptions{}, info);
  ASSERT_TRUE(recorder.ok()) << recorder.error().message;
  StereoFrame raw;
  raw.left = cv::Mat1b(48, 64, uchar{90});
  raw.right = cv::Mat1b(48, 64, uchar{160});
  raw.rectified = false;
  ASSERT_TRUE((*recorder)->AddFrame(raw).ok());
  ASSERT_TRUE((*recorder)->Stop().ok());

  std::unique_ptr<ReplaySource> replay = OpenOrDie(dir, 0);
  ASSERT_TRUE(replay);
  EXPECT_TRUE(SameRig(*shared, *replay->Rig()));
  EXPECT_EQ(replay->calibration_id(), "cal-000003");
  Result<StereoFrame> frame = replay->Next();
  ASSERT_TRUE(frame.ok()) << frame.error().message;
  EXPECT_FALSE(frame->rectified);
  cv::Mat a_left, a_right, b_left, b_right;
  ASSERT_TRUE(shared->Rectify(raw.left, raw.right, a_left, a_right).ok());
  ASSERT_TRUE(replay->Rig()->Rectify(frame->left, frame->right, b_left, b_right).ok());
  EXPECT_TRUE(ImagesIdentical(a_left, b_left));
  EXPECT_TRUE(ImagesIdentical(a_right, b_right));
}

TEST(ReplaySource, LoopsOverTheRecording) {
  const std::string dir = testing::MakeTempDir("stevi-replay-loop") + "/rec";
  const std::vector<StereoFrame> frames = RecordTimed(dir, 4, 100'000'000);
  std::unique_ptr<ReplaySource> replay = OpenOrDie(dir, 0, /*loop=*/true);
  ASSERT_TRUE(replay);
  EXPECT_EQ(replay->Describe(), "replay " + dir + " (4 frames, rate max, loop)");
  for (int k = 0; k < 10; ++k) {
    Result<StereoFrame> frame = replay->Next();
    ASSERT_TRUE(frame.ok()) << frame.error().message;
    EXPECT_EQ(frame->index, frames[k % 4].index) << "frame " << k;
    EXPECT_EQ(frame->t_ns, frames[k % 4].t_ns) << "each lap repeats the recorded times";
    EXPECT_TRUE(ImagesIdentical(frames[k % 4].left, frame->left));
  }
  EXPECT_EQ(replay->laps(), 2);
  EXPECT_EQ(replay->Counters().pairs, 10u);
}

TEST(ReplaySource, TruncatedRecordingReplaysItsCompletePrefix) {
  const std::string dir = testing::MakeTempDir("stevi-replay-cut") + "/rec";
  const std::vector<StereoFrame> frames = RecordTimed(dir, 5, 100'000'000);
  const std::string records = dir + "/records.bin";
  const uintmax_t size = fs::file_size(records);
  fs::resize_file(records, size - 10);  // inside the last frame

  std::unique_ptr<ReplaySource> replay = OpenOrDie(dir, 0);
  ASSERT_TRUE(replay);
  EXPECT_EQ(replay->frame_count(), 4u);
  ASSERT_EQ(replay->notes().size(), 1u);
  EXPECT_EQ(replay->notes()[0].rfind(records + ": truncated record after 4 frames at byte ", 0), 0u)
      << replay->notes()[0];
  for (int k = 0; k < 4; ++k) {
    Result<StereoFrame> frame = replay->Next();
    ASSERT_TRUE(frame.ok()) << frame.error().message;
    EXPECT_TRUE(ImagesIdentical(frames[k].left, frame->left));
    EXPECT_TRUE(ImagesIdentical(frames[k].right, frame->right));
  }
  Result<StereoFrame> end = replay->Next();
  ASSERT_FALSE(end.ok());
  EXPECT_THAT(end, IsError(ErrorCode::kOutOfRange));
  EXPECT_EQ(end.error().message,
            "end of the recording " + dir + " after 4 frames (" + replay->notes()[0] + ")");
}

// ---- Pacing -------------------------------------------------------------------------------------

// Plays every frame; when each came out, in seconds after the call that returned the first
// (`after_first`) and after that call began (`after_call`: the source's pacing starts within
// that call, so no frame may come out before its due time on this clock).
struct PlayedTimes {
  std::vector<double> after_first, after_call;
};
PlayedTimes PlayTimes(ReplaySource& replay, size_t count) {
  PlayedTimes times;
  const Clock::time_point called = Clock::now();
  Clock::time_point first;
  for (size_t k = 0; k < count; ++k) {
    Result<StereoFrame> frame = replay.Next();
    const Clock::time_point now = Clock::now();
    EXPECT_TRUE(frame.ok()) << frame.error().message;
    if (k == 0) first = now;
    times.after_first.push_back(std::chrono::duration<double>(now - first).count());
    times.after_call.push_back(std::chrono::duration<double>(now - called).count());
  }
  return times;
}

// Frame k must come out at (t_k - t_0) / rate after the first: never early (the pacing clock
// starts inside the first call: a thread descheduled between that and the call's return must
// not make later frames look early), and late by at most a generous scheduling margin.
void ExpectPaced(double rate) {
  const std::string dir = testing::MakeTempDir("stevi-replay-pace") + "/rec";
  constexpr int64_t kPeriodNs = 80'000'000;  // 12.5 frames/s as recorded
  constexpr int kFrames = 11;
  const std::vector<StereoFrame> frames = RecordTimed(dir, kFrames, kPeriodNs);
  std::unique_ptr<ReplaySource> replay = OpenOrDie(dir, rate);
  ASSERT_TRUE(replay);
  const PlayedTimes times = PlayTimes(*replay, kFrames);
  for (int k = 0; k < kFrames; ++k) {
    const double due = static_cast<double>(frames[k].t_ns - frames[0].t_ns) * 1e-9 / rate;
    EXPECT_GE(times.after_call[k], due - 0.0005) << "frame " << k << " early at rate " << rate;
    EXPECT_LE(times.after_first[k], due + 0.15) << "frame " << k << " late at rate " << rate;
  }
  const double span = static_cast<double>(frames.back().t_ns - frames[0].t_ns) * 1e-9 / rate;
  std::cout << "rate " << rate << ": last frame after " << times.after_first.back() << " s (due "
            << span << " s)\n";
}

TEST(ReplaySource, PacesAtTheRecordedRate) { ExpectPaced(1.0); }

TEST(ReplaySource, PacesFourTimesFaster) { ExpectPaced(4.0); }

TEST(ReplaySource, RateZeroDoesNotWait) {
  const std::string dir = testing::MakeTempDir("stevi-replay-max") + "/rec";
  constexpr int64_t kPeriodNs = 200'000'000;
  const std::vector<StereoFrame> frames = RecordTimed(dir, 11, kPeriodNs);  // 2 s recorded
  std::unique_ptr<ReplaySource> replay = OpenOrDie(dir, 0);
  ASSERT_TRUE(replay);
  const std::vector<double> times = PlayTimes(*replay, frames.size()).after_first;
  std::cout << "rate 0: 11 frames (2 s recorded) in " << times.back() << " s\n";
  EXPECT_LT(times.back(), 0.25 * 2.0) << "rate 0 must be much faster than the recording";
}

// Recorded gaps are honoured up to 10 s, then shortened: a bogus time cannot stall the replay.
TEST(ReplaySource, LongGapsAreShortened) {
  const std::string dir = testing::MakeTempDir("stevi-replay-gap") + "/rec";
  SyntheticSource source(SmallSynthetic());
  std::unique_ptr<Recorder> recorder = StartOrDie(dir, source);
  ASSERT_TRUE(recorder);
  for (int64_t t : {int64_t{0}, int64_t{3'600'000'000'000}}) {  // one hour apart
    StereoFrame frame = *source.Next();
    frame.t_ns = t;
    ASSERT_TRUE(recorder->AddFrame(frame).ok());
  }
  ASSERT_TRUE(recorder->Stop().ok());
  std::unique_ptr<ReplaySource> replay = OpenOrDie(dir, 1000.0);  // 10 s gap -> 10 ms
  ASSERT_TRUE(replay);
  // Never early, measured from the first call (the pacing clock starts inside it: a thread
  // descheduled before that call returns must not make the second frame look early); late by at
  // most a generous scheduling margin, measured from the first frame.
  const PlayedTimes times = PlayTimes(*replay, 2);
  EXPECT_GE(times.after_call[1], 0.010 - 0.0005);
  EXPECT_LE(times.after_first[1], 0.2);
}

}  // namespace
}  // namespace stevi::drivers
