#include "drivers/recording/recorder.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

#include <google/protobuf/io/zero_copy_stream_impl.h>
#include <google/protobuf/util/delimited_message_util.h>
#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "core/geometry/calibration_io.h"
#include "drivers/recording/recording_reader.h"
#include "drivers/recording/replay_source.h"
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

// ---- Helpers ------------------------------------------------------------------------------------

using testing::ImagesIdentical;

SyntheticOptions SmallSynthetic(int width = 160, int height = 120) {
  return fixtures::ScaledSynthetic(width, height);
}

// A colour pair from a grey one: three different channels, so that a swapped or dropped channel
// shows.
StereoFrame ToColour(StereoFrame frame) {
  for (cv::Mat* image : {&frame.left, &frame.right}) {
    cv::Mat inverted = 255 - *image;
    cv::Mat half = *image / 2;
    cv::Mat bgr;
    cv::merge(std::vector<cv::Mat>{*image, inverted, half}, bgr);
    *image = bgr;
  }
  return frame;
}

// A frame with every field set to something recognisable.
StereoFrame Stamped(StereoFrame frame, int64_t k) {
  frame.unix_time_ns = 1'700'000'000'000'000'000 + k * 100'000'000 + 17;
  frame.pair_skew_ns = (k % 2 == 0 ? 1 : -1) * (1000 + 37 * k);
  return frame;
}

geo::VehicleState State(int k) {
  geo::VehicleState s;
  s.t_ns = 1'700'000'000'000'000'000 + k * 20'000'000;
  s.lat_deg = 43.7167 + 1e-6 * k;
  s.lon_deg = 10.3833 - 1e-6 * k;
  s.alt_m = 120.25 + 0.1 * k;
  s.roll_deg = 1.5 - 0.01 * k;
  s.pitch_deg = -2.25;
  s.yaw_deg = 271.125 + k;
  s.velocity_ned_mps = Eigen::Vector3d(3.0 + k, -0.5, 0.125);
  s.sigma = geo::PoseSigma{0.5, 0.75, 0.2, 0.4};
  return s;
}

RecordingInfo InfoFor(const StereoSource& source, std::string calibration_id = "") {
  RecordingInfo info;
  info.source = source.Describe();
  info.rig = source.Rig();
  info.calibration_id = std::move(calibration_id);
  return info;
}

std::unique_ptr<Recorder> StartOrDie(const std::string& dir, RecorderOptions options,
                                     RecordingInfo info) {
  Result<std::unique_ptr<Recorder>> recorder = Recorder::Start(dir, options, std::move(info));
  EXPECT_TRUE(recorder.ok()) << (recorder.ok() ? "" : recorder.error().message);
  if (!recorder.ok()) return nullptr;
  return std::move(recorder.value());
}

std::unique_ptr<RecordingReader> OpenOrDie(const std::string& dir) {
  Result<std::unique_ptr<RecordingReader>> reader = RecordingReader::Open(dir);
  EXPECT_TRUE(reader.ok()) << (reader.ok() ? "" : reader.error().message);
  if (!reader.ok()) return nullptr;
  return std::move(reader.value());
}

std::vector<RecordingRecord> ReadAll(RecordingReader& reader, bool decode = true) {
  std::vector<RecordingRecord> records;
  // Bounded by the file: each call consumes at least one byte or ends.
  while (std::optional<RecordingRecord> r = reader.Next(decode)) records.push_back(std::move(*r));
  return records;
}

std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

void WriteFile(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(out.good()) << path;
}

bool Contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// Expects the frames to match what was recorded, field by field and pixel by pixel.
void ExpectSameFrame(const StereoFrame& expected, const StereoFrame& actual) {
  EXPECT_EQ(actual.index, expected.index);
  EXPECT_EQ(actual.t_ns, expected.t_ns);
  EXPECT_EQ(actual.unix_time_ns, expected.unix_time_ns);
  EXPECT_EQ(actual.pair_skew_ns, expected.pair_skew_ns);
  EXPECT_EQ(actual.rectified, expected.rectified);
  EXPECT_TRUE(ImagesIdentical(expected.left, actual.left)) << "left of frame " << expected.index;
  EXPECT_TRUE(ImagesIdentical(expected.right, actual.right)) << "right of frame " << expected.index;
}

// A small recording of `frames` frames with a vehicle state before each, returned with the frames.
std::vector<StereoFrame> RecordSmall(const std::string& dir, int frames, int width = 64,
                                     int height = 48) {
  SyntheticSource source(SmallSynthetic(width, height));
  RecorderOptions options;
  options.queue_frames = frames;  // room for all: nothing is dropped
  std::unique_ptr<Recorder> recorder = StartOrDie(dir, options, InfoFor(source));
  std::vector<StereoFrame> recorded;
  if (!recorder) return recorded;
  for (int k = 0; k < frames; ++k) {
    EXPECT_TRUE(recorder->AddVehicleState(State(k)).ok());
    StereoFrame frame = Stamped(*source.Next(), k);
    EXPECT_TRUE(recorder->AddFrame(frame).ok());
    recorded.push_back(frame);
  }
  EXPECT_TRUE(recorder->Stop("done").ok());
  return recorded;
}

// ---- Options ------------------------------------------------------------------------------------

TEST(RecorderOptions, ValidateListsEveryProblem) {
  RecorderOptions o;
  EXPECT_TRUE(o.Validate().empty());
  o.max_bytes = 0;
  o.queue_frames = 0;
  o.png_compression = 10;
  const std::vector<std::string> problems = o.Validate();
  ASSERT_EQ(problems.size(), 3u);
  EXPECT_EQ(problems[0], "max_bytes: must be >= 1048576 bytes (got 0)");
  EXPECT_EQ(problems[1], "queue_frames: must be in [1, 1024] frames (got 0)");
  EXPECT_EQ(problems[2], "png_compression: must be in [0, 9] (got 10)");
}

