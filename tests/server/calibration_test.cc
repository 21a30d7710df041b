// The CalibrationService in-process on a loopback port, through a real gRPC channel, on the
// synthetic chessboard scene (an ideal rig: f = 700 px, B = 0.6 m, 640x480).
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <fstream>
#include <cstdio>
#include <thread>
#include <mutex>
#include <condition_variable>

#include "client/lib/client.h"
#include "core/calibration/chessboard_render.h"
#include "core/geometry/calibration_io.h"
#include "server/runtime/engine.h"
#include "server/server.h"
#include "tests/server/loopback_client.h"
#include "tests/testing/data.h"
#include "tests/testing/sanitized.h"

namespace stevi::server {
namespace {

using ::testing::HasSubstr;

constexpr double kF = 700, kB = 0.6;
// The chessboard rig's rate: slower under a sanitizer, so that the slower pipeline still takes
// every frame and a capture sees each pose of the moving board (which holds one for 5 frames).
constexpr int kFps = testing::kSanitized ? 10 : 20;

v1::ServerConfig ChessboardConfig(const std::string& data_dir) {
  v1::ServerConfig config;
  config.set_listen("127.0.0.1:0");
  config.mutable_source()->set_fps(kFps);
  config.mutable_source()->mutable_synthetic()->set_scene("chessboard");
  config.set_data_dir(data_dir);
  return config;
}

v1::CalibrationSettings Board(bool apply) {
  v1::CalibrationSettings s;
  s.mutable_board()->set_columns(9);
  s.mutable_board()->set_rows(6);
  s.mutable_board()->set_square_m(0.10);
  s.set_apply(apply);
  return s;
}

std::string Png(const cv::Mat& image) {
  std::vector<uchar> bytes;
  cv::imencode(".png", image, bytes);
  return std::string(bytes.begin(), bytes.end());
}

// `count` uploaded pairs of the board seen by the ideal rig, as PNG.
std::vector<v1::ImagePair> RenderedPairs(int count) {
  const cv::Size size(640, 480);
  const geometry::StereoCalibration rig = geometry::IdealCalibration(size, kF, kB, 320, 240);
  const calibration::BoardSpec board{9, 6, 0.10};
  Result<calibration::ChessboardRenderer> renderer =
      calibration::ChessboardRenderer::Create(rig, board, size);
  EXPECT_TRUE(renderer.ok());
  Result<std::vector<cv::Affine3d>> poses =
      calibration::GenerateBoardPoses(rig, board, size, count, 7);
  EXPECT_TRUE(poses.ok());
  std::vector<v1::ImagePair> pairs;
  for (int i = 0; renderer.ok() && poses.ok() && i < count; ++i) {
    const calibration::RenderedPair r = renderer->Render((*poses)[i]);
    v1::ImagePair p;
    p.set_left(Png(r.left));
    p.set_right(Png(r.right));
    p.set_name("pair " + std::to_string(i));
    pairs.push_back(std::move(p));
  }
  return pairs;
}

class CalibrationServiceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    data_dir_ = testing::MakeTempDir("stevi-calibration");
    StartServer();
  }

  void StartServer() {
    Result<std::unique_ptr<Server>> server = Server::Start(ChessboardConfig(data_dir_));
    ASSERT_TRUE(server.ok()) << server.error().message;
    server_ = std::move(server).value();
    client_ = std::make_unique<client::Client>(
        testing::LoopbackOptions(*server_, std::chrono::seconds(20)));
  }

  std::string ActiveCalibrationId() {
    v1::GetStatusResponse status;
    EXPECT_TRUE(client_->GetStatus(&status).ok());
    return status.calibration_id();
  }

  std::string data_dir_;
  std::unique_ptr<Server> server_;
  std::unique_ptr<client::Client> client_;
};

