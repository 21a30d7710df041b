// stevi-server on two real GigE Vision peers (Aravis's fake cameras, run by the test in a private
// network namespace: tests/drivers/fake_camera_netns.sh): tracks stream with the pair skew, the
// status shows the pairing counters, and a camera that dies and comes back leaves the server up,
// its streams open, and resumes.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <optional>
#include <string>

#include "core/geometry/calibration_io.h"
#include <grpcpp/grpcpp.h>

#include "grpc/health/v1/health.grpc.pb.h"
#include "stevi/v1/obstacle_service.pb.h"
#include "tests/server/server_process.h"
#include "tests/testing/sanitized.h"
#include "tests/testing/fake_gv_camera.h"

namespace stevi {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;
using testing::ParseJsonLines;
using Clock = std::chrono::steady_clock;

// grpc.health.v1 Check of the obstacle service (what a load balancer or a watchdog asks), or
// nothing when the server does not answer.
std::optional<grpc::health::v1::HealthCheckResponse::ServingStatus> Health(
    const std::string& address) {
  auto stub = grpc::health::v1::Health::NewStub(
      grpc::CreateChannel(address, grpc::InsecureChannelCredentials()));
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
  grpc::health::v1::HealthCheckRequest request;
  request.set_service("stevi.v1.ObstacleService");
  grpc::health::v1::HealthCheckResponse response;
  const grpc::Status status = stub->Check(&context, request, &response);
  EXPECT_TRUE(status.ok()) << status.error_message();
  if (!status.ok()) return std::nullopt;
  return response.status();
}

// Waits (a bounded number of checks, each a round trip) until the health is `want`. A server
// that stops answering ends the wait at once.
bool HealthBecomes(const std::string& address,
                   grpc::health::v1::HealthCheckResponse::ServingStatus want) {
  for (int i = 0; i < 2000; ++i) {
    const auto health = Health(address);
    if (!health) return false;
    if (*health == want) return true;
  }
  return false;
}

v1::GetStatusResponse Status(const testing::ServerProcess& server) {
  const testing::RunResult r = server.Stevi({"status", "--json"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  const std::vector<v1::GetStatusResponse> s = ParseJsonLines<v1::GetStatusResponse>(r.out);
  return s.empty() ? v1::GetStatusResponse() : s[0];
}

class AravisServerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_NO_FATAL_FAILURE(testing::ExpectFakeCameraNetwork());
    dir_ = testing::MakeTempDir("stevi-aravis-server");
    left_ = std::make_unique<testing::FakeGvCamera>("127.0.0.1", "GV01", dir_ + "/GV01.log");
    right_ = std::make_unique<testing::FakeGvCamera>("127.0.0.2", "GV02", dir_ + "/GV02.log");
    ASSERT_NO_FATAL_FAILURE(left_->Start());
    ASSERT_NO_FATAL_FAILURE(right_->Start());
    ASSERT_NO_FATAL_FAILURE(
        testing::WaitDiscoverable({left_->id(), right_->id()}, {left_.get(), right_.get()}));
    // An ideal 640x480 rig for the cameras' region of interest (the fake cameras see a ramp, not
    // a scene: the test is about frames, pairing and faults, not about obstacles).
    calibration_ = dir_ + "/rig.yaml";
    ASSERT_TRUE(
        geometry::SaveCalibrationYaml(
            geometry::IdealCalibration(cv::Size(640, 480), 600, 0.12, 320, 240), calibration_)
            .ok());
    // The left camera by serial number, the right one by address.
    ASSERT_NO_FATAL_FAILURE(server_.Start({"--source", "aravis", "--left", "GV01", "--right",
                                           "127.0.0.2", "--calibration", calibration_, "--fps",
                                           "30", "--exposure-us", "10000", "--gain-db", "0"}));
  }

  std::string dir_, calibration_;
  std::unique_ptr<testing::FakeGvCamera> left_, right_;
  testing::ServerProcess server_;
};

TEST_F(AravisServerTest, StreamsPairedFramesWithSkewAndCountersInStatus) {
  const testing::RunResult watch = server_.Stevi({"watch", "--count", "40", "--json"});
  ASSERT_EQ(watch.exit_code, 0) << watch.err;
  const std::vector<v1::TrackFrame> frames = ParseJsonLines<v1::TrackFrame>(watch.out);
  ASSERT_EQ(frames.size(), 40u);
  const int64_t tolerance_ns = 1'000'000'000 / 30 / 2;  // half a frame period
  int64_t max_skew = 0;
  for (size_t i = 0; i < frames.size(); ++i) {
    EXPECT_LE(std::llabs(frames[i].pair_skew_ns()), tolerance_ns);
    max_skew = std::max<int64_t>(max_skew, std::llabs(frames[i].pair_skew_ns()));
    EXPECT_EQ(frames[i].calibration_id(), "rig");
    if (i > 0) {
      EXPECT_GT(frames[i].capture_time_ns(), frames[i - 1].capture_time_ns());
    }
  }
  const v1::GetStatusResponse status = Status(server_);
  EXPECT_EQ(status.source_state(), v1::SOURCE_STATE_RUNNING);
  EXPECT_THAT(status.source(), HasSubstr("aravis Aravis-Fake-GV01 + Aravis-Fake-GV02 640x480"));
  EXPECT_GE(status.pairing().pairs(), 40u);
  // The pairing of what the cameras deliver is asserted at the driver (aravis_source_test);
  // through the whole server, on two cores shared with other tests, the bound is looser (30 alone,
  // 17 seen under a 32-client load test running beside it).
  EXPECT_GE(status.fps_in(), 12.0) << "two cameras at 30 fps";
  EXPECT_LE(status.pairing().max_abs_skew_ns(), tolerance_ns);
  EXPECT_GT(status.pairing().mean_abs_skew_ns(), 0.0) << "two clocks never agree exactly";
  std::cout << "aravis through the server: " << status.fps_in() << " fps in, "
            << status.pairing().pairs() << " pairs, mean |skew| "
            << status.pairing().mean_abs_skew_ns() * 1e-6 << " ms, max "
            << status.pairing().max_abs_skew_ns() * 1e-6 << " ms, "
            << status.pairing().unpaired_dropped() << " unpaired and "
            << status.pairing().incomplete_dropped() << " incomplete dropped\n";
  const testing::RunResult text = server_.Stevi({"status"});
  EXPECT_THAT(text.out, HasSubstr("pairing"));
  EXPECT_THAT(text.out, HasSubstr("mean |skew|"));
}

TEST_F(AravisServerTest, ALostCameraLeavesTheServerUpAndStreamsResume) {
  ASSERT_EQ(server_.Stevi({"watch", "--count", "5"}).exit_code, 0);
  EXPECT_TRUE(HealthBecomes(server_.address(), grpc::health::v1::HealthCheckResponse::SERVING));
  // A stream opened before the fault must live through it: its first frame comes before the kill,
  // and the rest of its count (at most a few more are in flight at the kill) after the camera is
  // back. The instrumented server gives under 2 fps, so a sanitizer counts fewer.
  const int count = testing::kSanitized ? 15 : 60;
  testing::Subprocess watch({testing::BinaryPath("stevi"), "--server", server_.address(),
                             "--timeout", "60", "watch", "--json", "--count",
                             std::to_string(count)});
  ASSERT_TRUE(watch.WaitForStdoutLine("\"frame_id\"", std::chrono::seconds(60)))
      << watch.DrainStderr();
  left_->Kill();
  v1::GetStatusResponse status = Status(server_);
  for (int i = 0; i < 300 && status.source_state() != v1::SOURCE_STATE_DOWN; ++i) {
    status = Status(server_);
  }
  ASSERT_EQ(status.source_state(), v1::SOURCE_STATE_DOWN);
  EXPECT_THAT(status.source_error(), HasSubstr("Aravis-Fake-GV01"));
  EXPECT_TRUE(HealthBecomes(server_.address(), grpc::health::v1::HealthCheckResponse::NOT_SERVING))
      << "a camera down is NOT_SERVING";
  const testing::RunResult snapshot = server_.Stevi({"snapshot", "--out", dir_ + "/snap"});
  EXPECT_EQ(snapshot.exit_code, 1);
  EXPECT_THAT(snapshot.err, HasSubstr("UNAVAILABLE"));

  const auto restarted = Clock::now();
  ASSERT_NO_FATAL_FAILURE(left_->Start());
  for (int i = 0; i < 600 && status.source_state() != v1::SOURCE_STATE_RUNNING; ++i) {
    status = Status(server_);
  }
  const double recovery_s = std::chrono::duration<double>(Clock::now() - restarted).count();
  std::cout << "recovery after the camera restarted: " << recovery_s << " s\n";
  ASSERT_EQ(status.source_state(), v1::SOURCE_STATE_RUNNING);
  // Uninstrumented, the reopening takes about 1-2 s (backoff 250 ms doubling to 1 s, plus Aravis's
  // own timeouts); a sanitizer slows the control traffic several times over.
  EXPECT_LT(recovery_s, testing::kSanitized ? 20.0 : 5.0);
  EXPECT_GE(status.pairing().reconnects(), 1u);
  EXPECT_TRUE(HealthBecomes(server_.address(), grpc::health::v1::HealthCheckResponse::SERVING));
  const std::optional<int> watched =
      watch.Wait(std::chrono::seconds(testing::kSanitized ? 120 : 30));
  const std::string watch_err = watch.DrainStderr();
  EXPECT_EQ(watched, 0) << watch_err;
  // The client would reconnect a stream the server ended, so its exit alone does not show that the
  // server kept the stream open through the fault.
  EXPECT_THAT(watch_err, Not(HasSubstr("stream lost"))) << "the server ended the stream";
}

TEST(AravisServer, AnUnknownCameraIsAClearStartError) {
  ASSERT_NO_FATAL_FAILURE(testing::ExpectFakeCameraNetwork());
  const std::string dir = testing::MakeTempDir("stevi-aravis-unknown");
  testing::FakeGvCamera left("127.0.0.1", "GV01", dir + "/GV01.log");
  ASSERT_NO_FATAL_FAILURE(left.Start());
  ASSERT_NO_FATAL_FAILURE(testing::WaitDiscoverable({left.id()}, {&left}));
  const testing::RunResult r =
      testing::Run({testing::BinaryPath("stevi-server"), "--listen", "127.0.0.1:0", "--data-dir",
                    dir + "/data", "--source", "aravis", "--left", "GV01", "--right", "GV77"},
                   testing::kCommandTimeout);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.err, HasSubstr("GV77"));
  EXPECT_THAT(r.err, HasSubstr("not found"));
  EXPECT_THAT(r.err, HasSubstr("Aravis-Fake-GV01")) << "lists the cameras that are there";
}

}  // namespace
}  // namespace stevi