TEST(Recorder, StartRefusesBadArguments) {
  const std::string dir = testing::MakeTempDir("stevi-rec-args");
  RecorderOptions bad;
  bad.png_compression = -1;
  Result<std::unique_ptr<Recorder>> r = Recorder::Start(dir + "/rec", bad, RecordingInfo{});
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r, IsError(ErrorCode::kInvalidArgument));
  EXPECT_TRUE(Contains(r.error().message, "options.png_compression: must be in [0, 9] (got -1)"))
      << r.error().message;
  EXPECT_TRUE(Contains(r.error().message, "info.rig: missing")) << r.error().message;
  EXPECT_FALSE(fs::exists(dir + "/rec")) << "nothing is created for invalid arguments";

  // A path that is a file.
  WriteFile(dir + "/file", "x");
  SyntheticSource source(SmallSynthetic());
  r = Recorder::Start(dir + "/file", RecorderOptions{}, InfoFor(source));
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r, IsError(ErrorCode::kInvalidArgument));
  EXPECT_TRUE(Contains(r.error().message, "is not a directory")) << r.error().message;
}

TEST(Recorder, RefusesADirectoryThatHoldsARecording) {
  const std::string dir = testing::MakeTempDir("stevi-rec-twice") + "/a/b";  // created
  SyntheticSource source(SmallSynthetic());
  std::unique_ptr<Recorder> first = StartOrDie(dir, RecorderOptions{}, InfoFor(source));
  ASSERT_TRUE(first);
  ASSERT_TRUE(first->Stop().ok());
  const std::string manifest_before = ReadFile(dir + "/manifest.json");

  Result<std::unique_ptr<Recorder>> second =
      Recorder::Start(dir, RecorderOptions{}, InfoFor(source));
  ASSERT_FALSE(second.ok());
  EXPECT_THAT(second, IsError(ErrorCode::kAlreadyExists));
  EXPECT_TRUE(Contains(second.error().message, "already holds a recording"))
      << second.error().message;
  EXPECT_EQ(ReadFile(dir + "/manifest.json"), manifest_before) << "the recording is untouched";

  // A crash before the manifest was rewritten still leaves records.bin: refused too.
  const std::string other = testing::MakeTempDir("stevi-rec-records-only");
  WriteFile(other + "/records.bin", "");
  second = Recorder::Start(other, RecorderOptions{}, InfoFor(source));
  ASSERT_FALSE(second.ok());
  EXPECT_THAT(second, IsError(ErrorCode::kAlreadyExists));
  EXPECT_TRUE(Contains(second.error().message, "records.bin exists")) << second.error().message;
}

// ---- Round trips --------------------------------------------------------------------------------

TEST(Recorder, RoundTripOfGreyAndColourFramesIsExact) {
  for (const bool colour : {false, true}) {
    SCOPED_TRACE(colour ? "BGR" : "grey");
    const std::string dir = testing::MakeTempDir("stevi-rec-roundtrip") + "/rec";
    SyntheticSource source(SmallSynthetic());
    RecorderOptions options;
    options.queue_frames = 64;
    std::unique_ptr<Recorder> recorder = StartOrDie(dir, options, InfoFor(source, "cal-000007"));
    ASSERT_TRUE(recorder);
    EXPECT_TRUE(recorder->Status().recording);

    std::vector<StereoFrame> frames;
    std::vector<geo::VehicleState> states;
    for (int k = 0; k < 12; ++k) {
      states.push_back(State(2 * k));
      states.push_back(State(2 * k + 1));
      ASSERT_TRUE(recorder->AddVehicleState(states[states.size() - 2]).ok());
      StereoFrame frame = Stamped(*source.Next(), k);
      if (colour) frame = ToColour(frame);
      ASSERT_TRUE(recorder->AddFrame(frame).ok());
      StereoFrame kept = frame;
      kept.left = frame.left.clone();
      kept.right = frame.right.clone();
      frames.push_back(kept);
      // The recorder copied the images: scribbling on ours afterwards changes nothing.
      frame.left.setTo(0);
      ASSERT_TRUE(recorder->AddVehicleState(states.back()).ok());
    }
    ASSERT_TRUE(recorder->Stop("operator").ok());
    const RecorderStatus status = recorder->Status();
    EXPECT_FALSE(status.recording);
    EXPECT_EQ(status.dir, dir);
    EXPECT_EQ(status.frames_written, 12u);
    EXPECT_EQ(status.frames_dropped, 0u);
    EXPECT_EQ(status.vehicle_states_written, 24u);
    EXPECT_EQ(status.stop_reason, "operator");
    EXPECT_EQ(status.error, "");
    EXPECT_EQ(status.bytes_written, fs::file_size(dir + "/records.bin"));

    std::unique_ptr<RecordingReader> reader = OpenOrDie(dir);
    ASSERT_TRUE(reader);
    const v1::RecordingManifest& m = reader->manifest();
    EXPECT_EQ(m.format_version(), 1u);
    EXPECT_EQ(m.state(), v1::RECORDING_STATE_STOPPED);
    EXPECT_EQ(m.stop_reason(), "operator");
    EXPECT_FALSE(m.failed());
    EXPECT_EQ(m.source(), source.Describe());
    EXPECT_EQ(m.calibration_id(), "cal-000007");
    EXPECT_EQ(m.frames_written(), 12u);
    EXPECT_EQ(m.vehicle_states_written(), 24u);
    EXPECT_EQ(m.bytes_written(), status.bytes_written);
    EXPECT_EQ(m.first_t_ns(), frames.front().t_ns);
    EXPECT_EQ(m.last_t_ns(), frames.back().t_ns);
    EXPECT_GT(m.created_unix_ns(), 0);
    EXPECT_GE(m.stopped_unix_ns(), m.created_unix_ns());
    EXPECT_TRUE(RigsIdentical(*reader->rig(), *source.Rig()));

    // Records come back in the order they were added.
    const std::vector<RecordingRecord> records = ReadAll(*reader);
    EXPECT_EQ(reader->end_note(), "");
    ASSERT_EQ(records.size(), 36u);
    size_t frame_k = 0, state_k = 0;
    for (size_t i = 0; i < records.size(); ++i) {
      const RecordingRecord& r = records[i];
      const auto expected_kind =
          i % 3 == 1 ? RecordingRecord::Kind::kFrame : RecordingRecord::Kind::kVehicleState;
      ASSERT_EQ(r.kind, expected_kind) << "record " << i;
      if (r.kind == RecordingRecord::Kind::kFrame) {
        ExpectSameFrame(frames[frame_k++], r.frame);
      } else {
        EXPECT_EQ(r.vehicle_state, states[state_k++]) << "record " << i;
      }
    }
    EXPECT_EQ(reader->frames_read(), 12u);
  }
}