TEST_F(CalibrationServiceTest, UploadCalibratesAppliesAndTheStreamGoesOnWithIt) {
  EXPECT_EQ(ActiveCalibrationId(), "synthetic");
  v1::CalibrationReport report;
  const grpc::Status status = client_->Calibrate(Board(/*apply=*/true), RenderedPairs(14), &report);
  ASSERT_TRUE(status.ok()) << status.error_message();
  std::cout << report.text() << "\n";
  EXPECT_TRUE(report.passed()) << report.text();
  EXPECT_TRUE(report.applied());
  EXPECT_EQ(report.calibration_id(), "cal-000001");
  EXPECT_EQ(report.pairs_used(), 14);
  EXPECT_LT(report.rms_px(), 0.3);
  EXPECT_NEAR(report.f_px(), kF, 0.005 * kF);
  EXPECT_NEAR(report.baseline_m(), kB, 0.005 * kB);
  EXPECT_FALSE(report.swapped_left_right());

  // The next frames are processed with it, without a restart. Frames already in the pipeline
  // when it was applied (at most one per worker) were taken with the old rig and may still come
  // out; after the first frame with the new calibration, every frame has it.
  EXPECT_EQ(ActiveCalibrationId(), "cal-000001");
  client::StreamOptions options;
  options.max_frames = Engine::kDefaultWorkers + 3;
  std::vector<std::string> ids;
  ASSERT_TRUE(client_
                  ->StreamTracks(
                      [&](const v1::TrackFrame& f) {
                        ids.push_back(f.calibration_id());
                        return true;
                      },
                      options)
                  .ok());
  const auto first_new = std::find(ids.begin(), ids.end(), "cal-000001");
  EXPECT_LE(first_new - ids.begin(), static_cast<std::ptrdiff_t>(Engine::kDefaultWorkers));
  EXPECT_THAT(std::vector<std::string>(first_new, ids.end()),
              ::testing::Each(std::string("cal-000001")));
  EXPECT_GE(ids.end() - first_new, 3);

  v1::ListCalibrationsResponse list;
  ASSERT_TRUE(client_->ListCalibrations(&list).ok());
  ASSERT_EQ(list.calibrations_size(), 1);
  EXPECT_EQ(list.active_id(), "cal-000001");
  EXPECT_TRUE(list.calibrations(0).active());
  v1::CalibrationRecord record;
  ASSERT_TRUE(client_->GetCalibration("cal-000001", &record).ok());
  EXPECT_THAT(record.yaml(), HasSubstr("M1"));
  Result<geometry::StereoCalibration> parsed = geometry::ParseCalibrationYaml(record.yaml());
  ASSERT_TRUE(parsed.ok()) << parsed.error().message;
  EXPECT_NEAR(cv::norm(parsed->T), kB, 0.005 * kB);

  // A restart comes back with it.
  server_->Shutdown();
  server_.reset();
  StartServer();
  EXPECT_EQ(ActiveCalibrationId(), "cal-000001");

  // A second one becomes active; then its file is damaged while the server is down: the server
  // starts anyway, says what is wrong, and runs with the last good calibration.
  ASSERT_TRUE(client_->Calibrate(Board(/*apply=*/true), RenderedPairs(12), &report).ok());
  ASSERT_EQ(report.calibration_id(), "cal-000002");
  EXPECT_EQ(ActiveCalibrationId(), "cal-000002");
  server_->Shutdown();
  server_.reset();
  {
    std::ofstream damaged(data_dir_ + "/cal-000002.yaml", std::ios::trunc);
    damaged << "%YAML:1.0\nM1: [1, 2\n";
  }
  StartServer();
  EXPECT_EQ(ActiveCalibrationId(), "cal-000001");
  ASSERT_TRUE(client_->ListCalibrations(&list).ok());
  EXPECT_EQ(list.active_id(), "cal-000001");
  ASSERT_GE(list.store_problems_size(), 1);
  EXPECT_THAT(list.store_problems(0), HasSubstr("cal-000002"));
}

TEST_F(CalibrationServiceTest, CaptureOnTheMovingChessboardStreamsProgressThenTheReport) {
  v1::CaptureCalibrationRequest request;
  *request.mutable_settings() = Board(/*apply=*/true);
  request.set_pairs(12);
  request.set_interval_s(6.0 / kFps);  // the board holds each pose 5 frames (0.25 s at 20 fps)
  std::vector<v1::CapturedPair> progress;
  v1::CalibrationReport report;
  const grpc::Status status =
      client_->CaptureCalibration(request, [&](const v1::CaptureProgress& p) {
        if (p.has_pair()) progress.push_back(p.pair());
        if (p.has_report()) report = p.report();
      });
  ASSERT_TRUE(status.ok()) << status.error_message();
  ASSERT_EQ(progress.size(), 12u);
  int boards = 0;
  for (size_t i = 0; i < progress.size(); ++i) {
    EXPECT_EQ(progress[i].index(), static_cast<int>(i) + 1);
    EXPECT_EQ(progress[i].of(), 12);
    if (progress[i].board_left() && progress[i].board_right()) ++boards;
    if (i > 0) {
      EXPECT_GE(progress[i].coverage_left(), progress[i - 1].coverage_left());
    }
  }
  EXPECT_EQ(boards, 12);
  // The union grows as the board moves about (one pose covers 10-20 % of the image).
  EXPECT_GT(progress.back().coverage_left(), 1.5 * progress.front().coverage_left());
  EXPECT_NEAR(progress.back().coverage_left(), report.coverage_union_left(), 0.15);
  std::cout << report.text() << "\n";
  EXPECT_TRUE(report.passed()) << report.text();
  EXPECT_TRUE(report.applied());
  // Which frames the capture takes depends on when the pipeline gets to them. Under a sanitizer's
  // slower pipeline one set of poses gave f = 707.3 px (1.04 %); the normal run holds it to 1 %.
  const double tolerance = testing::kSanitized ? 0.02 : 0.01;
  EXPECT_NEAR(report.f_px(), kF, tolerance * kF);
  EXPECT_NEAR(report.baseline_m(), kB, tolerance * kB);
  EXPECT_EQ(ActiveCalibrationId(), report.calibration_id());
}

