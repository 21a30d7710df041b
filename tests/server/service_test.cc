// The services' logic apart from gRPC's transport (server/service.h): the *Impl functions on a real
// engine.
#include "server/service.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <mutex>

#include "tests/server/flaky_source.h"

namespace stevi::server {
namespace {

using test_support::FlakySource;
using ::testing::HasSubstr;

TEST(GetDisparitySnapshotImpl, FailedPreconditionBeforeTheFirstFrame) {
  Result<std::unique_ptr<Engine>> engine =
      Engine::Create(std::make_unique<FlakySource>(0, 1), pipeline::PipelineConfig{}, nullptr);
  ASSERT_TRUE(engine.ok());
  v1::DisparitySnapshot snapshot;
  const grpc::Status status =
      GetDisparitySnapshotImpl(**engine, v1::GetDisparitySnapshotRequest(), &snapshot);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_THAT(status.error_message(), HasSubstr("no frame"));
}

TEST(SetPipelineConfigImpl, MergesValidatesAndKeepsTheActiveOnError) {
  Result<std::unique_ptr<Engine>> engine =
      Engine::Create(std::make_unique<FlakySource>(0, 1), pipeline::PipelineConfig{}, nullptr);
  ASSERT_TRUE(engine.ok());
  std::mutex mu;
  v1::SetPipelineConfigRequest request;
  request.mutable_config()->mutable_canonical()->mutable_blobs()->set_min_area_px(0);
  request.mutable_config()->mutable_range()->set_disparity_sigma_px(-1);
  v1::PipelineConfig active;
  const grpc::Status refused = SetPipelineConfigImpl(**engine, mu, request, &active);
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_THAT(refused.error_message(), HasSubstr("canonical.blobs.min_area_px"));
  EXPECT_THAT(refused.error_message(), HasSubstr("range.disparity_sigma_px"));
  EXPECT_EQ((*engine)->config().Get()->canonical.blobs.min_area_px,
            detection::StereoBlobOptions().min_area_px);

  request.Clear();
  request.mutable_config()->mutable_canonical()->mutable_blobs()->set_min_area_px(150);
  ASSERT_TRUE(SetPipelineConfigImpl(**engine, mu, request, &active).ok());
  EXPECT_EQ(active.canonical().blobs().min_area_px(), 150);
  EXPECT_EQ((*engine)->config().Get()->canonical.blobs.min_area_px, 150);
}

}  // namespace
}  // namespace stevi::server