TEST(RecordedRig, IdealAndCalibratedRigsRebuildBitForBit) {
  // The synthetic source's ideal rig, with awkward numbers.
  const geometry::StereoRig ideal = geometry::StereoRig::Ideal(
      cv::Size(641, 479), 701.123456789, 0.6123456789, 320.3, 239.7, "synthetic");
  Result<v1::RecordedRig> recorded = RecordedRigOf(ideal);
  ASSERT_TRUE(recorded.ok()) << recorded.error().message;
  EXPECT_TRUE(recorded->has_ideal());
  Result<geometry::StereoRig> rebuilt = RigFromRecorded(*recorded);
  ASSERT_TRUE(rebuilt.ok()) << rebuilt.error().message;
  EXPECT_TRUE(RigsIdentical(ideal, *rebuilt));
  EXPECT_EQ(rebuilt->baseline_m(), 0.6123456789);

  // A raw rig with distortion and a rotation: rebuilt from its YAML, remap tables included.
  geometry::StereoCalibration c;
  c.image_size = cv::Size(320, 240);
  c.M1 = cv::Matx33d(412.3456789012, 0, 161.234567, 0, 411.987654321, 119.87654321, 0, 0, 1);
  c.M2 = cv::Matx33d(409.87654321, 0, 158.7654321, 0, 410.123456789, 121.23456789, 0, 0, 1);
  c.D1 = (cv::Mat_<double>(1, 5) << -0.123456789, 0.0456789, 1.23e-4, -2.34e-4, -0.0123);
  c.D2 = (cv::Mat_<double>(1, 5) << -0.11111111, 0.0333333, -1.1e-4, 2.2e-4, 0.0);
  cv::Matx33d rotation;
  cv::Rodrigues(cv::Vec3d(0.00312345, -0.0123456, 0.00456789), rotation);
  c.R = rotation;
  c.T = cv::Vec3d(-0.5987654321, 0.00312345, -0.00123456);
  Result<geometry::StereoRig> raw = geometry::StereoRig::FromCalibration(c, "cal-000042");
  ASSERT_TRUE(raw.ok()) << raw.error().message;
  ASSERT_TRUE(raw->needs_remap());
  recorded = RecordedRigOf(*raw);
  ASSERT_TRUE(recorded.ok()) << recorded.error().message;
  EXPECT_FALSE(recorded->has_ideal());
  rebuilt = RigFromRecorded(*recorded);
  ASSERT_TRUE(rebuilt.ok()) << rebuilt.error().message;
  EXPECT_TRUE(RigsIdentical(*raw, *rebuilt));
  // The remap tables agree too: the same raw pair rectifies to the same pixels.
  cv::Mat1b left(c.image_size), right(c.image_size);
  cv::RNG rng(7);
  rng.fill(left, cv::RNG::UNIFORM, 0, 256);
  rng.fill(right, cv::RNG::UNIFORM, 0, 256);
  cv::Mat a_left, a_right, b_left, b_right;
  ASSERT_TRUE(raw->Rectify(left, right, a_left, a_right).ok());
  ASSERT_TRUE(rebuilt->Rectify(left, right, b_left, b_right).ok());
  EXPECT_TRUE(ImagesIdentical(a_left, b_left));
  EXPECT_TRUE(ImagesIdentical(a_right, b_right));

  // A calibration file of an already rectified rig (FromCalibration, not Ideal): derived baseline.
  Result<geometry::StereoRig> rectified = geometry::StereoRig::FromCalibration(
      geometry::IdealCalibration(cv::Size(320, 240), 333.333333333, 0.3333333333, 160.1, 120.2),
      "bench");
  ASSERT_TRUE(rectified.ok()) << rectified.error().message;
  recorded = RecordedRigOf(*rectified);
  ASSERT_TRUE(recorded.ok()) << recorded.error().message;
  rebuilt = RigFromRecorded(*recorded);
  ASSERT_TRUE(rebuilt.ok()) << rebuilt.error().message;
  EXPECT_TRUE(RigsIdentical(*rectified, *rebuilt));

  // The YAML is a calibration file OpenCV's tools (and ours) read.
  Result<geometry::StereoCalibration> parsed =
      geometry::ParseCalibrationYaml(recorded->calibration_yaml());
  ASSERT_TRUE(parsed.ok()) << parsed.error().message;
  EXPECT_EQ(parsed->M1, rectified->calibration().M1);
}

// Found by fuzzing (tests/fuzz/corpus/recording/regression-huge-rig): a 20 KB manifest naming a
// 16384x16384 rig with a distortion made Open() build 3 GiB of remap tables for most of a
// minute. The rig is bounded in pixels like the frames, before anything is built.
TEST(RecordedRig, ARigOverThePixelLimitIsRefusedBeforeItIsBuilt) {
  geometry::StereoCalibration c = geometry::IdealCalibration(cv::Size(64, 48), 50, 0.12, 32, 24);
  c.D1.at<double>(0) = 0.01;
  c.R1.reset();
  c.R2.reset();
  c.P1.reset();
  c.P2.reset();
  c.Q.reset();
  Result<geometry::StereoRig> rig = geometry::StereoRig::FromCalibration(c, "small");
  ASSERT_TRUE(rig.ok()) << rig.error().message;
  Result<v1::RecordedRig> recorded = RecordedRigOf(*rig);
  ASSERT_TRUE(recorded.ok()) << recorded.error().message;
  ASSERT_FALSE(recorded->has_ideal());
  std::string yaml = recorded->calibration_yaml();
  yaml.replace(yaml.find("image_width: 64"), 15, "image_width: 16384");
  yaml.replace(yaml.find("image_height: 48"), 16, "image_height: 16384");
  recorded->set_calibration_yaml(yaml);
  recorded->set_image_width(16384);
  recorded->set_image_height(16384);
  const auto start = std::chrono::steady_clock::now();
  Result<geometry::StereoRig> rebuilt = RigFromRecorded(*recorded);
  ASSERT_FALSE(rebuilt.ok());
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(1));
  EXPECT_THAT(rebuilt, IsError(ErrorCode::kInvalidArgument));
  EXPECT_TRUE(Contains(rebuilt.error().message, "at most 67108864 pixels in all (got 16384x16384)"))
      << rebuilt.error().message;
}

