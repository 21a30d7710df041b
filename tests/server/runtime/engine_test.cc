#include "server/runtime/engine.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <condition_variable>
#include <future>
#include <mutex>

#include "tests/server/flaky_source.h"

namespace stevi::server {
namespace {

using ::testing::HasSubstr;
using test_support::FlakySource;

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

}  // namespace
}  // namespace stevi::server