TEST_F(CalibrationServiceTest, BadInputIsRefusedAndTheActiveCalibrationStays) {
  v1::CalibrationReport report;
  // Undecodable bytes everywhere: no board anywhere.
  v1::ImagePair garbage;
  garbage.set_left("not an image");
  garbage.set_right(std::string(100, '\xff'));
  grpc::Status status = client_->Calibrate(Board(true), {garbage, garbage}, &report);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << status.error_message();

  // A wrong board size: the error says to check it.
  v1::CalibrationSettings wrong = Board(true);
  wrong.mutable_board()->set_columns(8);
  wrong.mutable_board()->set_rows(5);
  status = client_->Calibrate(wrong, RenderedPairs(4), &report);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_THAT(status.error_message(), HasSubstr("board size"));

  // An image whose header announces more than 4096 pixels a side is refused without decoding.
  std::vector<v1::ImagePair> huge = RenderedPairs(1);
  huge[0].set_left(Png(cv::Mat1b(8, 5000, uchar{0})));
  status = client_->Calibrate(Board(true), huge, &report);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << status.error_message();

  // A bad setting is named.
  v1::CalibrationSettings bad = Board(true);
  bad.mutable_board()->set_square_m(-1);
  status = client_->Calibrate(bad, RenderedPairs(1), &report);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_THAT(status.error_message(), HasSubstr("settings.board.square_m"));

  // Left and right of different sizes: the pair is rejected with the reason, the others used.
  std::vector<v1::ImagePair> pairs = RenderedPairs(12);
  pairs[3].set_right(Png(cv::Mat1b(240, 320, uchar{128})));
  v1::CalibrationSettings strict = Board(true);
  strict.mutable_gates()->set_max_rms_px(1e-6);  // no calibration passes this
  status = client_->Calibrate(strict, pairs, &report);
  ASSERT_TRUE(status.ok()) << status.error_message();
  EXPECT_FALSE(report.passed());
  EXPECT_FALSE(report.applied());
  EXPECT_EQ(report.pairs_used(), 11);
  bool found_mismatch = false;
  for (const v1::PairResult& p : report.pairs()) {
    if (!p.used()) {
      EXPECT_THAT(p.rejected_reason(), HasSubstr("size_mismatch"));
      found_mismatch = true;
    }
  }
  EXPECT_TRUE(found_mismatch);
  ASSERT_EQ(report.failures_size(), 1);
  EXPECT_THAT(report.failures(0), HasSubstr("max_rms_px"));

  // The failed calibration is stored but cannot be activated.
  v1::CalibrationRecord record;
  status = client_->ActivateCalibration(report.calibration_id(), &record);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_EQ(client_->ActivateCalibration("cal-000099", &record).error_code(),
            grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(client_->ActivateCalibration("yesterday's", &record).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);

  // Through all of it the source's own calibration stayed active.
  EXPECT_EQ(ActiveCalibrationId(), "synthetic");
  v1::ListCalibrationsResponse list;
  ASSERT_TRUE(client_->ListCalibrations(&list).ok());
  EXPECT_EQ(list.calibrations_size(), 1);
  EXPECT_EQ(list.active_id(), "");

  // A capture with an out-of-range request is refused before any work.
  v1::CaptureCalibrationRequest capture;
  *capture.mutable_settings() = Board(true);
  capture.set_pairs(1000);
  status = client_->CaptureCalibration(capture, [](const v1::CaptureProgress&) {});
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_THAT(status.error_message(), HasSubstr("pairs"));
}

TEST_F(CalibrationServiceTest, TooManyPairsIsResourceExhausted) {
  v1::ImagePair tiny;
  tiny.set_left(Png(cv::Mat1b(8, 8, uchar{0})));
  tiny.set_right(tiny.left());
  const std::vector<v1::ImagePair> pairs(kMaxCalibrationPairs + 1, tiny);
  v1::CalibrationReport report;
  const grpc::Status status = client_->Calibrate(Board(true), pairs, &report);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
}

// Deadlines are honoured: a Calibrate whose deadline passes while it waits behind other work
// (a capture holding the single calibration worker) fails with DEADLINE_EXCEEDED at its deadline,
// and the server then neither stores nor applies it: what the client was told stays true.
TEST_F(CalibrationServiceTest, ACalibrationWhoseDeadlinePassedIsNeitherStoredNorApplied) {
  v1::ListCalibrationsResponse before;
  ASSERT_TRUE(client_->ListCalibrations(&before).ok());
  const std::vector<v1::ImagePair> pairs = RenderedPairs(8);

  // A capture of 8 pairs 0.3 s apart keeps the worker busy for about 2.5 s.
  v1::CaptureCalibrationRequest capture;
  *capture.mutable_settings() = Board(/*apply=*/false);
  capture.set_pairs(8);
  capture.set_interval_s(0.3);
  std::mutex mu;
  std::condition_variable cv;
  bool capturing = false;
  grpc::Status capture_status;
  std::unique_ptr<client::Client> capturer = std::make_unique<client::Client>(client_->options());
  std::thread capture_thread([&] {
    capture_status = capturer->CaptureCalibration(capture, [&](const v1::CaptureProgress& p) {
      if (!p.has_pair()) return;
      {
        std::lock_guard lock(mu);
        capturing = true;
      }
      cv.notify_all();
    });
    std::lock_guard lock(mu);
    capturing = true;  // also when it failed: never leave the wait below hanging
    cv.notify_all();
  });
  {
    std::unique_lock lock(mu);
    ASSERT_TRUE(cv.wait_for(lock, std::chrono::seconds(30), [&] { return capturing; }));
  }

  const auto start = std::chrono::steady_clock::now();
  v1::CalibrationReport late;
  const grpc::Status expired =
      client_->Calibrate(Board(/*apply=*/true), pairs, &late, std::chrono::milliseconds(400));
  const double waited_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  capture_thread.join();
  ASSERT_TRUE(capture_status.ok()) << capture_status.error_message();
  EXPECT_EQ(expired.error_code(), grpc::StatusCode::DEADLINE_EXCEEDED) << expired.error_message();
  EXPECT_LT(waited_s, 2.0) << "the client waited past its deadline";

  // The worker takes jobs in order: once this call returns, the expired one has been dealt with.
  v1::CalibrationReport next;
  const grpc::Status done = client_->Calibrate(Board(/*apply=*/false), pairs, &next);
  ASSERT_TRUE(done.ok()) << done.error_message();
  v1::ListCalibrationsResponse after;
  ASSERT_TRUE(client_->ListCalibrations(&after).ok());
  // The capture's calibration and the last one; none from the expired call.
  EXPECT_EQ(after.calibrations_size(), before.calibrations_size() + 2);
  EXPECT_EQ(ActiveCalibrationId(), "synthetic") << "the expired call's apply=true was applied";
  std::printf(
      "deadline: the expired Calibrate returned after %.2f s; %d calibrations stored "
      "before, %d after the capture and one more call\n",
      waited_s, before.calibrations_size(), after.calibrations_size());
}

// max_message_bytes bounds every received message: a larger upload is RESOURCE_EXHAUSTED, and
// a smaller one in the same server still works.
TEST(CalibrationLimits, AMessageOverMaxMessageBytesIsResourceExhausted) {
  v1::ServerConfig config = ChessboardConfig(testing::MakeTempDir("stevi-max-message"));
  config.set_max_message_bytes(64u << 10);  // the smallest allowed
  Result<std::unique_ptr<Server>> server = Server::Start(config);
  ASSERT_TRUE(server.ok()) << server.error().message;
  client::ClientOptions options;
  options.address = "127.0.0.1:" + std::to_string((*server)->port());
  client::Client client(options);

  // Noise does not compress: two 640x480 PNGs of about 300 kB each in one message.
  cv::Mat1b noise(480, 640);
  cv::randu(noise, 0, 256);
  v1::ImagePair big;
  big.set_left(Png(noise));
  big.set_right(big.left());
  ASSERT_GT(big.ByteSizeLong(), 64u << 10);
  v1::CalibrationReport report;
  const grpc::Status refused = client.Calibrate(Board(false), {big}, &report);
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << refused.error_message();

  // A message under the limit goes through (and is judged on its content: no board in it).
  v1::ImagePair small;
  small.set_left(Png(cv::Mat1b(48, 64, uchar{128})));
  small.set_right(small.left());
  const grpc::Status judged = client.Calibrate(Board(false), {small}, &report);
  EXPECT_EQ(judged.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << judged.error_message();
  v1::GetStatusResponse status;
  EXPECT_TRUE(client.GetStatus(&status).ok());
  std::printf("max message: %zu-byte message refused with %s (\"%s\") at a limit of %u\n",
              big.ByteSizeLong(), client::StatusCodeName(refused.error_code()).c_str(),
              refused.error_message().c_str(), config.max_message_bytes());
}

}  // namespace
}  // namespace stevi::server