TEST(Recorder, CalibrationChangesAreRecordedInOrderAndBadOnesRefused) {
  const std::string dir = testing::MakeTempDir("stevi-rec-calib") + "/rec";
  SyntheticSource source(SmallSynthetic(64, 48));
  std::unique_ptr<Recorder> recorder = StartOrDie(dir, RecorderOptions{}, InfoFor(source));
  ASSERT_TRUE(recorder);
  Result<std::string> yaml = geometry::CalibrationYamlText(
      geometry::IdealCalibration(cv::Size(64, 48), 70.5, 0.25, 32.5, 24.5));
  ASSERT_TRUE(yaml.ok());

  const stevi::Status bad = recorder->SetCalibration("cal-bad", "M1: [1, 2]\n");
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad, IsError(ErrorCode::kInvalidArgument));
  EXPECT_TRUE(Contains(bad.error().message, "calibration change refused")) << bad.error().message;
  EXPECT_TRUE(Contains(bad.error().message, "image_width: missing")) << bad.error().message;
  ASSERT_FALSE(recorder->SetCalibration("", *yaml).ok());

  ASSERT_TRUE(recorder->AddFrame(*source.Next()).ok());
  ASSERT_TRUE(recorder->SetCalibration("cal-000008", *yaml).ok());
  ASSERT_TRUE(recorder->AddFrame(*source.Next()).ok());
  ASSERT_TRUE(recorder->Stop().ok());
  EXPECT_EQ(recorder->Status().calibration_changes_written, 1u);

  std::unique_ptr<RecordingReader> reader = OpenOrDie(dir);
  ASSERT_TRUE(reader);
  const std::vector<RecordingRecord> records = ReadAll(*reader, /*decode=*/false);
  ASSERT_EQ(records.size(), 3u);
  EXPECT_EQ(records[0].kind, RecordingRecord::Kind::kFrame);
  ASSERT_EQ(records[1].kind, RecordingRecord::Kind::kCalibration);
  EXPECT_EQ(records[1].calibration.calibration_id, "cal-000008");
  EXPECT_EQ(records[1].calibration.yaml, *yaml);
  EXPECT_GT(records[1].calibration.unix_time_ns, 0);
  EXPECT_EQ(records[2].kind, RecordingRecord::Kind::kFrame);
  EXPECT_EQ(reader->manifest().calibration_changes_written(), 1u);
}

TEST(Recorder, StopIsIdempotentAndLaterRecordsAreRefused) {
  const std::string dir = testing::MakeTempDir("stevi-rec-stop") + "/rec";
  SyntheticSource source(SmallSynthetic(64, 48));
  std::unique_ptr<Recorder> recorder = StartOrDie(dir, RecorderOptions{}, InfoFor(source));
  ASSERT_TRUE(recorder);
  ASSERT_TRUE(recorder->AddFrame(*source.Next()).ok());
  ASSERT_TRUE(recorder->Stop("first").ok());
  ASSERT_TRUE(recorder->Stop("second").ok());
  EXPECT_EQ(recorder->Status().stop_reason, "first");

  const stevi::Status late = recorder->AddFrame(*source.Next());
  ASSERT_FALSE(late.ok());
  EXPECT_THAT(late, IsError(ErrorCode::kFailedPrecondition));
  EXPECT_TRUE(Contains(late.error().message, "has stopped (first)")) << late.error().message;
  EXPECT_THAT(recorder->AddVehicleState(State(0)), IsError(ErrorCode::kFailedPrecondition));
  EXPECT_EQ(recorder->Status().frames_written, 1u);

  // Bad images are refused up front, naming the problem.
  const std::string dir2 = testing::MakeTempDir("stevi-rec-badframe") + "/rec";
  recorder = StartOrDie(dir2, RecorderOptions{}, InfoFor(source));
  ASSERT_TRUE(recorder);
  StereoFrame bad = *source.Next();
  bad.right = cv::Mat1f(bad.left.size(), 0.5f);
  const stevi::Status refused = recorder->AddFrame(bad);
  ASSERT_FALSE(refused.ok());
  EXPECT_THAT(refused, IsError(ErrorCode::kInvalidArgument));
  EXPECT_TRUE(Contains(refused.error().message, "right: expected 8-bit grey (CV_8UC1) or BGR"))
      << refused.error().message;
  // Destruction stops the recording with a reason.
  recorder.reset();
  std::unique_ptr<RecordingReader> reader = OpenOrDie(dir2);
  ASSERT_TRUE(reader);
  EXPECT_EQ(reader->manifest().state(), v1::RECORDING_STATE_STOPPED);
  EXPECT_EQ(reader->manifest().stop_reason(), "recorder destroyed");
}

// ---- Bounds -------------------------------------------------------------------------------------

TEST(Recorder, DiskLimitStopsWithTheReasonAndKeepsWholeRecords) {
  const std::string dir = testing::MakeTempDir("stevi-rec-limit") + "/rec";
  SyntheticSource source(SmallSynthetic());  // 160x120 noisy frames: tens of KiB each
  RecorderOptions options;
  options.max_bytes = RecorderOptions::kMinMaxBytes;
  constexpr int kOffered = 100;
  options.queue_frames = kOffered;
  std::unique_ptr<Recorder> recorder = StartOrDie(dir, options, InfoFor(source));
  ASSERT_TRUE(recorder);
  std::vector<StereoFrame> frames;
  for (int k = 0; k < kOffered; ++k) {
    frames.push_back(Stamped(*source.Next(), k));
    // Queued, or refused because the writer already reached the limit: never blocked.
    const stevi::Status added = recorder->AddFrame(frames.back());
    if (!added.ok()) {
      EXPECT_THAT(added, IsError(ErrorCode::kFailedPrecondition));
    }
  }
  // The limit is not an error: Stop() succeeds, and the first reason stays.
  EXPECT_TRUE(recorder->Stop("end of test").ok());
  const RecorderStatus status = recorder->Status();
  EXPECT_FALSE(status.recording);
  ASSERT_GT(status.frames_written, 0u);
  ASSERT_LT(status.frames_written, static_cast<uint64_t>(kOffered));
  EXPECT_EQ(status.stop_reason, "disk limit of 1.0 MiB reached after " +
                                    std::to_string(status.frames_written) + " frames");
  EXPECT_EQ(status.error, "");
  EXPECT_LE(status.bytes_written, options.max_bytes);
  EXPECT_EQ(fs::file_size(dir + "/records.bin"), status.bytes_written);

  std::unique_ptr<RecordingReader> reader = OpenOrDie(dir);
  ASSERT_TRUE(reader);
  EXPECT_EQ(reader->manifest().state(), v1::RECORDING_STATE_STOPPED);
  EXPECT_EQ(reader->manifest().stop_reason(), status.stop_reason);
  EXPECT_EQ(reader->manifest().frames_written(), status.frames_written);
  const std::vector<RecordingRecord> records = ReadAll(*reader);
  EXPECT_EQ(reader->end_note(), "") << "only whole records";
  ASSERT_EQ(records.size(), status.frames_written);
  for (size_t k = 0; k < records.size(); ++k) ExpectSameFrame(frames[k], records[k].frame);

  // And it replays.
  Result<std::unique_ptr<ReplaySource>> replay = ReplaySource::Open(dir, ReplayOptions{0, false});
  ASSERT_TRUE(replay.ok()) << replay.error().message;
  for (size_t k = 0; k < records.size(); ++k) {
    Result<StereoFrame> frame = (*replay)->Next();
    ASSERT_TRUE(frame.ok()) << frame.error().message;
    ExpectSameFrame(frames[k], *frame);
  }
  EXPECT_THAT((*replay)->Next(), IsError(ErrorCode::kOutOfRange));
}

