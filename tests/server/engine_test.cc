#include "server/engine.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <condition_variable>
#include <future>
#include <mutex>

#include "drivers/synthetic/synthetic_source.h"
#include "server/service.h"

namespace stevi::server {
namespace {

using ::testing::HasSubstr;

// A source that fails `failures` times (camera down), then renders `frames` synthetic frames,
// then ends: the engine's retry, accounting and end-of-stream paths on a real renderer.
class FlakySource : public drivers::StereoSource {
 public:
  FlakySource(int failures, int frames) : failures_(failures), frames_(frames) {
    drivers::SyntheticOptions options;
    options.width = 320;
    options.height = 240;
    options.f_px = 350;
    renderer_ = std::make_unique<drivers::SyntheticRenderer>(options);
    rig_ = std::make_shared<const geometry::StereoRig>(renderer_->Rig());
  }
  std::string Describe() const override { return "flaky synthetic"; }
  std::shared_ptr<const geometry::StereoRig> Rig() const override { return rig_; }
  double NominalFps() const override { return 0; }  // as fast as it can
  Result<StereoFrame> Next() override {
    if (failures_ > 0) {
      --failures_;
      return Error{ErrorCode::kUnavailable, "camera unplugged"};
    }
    if (next_ >= frames_) {
      if (!ended_told_) ended_.set_value();  // the capture thread marks the source ENDED next
      ended_told_ = true;
      return Error{ErrorCode::kOutOfRange, "end of the recording"};
    }
    return renderer_->Render(next_++);
  }

  // Ready once Next() has said the recording ended.
  std::shared_future<void> Ended() const { return ended_future_; }

 private:
  std::promise<void> ended_;
  std::shared_future<void> ended_future_ = ended_.get_future().share();
  bool ended_told_ = false;
  int failures_, frames_, next_ = 0;
  std::unique_ptr<drivers::SyntheticRenderer> renderer_;
  std::shared_ptr<const geometry::StereoRig> rig_;
};

struct Collector {
  std::mutex mu;
  std::condition_variable cv;
  std::vector<std::shared_ptr<const pipeline::FrameResult>> results;

  Engine::Sink Sink() {
    return [this](const std::shared_ptr<const pipeline::FrameResult>& r) {
      std::lock_guard lock(mu);
      results.push_back(r);
      cv.notify_all();
    };
  }
  bool WaitForSourceIndex(int64_t index) {
    std::unique_lock lock(mu);
    return cv.wait_for(lock, std::chrono::seconds(60), [&] {
      return !results.empty() && results.back()->source_index == index;
    });
  }
};

TEST(Engine, RecoversFromADownSourceAndAccountsForEveryFrame) {
  constexpr int kFrames = 40;
  Collector collector;
  auto source = std::make_unique<FlakySource>(2, kFrames);
  const std::shared_future<void> ended = source->Ended();
  Result<std::unique_ptr<Engine>> engine =
      Engine::Create(std::move(source), pipeline::PipelineConfig{}, collector.Sink());
  ASSERT_TRUE(engine.ok()) << engine.error().message;
  (*engine)->Start();
  // The last frame is never replaced, so the pipeline always gets it.
  ASSERT_TRUE(collector.WaitForSourceIndex(kFrames - 1));
  // The source said it ended; Stop() joins the capture thread, which marks it ENDED first (the
  // last frame can be processed before the capture thread asks for the next one).
  ASSERT_EQ(ended.wait_for(std::chrono::seconds(60)), std::future_status::ready);
  (*engine)->Stop();

  const EngineStatus status = (*engine)->Status();
  EXPECT_EQ(status.source_state, SourceState::kEnded);
  EXPECT_THAT(status.source_error, HasSubstr("end of the recording"));
  EXPECT_EQ(status.frames_captured, static_cast<uint64_t>(kFrames));
  // Latest wins: every captured frame was either processed or replaced in the mailbox.
  EXPECT_EQ(status.frames_processed + status.frames_dropped_capture, status.frames_captured);
  EXPECT_EQ(status.frames_processed, collector.results.size());
  for (size_t i = 0; i < collector.results.size(); ++i) {
    EXPECT_EQ(collector.results[i]->frame_id, i + 1) << "frame ids have no gaps";
    if (i > 0) {
      EXPECT_GT(collector.results[i]->source_index, collector.results[i - 1]->source_index);
    }
  }
  EXPECT_EQ(status.source, "flaky synthetic");
  ASSERT_FALSE(status.mean_timings.empty());
  EXPECT_EQ(status.mean_timings.back().stage, "total");
}

TEST(Engine, RefusesAnInvalidConfigNamingIt) {
  pipeline::PipelineConfig config;
  config.matcher.block_matching.num_disparities = 20;
  Result<std::unique_ptr<Engine>> engine =
      Engine::Create(std::make_unique<FlakySource>(0, 1), config, nullptr);
  ASSERT_FALSE(engine.ok());
  EXPECT_THAT(engine.error().message, HasSubstr("matcher.block_matching.num_disparities"));
}

TEST(GetDisparitySnapshotImpl, FailedPreconditionBeforeTheFirstFrame) {
  Result<std::unique_ptr<Engine>> engine = Engine::Create(std::make_unique<FlakySource>(0, 1),
                                                          pipeline::PipelineConfig{}, nullptr);
  ASSERT_TRUE(engine.ok());
  v1::DisparitySnapshot snapshot;
  const grpc::Status status =
      GetDisparitySnapshotImpl(**engine, v1::GetDisparitySnapshotRequest(), &snapshot);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_THAT(status.error_message(), HasSubstr("no frame"));
}

TEST(SetPipelineConfigImpl, MergesValidatesAndKeepsTheActiveOnError) {
  Result<std::unique_ptr<Engine>> engine = Engine::Create(std::make_unique<FlakySource>(0, 1),
                                                          pipeline::PipelineConfig{}, nullptr);
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