// A file-size limit (RLIMIT_FSIZE) makes write() fail part-way through a record, as a full disk
// would: the recorder cuts the torn record off and stops with the error.
TEST(Recorder, WriteErrorStopsAndTruncatesToTheLastWholeRecord) {
  const std::string dir = testing::MakeTempDir("stevi-rec-ioerror") + "/rec";
  SyntheticSource source(SmallSynthetic());
  RecorderOptions options;
  options.queue_frames = 20;
  std::unique_ptr<Recorder> recorder = StartOrDie(dir, options, InfoFor(source));
  ASSERT_TRUE(recorder);

  rlimit saved{};
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &saved), 0);
  const auto old_handler = signal(SIGXFSZ, SIG_IGN);  // EFBIG instead of the signal
  rlimit limited = saved;
  limited.rlim_cur = 150'000;
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &limited), 0);
  std::vector<StereoFrame> frames;
  for (int k = 0; k < 20; ++k) {
    frames.push_back(Stamped(*source.Next(), k));
    (void)recorder->AddFrame(frames.back());  // refused once the writer has failed
  }
  const stevi::Status stopped = recorder->Stop("end of test");
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &saved), 0);
  signal(SIGXFSZ, old_handler);

  ASSERT_FALSE(stopped.ok());
  EXPECT_THAT(stopped, IsError(ErrorCode::kResourceExhausted));
  const RecorderStatus status = recorder->Status();
  ASSERT_GT(status.frames_written, 0u);
  EXPECT_EQ(status.error, dir + "/records.bin: write failed after " +
                              std::to_string(status.frames_written) + " frames (" +
                              std::strerror(EFBIG) + ")");
  EXPECT_EQ(status.stop_reason, status.error);
  EXPECT_EQ(fs::file_size(dir + "/records.bin"), status.bytes_written) << "torn record cut off";
  EXPECT_GT(status.bytes_written + 60'000, limited.rlim_cur) << "it wrote up to the limit";

  std::unique_ptr<RecordingReader> reader = OpenOrDie(dir);
  ASSERT_TRUE(reader);
  EXPECT_EQ(reader->manifest().state(), v1::RECORDING_STATE_STOPPED);
  EXPECT_TRUE(reader->manifest().failed());
  EXPECT_EQ(reader->manifest().stop_reason(), status.error);
  const std::vector<RecordingRecord> records = ReadAll(*reader);
  EXPECT_EQ(reader->end_note(), "");
  ASSERT_EQ(records.size(), status.frames_written);
  for (size_t k = 0; k < records.size(); ++k) ExpectSameFrame(frames[k], records[k].frame);
}

// A burst of large frames against a one-frame queue: AddFrame drops and counts instead of waiting
// for the encoder (a 1920x1080 colour PNG at level 9 takes a large fraction of a second).
TEST(Recorder, FullQueueDropsAndCountsWithoutBlocking) {
  const std::string dir = testing::MakeTempDir("stevi-rec-burst") + "/rec";
  SyntheticSource source(SmallSynthetic(64, 48));
  RecorderOptions options;
  options.queue_frames = 1;
  options.png_compression = 9;
  std::unique_ptr<Recorder> recorder = StartOrDie(dir, options, InfoFor(source));
  ASSERT_TRUE(recorder);
  StereoFrame big;
  big.left = cv::Mat3b(1080, 1920);
  big.right = cv::Mat3b(1080, 1920);
  cv::RNG rng(3);
  rng.fill(big.left, cv::RNG::UNIFORM, 0, 256);
  rng.fill(big.right, cv::RNG::UNIFORM, 0, 256);

  constexpr int kBurst = 20;
  int queued = 0, dropped = 0;
  const Clock::time_point start = Clock::now();
  for (int k = 0; k < kBurst; ++k) {
    big.index = k;
    const stevi::Status added = recorder->AddFrame(big);
    if (added.ok()) {
      ++queued;
    } else {
      EXPECT_THAT(added, IsError(ErrorCode::kResourceExhausted)) << added.error().message;
      EXPECT_TRUE(Contains(added.error().message, "dropped")) << added.error().message;
      ++dropped;
    }
  }
  const double burst_s = std::chrono::duration<double>(Clock::now() - start).count();
  const RecorderStatus during = recorder->Status();
  EXPECT_GT(dropped, 0);
  EXPECT_EQ(during.frames_dropped, static_cast<uint64_t>(dropped));
  ASSERT_TRUE(recorder->Stop().ok());
  const RecorderStatus status = recorder->Status();
  EXPECT_EQ(status.frames_written, static_cast<uint64_t>(queued));
  EXPECT_EQ(status.frames_written + status.frames_dropped, static_cast<uint64_t>(kBurst));
  // Waiting for the writer would take about kBurst encodes; copying twenty frames takes a blink.
  const double per_encode_s = std::chrono::duration<double>(Clock::now() - start).count() /
                              static_cast<double>(std::max<uint64_t>(1, status.frames_written));
  std::cout << "burst of " << kBurst << " frames: " << burst_s << " s, " << queued << " queued, "
            << dropped << " dropped; about " << per_encode_s << " s per written frame\n";
  EXPECT_LT(burst_s, 2.0);
  EXPECT_LT(burst_s, 0.5 * kBurst * per_encode_s);
  fs::remove_all(dir);  // tens of MB of incompressible PNG
}

// ---- Damaged recordings -------------------------------------------------------------------------

// records.bin cut at every byte: the reader returns exactly the records that end before the cut,
// and says where it stopped whenever the cut is inside a record.
TEST(RecordingReader, TruncationAtAnyByteKeepsEveryCompleteRecord) {
  const std::string dir = testing::MakeTempDir("stevi-rec-cut") + "/rec";
  const std::vector<StereoFrame> frames = RecordSmall(dir, 4, 32, 24);
  ASSERT_EQ(frames.size(), 4u);
  const std::string bytes = ReadFile(dir + "/records.bin");
  std::vector<uint64_t> ends;  // end offset of each record
  {
    std::unique_ptr<RecordingReader> reader = OpenOrDie(dir);
    ASSERT_TRUE(reader);
    while (reader->Next(false)) ends.push_back(reader->offset());
    ASSERT_EQ(ends.size(), 8u);  // a state and a frame, four times
    ASSERT_EQ(ends.back(), bytes.size());
  }

  const std::string cut_dir = testing::MakeTempDir("stevi-rec-cut-copy");
  fs::copy_file(dir + "/manifest.json", cut_dir + "/manifest.json");
  // Longest first, each cut shortening the one file: rewriting it each time would make ext4
  // flush it to disk on every close (its replace-by-truncate heuristic), which is slow.
  WriteFile(cut_dir + "/records.bin", bytes);
  for (size_t cut = bytes.size() + 1; cut-- > 0;) {
    fs::resize_file(cut_dir + "/records.bin", cut);
    std::unique_ptr<RecordingReader> reader = OpenOrDie(cut_dir);
    ASSERT_TRUE(reader);
    // Decode the images at some cuts; the framing alone at the others (faster).
    const bool decode = cut % 7 == 0 || cut == bytes.size();
    const std::vector<RecordingRecord> records = ReadAll(*reader, decode);
    size_t complete = 0;
    while (complete < ends.size() && ends[complete] <= cut) ++complete;
    ASSERT_EQ(records.size(), complete) << "cut at byte " << cut;
    const bool at_boundary = cut == 0 || (complete > 0 && ends[complete - 1] == cut);
    if (at_boundary) {
      EXPECT_EQ(reader->end_note(), "") << "cut at byte " << cut;
    } else {
      const uint64_t start = complete == 0 ? 0 : ends[complete - 1];
      EXPECT_EQ(reader->end_note().rfind(cut_dir + "/records.bin: truncated record after " +
                                             std::to_string(complete / 2) + " frames at byte " +
                                             std::to_string(start) + " (",
                                         0),
                0u)
          << "cut at byte " << cut << ": " << reader->end_note();
    }
    if (decode) {
      for (const RecordingRecord& r : records) {
        if (r.kind == RecordingRecord::Kind::kFrame) {
          ExpectSameFrame(frames[r.frame.index], r.frame);
        }
      }
    }
  }
}

// The child half of CrashLeavesAReadablePrefix: records until killed. Run only by that test.
TEST(RecorderCrashChild, DISABLED_RecordUntilKilled) {
  const char* dir = std::getenv("STEVI_RECORDING_CHILD_DIR");
  const char* fd_text = std::getenv("STEVI_RECORDING_CHILD_FD");
  if (dir == nullptr || fd_text == nullptr) GTEST_SKIP() << "run by CrashLeavesAReadablePrefix";
  const int fd = std::atoi(fd_text);
  SyntheticSource source(SmallSynthetic());
  std::unique_ptr<Recorder> recorder = StartOrDie(dir, RecorderOptions{}, InfoFor(source));
  ASSERT_TRUE(recorder);
  bool told = false;
  const Clock::time_point give_up = Clock::now() + std::chrono::seconds(60);
  while (Clock::now() < give_up) {  // the parent kills us long before
    (void)recorder->AddFrame(*source.Next());
    if (!told && recorder->Status().frames_written >= 5) {
      told = write(fd, "R", 1) == 1;
    }
  }
}

TEST(Recorder, CrashLeavesAReadablePrefix) {
  const std::string dir = testing::MakeTempDir("stevi-rec-crash") + "/rec";
  int ready[2];
  ASSERT_EQ(pipe(ready), 0);
  const std::string exe = fs::read_symlink("/proc/self/exe").string();
  const std::string fd_text = std::to_string(ready[1]);
  std::vector<std::string> args = {exe, "--gtest_filter=RecorderCrashChild.*",
                                   "--gtest_also_run_disabled_tests"};
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  setenv("STEVI_RECORDING_CHILD_DIR", dir.c_str(), 1);
  setenv("STEVI_RECORDING_CHILD_FD", fd_text.c_str(), 1);
  const int devnull = open("/dev/null", O_WRONLY);
  const pid_t pid = fork();
  if (pid == 0) {
    dup2(devnull, STDOUT_FILENO);
    dup2(devnull, STDERR_FILENO);
    close(ready[0]);
    execv(exe.c_str(), argv.data());
    _exit(127);
  }
  unsetenv("STEVI_RECORDING_CHILD_DIR");
  unsetenv("STEVI_RECORDING_CHILD_FD");
  close(devnull);
  close(ready[1]);
  ASSERT_GT(pid, 0);

  pollfd wait_for{ready[0], POLLIN, 0};
  const int polled = poll(&wait_for, 1, 60'000);
  char got = 0;
  const bool child_ready = polled == 1 && read(ready[0], &got, 1) == 1 && got == 'R';
  close(ready[0]);
  kill(pid, SIGKILL);  // mid-recording: frames are being encoded and appended
  int wait_status = 0;
  ASSERT_EQ(waitpid(pid, &wait_status, 0), pid);
  ASSERT_TRUE(child_ready) << "the child never reported 5 frames written";
  EXPECT_TRUE(WIFSIGNALED(wait_status) && WTERMSIG(wait_status) == SIGKILL);

  std::unique_ptr<RecordingReader> reader = OpenOrDie(dir);
  ASSERT_TRUE(reader);
  EXPECT_EQ(reader->manifest().state(), v1::RECORDING_STATE_RECORDING) << "never stopped";
  const SyntheticRenderer renderer(SmallSynthetic());
  const std::vector<RecordingRecord> records = ReadAll(*reader);
  EXPECT_GE(records.size(), 5u);
  EXPECT_TRUE(reader->end_note().empty() || Contains(reader->end_note(), "truncated record"))
      << reader->end_note();
  int64_t previous = -1;
  for (const RecordingRecord& r : records) {
    ASSERT_EQ(r.kind, RecordingRecord::Kind::kFrame);
    EXPECT_GT(r.frame.index, previous) << "in order (some may have been dropped)";
    previous = r.frame.index;
    ExpectSameFrame(renderer.Render(r.frame.index), r.frame);
  }
  std::cout << "killed child left " << records.size() << " readable frames ("
            << (reader->end_note().empty() ? "clean end" : reader->end_note()) << ")\n";
}

TEST(RecordingReader, DamagedManifestsAreClearErrors) {
  const std::string dir = testing::MakeTempDir("stevi-rec-manifest") + "/rec";
  RecordSmall(dir, 2);
  const std::string good = ReadFile(dir + "/manifest.json");
  const std::string manifest = dir + "/manifest.json";
  auto open_error = [&](const std::string& text) {
    WriteFile(manifest, text);
    Result<std::unique_ptr<RecordingReader>> r = RecordingReader::Open(dir);
    EXPECT_FALSE(r.ok());
    return r.ok() ? Error{} : r.error();
  };

  Error e = open_error("\x89garbage\x01\x02{{{");
  EXPECT_EQ(e.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(e.message.rfind(manifest + ": not a recording manifest (", 0), 0u) << e.message;

  e = open_error("{}");
  EXPECT_EQ(e.message, manifest + ": format_version: missing (not a recording manifest)");

  std::string newer = good;
  newer.replace(newer.find("\"format_version\": 1"), 19, "\"format_version\": 99");
  e = open_error(newer);
  EXPECT_EQ(e.message, manifest + ": format_version: 99 is newer than this program reads (1)");

  std::string bad_rig = good;
  const size_t f_px = bad_rig.find("\"f_px\": ");
  ASSERT_NE(f_px, std::string::npos);
  bad_rig.insert(f_px + 8, 1, '-');
  e = open_error(bad_rig);
  EXPECT_TRUE(Contains(e.message, manifest + ": rig: ideal.f_px: must be > 0 and finite (got -"))
      << e.message;

  // Too large to be a manifest: refused before it is read.
  WriteFile(manifest, "");
  fs::resize_file(manifest, 64ull << 20);
  Result<std::unique_ptr<RecordingReader>> r = RecordingReader::Open(dir);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(Contains(r.error().message, "more than the 16.0 MiB a manifest may have"))
      << r.error().message;

  fs::remove(manifest);
  r = RecordingReader::Open(dir);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r, IsError(ErrorCode::kNotFound));
  EXPECT_EQ(r.error().message, manifest + ": not found (" + dir + " is not a recording directory)");

  r = RecordingReader::Open(dir + "/nope");
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r, IsError(ErrorCode::kNotFound));
}

// Writes records with protobuf's own delimited writer (the format is its framing).
void AppendEntries(const std::string& path, const std::vector<v1::RecordEntry>& entries) {
  std::ofstream out(path, std::ios::binary | std::ios::app);
  for (const v1::RecordEntry& e : entries) {
    ASSERT_TRUE(google::protobuf::util::SerializeDelimitedToOstream(e, &out));
  }
}

TEST(RecordingReader, CorruptRecordsEndTheIterationCleanly) {
  const std::string dir = testing::MakeTempDir("stevi-rec-corrupt") + "/rec";
  const std::vector<StereoFrame> frames = RecordSmall(dir, 3);
  const std::string records_path = dir + "/records.bin";
  const std::string good = ReadFile(records_path);

  // Protobuf's own delimited reader reads our records: the framing is the standard one.
  {
    std::ifstream in(records_path, std::ios::binary);
    google::protobuf::io::IstreamInputStream stream(&in);
    v1::RecordEntry entry;
    int n = 0;
    bool clean_eof = false;
    while (google::protobuf::util::ParseDelimitedFromZeroCopyStream(&entry, &stream, &clean_eof)) {
      ++n;
    }
    EXPECT_TRUE(clean_eof);
    EXPECT_EQ(n, 6);
  }

  // Each case: the good records, then the damage. The three frames come back, then a note.
  struct Case {
    std::string name;
    std::string tail;
    std::string note;  // part of the end note
  };
  std::vector<Case> cases;
  cases.push_back({"absurd length", std::string("\xff\xff\xff\xff\x0f", 5) + "xyz",
                   "(it announces 4294967295 bytes, more than the 512.0 MiB limit)"});
  cases.push_back(
      {"long varint", std::string("\xff\xff\xff\xff\xff\x01", 6), "(bad length prefix)"});
  cases.push_back({"length past the end", std::string("\x80\x80\x10", 3) + "abc",
                   "(262144 bytes announced, 3 left)"});
  cases.push_back({"not a message", std::string("\x04\xff\xff\xff\xff", 5), "(not a RecordEntry)"});
  std::mt19937 rng(11);
  std::string noise(4000, '\0');
  for (char& c : noise) c = static_cast<char>(rng());
  cases.push_back({"random bytes", noise, "records.bin: "});
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    WriteFile(records_path, good + c.tail);
    std::unique_ptr<RecordingReader> reader = OpenOrDie(dir);
    ASSERT_TRUE(reader);
    const std::vector<RecordingRecord> records = ReadAll(*reader);
    ASSERT_GE(records.size(), 6u);
    for (size_t i = 0; i < 6; ++i) {
      if (records[i].kind == RecordingRecord::Kind::kFrame) {
        ExpectSameFrame(frames[i / 2], records[i].frame);
      }
    }
    EXPECT_TRUE(Contains(reader->end_note(), c.note)) << reader->end_note();
    EXPECT_TRUE(Contains(reader->end_note(), records_path)) << reader->end_note();
  }

  // Frames whose images lie about their size, or claim a huge one, are refused before decoding.
  std::vector<uchar> png;
  ASSERT_TRUE(cv::imencode(".png", frames[0].left, png));
  const std::string png_bytes(png.begin(), png.end());
  auto frame_entry = [&](int w, int h, int channels, const std::string& data) {
    v1::RecordEntry e;
    v1::RecordedFrame* f = e.mutable_frame();
    for (v1::RecordedImage* image : {f->mutable_left(), f->mutable_right()}) {
      image->set_width(w);
      image->set_height(h);
      image->set_channels(channels);
      image->set_data(data);
    }
    return e;
  };
  std::string huge_png = png_bytes;  // IHDR width and height at bytes 16..23, big-endian
  for (int i = 16; i < 24; ++i) huge_png[i] = '\x7f';
  struct FrameCase {
    std::string name;
    v1::RecordEntry entry;
    std::string note;
  };
  std::string corrupt_png = png_bytes;
  corrupt_png[corrupt_png.size() / 2] ^= 0x55;
  const std::vector<FrameCase> frame_cases = {
      {"size lie", frame_entry(16000, 16000, 1, png_bytes), "is outside the format's limits"},
      {"header lie", frame_entry(48, 64, 1, png_bytes), "PNG is 64x48 but the record says 48x64"},
      {"huge header", frame_entry(64, 48, 1, huge_png), "PNG is 2139062143x2139062143"},
      {"channels", frame_entry(64, 48, 3, png_bytes), "expected 8-bit colour"},
      {"not png", frame_entry(64, 48, 1, std::string(100, 'x')), "is not a PNG"},
      {"bad data", frame_entry(64, 48, 1, corrupt_png), "left image: the PNG does not decode"},
  };
  for (const FrameCase& c : frame_cases) {
    SCOPED_TRACE(c.name);
    WriteFile(records_path, good);
    AppendEntries(records_path, {c.entry});
    std::unique_ptr<RecordingReader> reader = OpenOrDie(dir);
    ASSERT_TRUE(reader);
    EXPECT_EQ(ReadAll(*reader).size(), 6u);
    EXPECT_TRUE(Contains(reader->end_note(),
                         "corrupt record after 3 frames at byte " + std::to_string(good.size())))
        << reader->end_note();
    EXPECT_TRUE(Contains(reader->end_note(), c.note)) << reader->end_note();
  }

  // A record kind from a newer writer (an unknown field) is skipped, not an error.
  WriteFile(records_path, good + std::string("\x03\xf8\x06\x01", 4));  // field 111, varint 1
  std::unique_ptr<RecordingReader> reader = OpenOrDie(dir);
  ASSERT_TRUE(reader);
  EXPECT_EQ(ReadAll(*reader).size(), 6u);
  EXPECT_EQ(reader->end_note(), "");
  EXPECT_EQ(reader->unknown_skipped(), 1u);

  // Flipped bytes anywhere: never a crash, and the records that end before the damage are exact.
  std::vector<uint64_t> ends;
  {
    WriteFile(records_path, good);
    std::unique_ptr<RecordingReader> r = OpenOrDie(dir);
    ASSERT_TRUE(r);
    while (r->Next(false)) ends.push_back(r->offset());
    ASSERT_EQ(ends.size(), 6u);
  }
  for (int trial = 0; trial < 300; ++trial) {
    std::string damaged = good;
    const size_t at = rng() % damaged.size();
    damaged[at] = static_cast<char>(damaged[at] ^ (1 + rng() % 255));
    WriteFile(records_path, damaged);
    std::unique_ptr<RecordingReader> r = OpenOrDie(dir);
    ASSERT_TRUE(r);
    const std::vector<RecordingRecord> records = ReadAll(*r);
    for (size_t i = 0; i < records.size() && i < ends.size() && ends[i] <= at; ++i) {
      if (records[i].kind == RecordingRecord::Kind::kFrame) {
        ExpectSameFrame(frames[i / 2], records[i].frame);
      } else {
        EXPECT_EQ(records[i].vehicle_state, State(static_cast<int>(i / 2)));
      }
    }
  }
}

// ---- Throughput ---------------------------------------------------------------------------------

// How fast the writer thread encodes and appends 640x480 grey pairs at the default PNG level, and
// how large they are. It must at least keep up with the synthetic source's 10 frames/s.
TEST(Recorder, ThroughputOf640x480GreyPairs) {
  const std::string dir = testing::MakeTempDir("stevi-rec-speed") + "/rec";
  SyntheticSource source(SyntheticOptions{});
  constexpr int kFrames = 40;
  std::vector<StereoFrame> frames;
  for (int k = 0; k < kFrames; ++k) frames.push_back(*source.Next());
  RecorderOptions options;
  options.queue_frames = kFrames;
  std::unique_ptr<Recorder> recorder = StartOrDie(dir, options, InfoFor(source));
  ASSERT_TRUE(recorder);
  const Clock::time_point start = Clock::now();
  for (const StereoFrame& f : frames) ASSERT_TRUE(recorder->AddFrame(f).ok());
  ASSERT_TRUE(recorder->Stop().ok());
  const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
  const RecorderStatus status = recorder->Status();
  ASSERT_EQ(status.frames_written, static_cast<uint64_t>(kFrames));
  const double fps = kFrames / seconds;
  const double bytes_per_frame = static_cast<double>(status.bytes_written) / kFrames;
  std::cout << "recorded " << kFrames << " 640x480 grey pairs (synthetic, noise sigma 2, PNG level "
            << options.png_compression << ") in " << seconds << " s: " << fps << " frames/s, "
            << bytes_per_frame << " bytes/frame (raw " << 2 * 640 * 480 << ")\n";
  ::testing::Test::RecordProperty("frames_per_second", std::to_string(fps));
  ::testing::Test::RecordProperty("bytes_per_frame", std::to_string(bytes_per_frame));
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  // Instrumented builds run several times slower: the number is printed, not judged.
#else
  EXPECT_GT(fps, 10.0);
#endif
  EXPECT_LT(bytes_per_frame, 2.0 * 640 * 480) << "PNG should not be larger than raw";
  fs::remove_all(dir);  // 15 MB
}

}  // namespace
}  // namespace stevi::drivers
