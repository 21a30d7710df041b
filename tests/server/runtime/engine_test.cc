#include "server/runtime/engine.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <condition_variable>
#include <future>
#include <mutex>

#include "tests/server/flaky_source.h"
#include "tests/testing/sanitized.h"

namespace stevi::server {
namespace {

using test_support::FlakySource;
using ::testing::HasSubstr;

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
  bool WaitForCount(size_t n) {
    std::unique_lock lock(mu);
    return cv.wait_for(lock, std::chrono::seconds(60), [&] { return results.size() >= n; });
  }
  bool WaitForSourceIndex(int64_t index) {
    std::unique_lock lock(mu);
    return cv.wait_for(lock, std::chrono::seconds(60),
                       [&] { return !results.empty() && results.back()->source_index == index; });
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

// Every frame the source delivers reaches the capture tap, in order, including those the pipeline
// never takes (latest wins); a tap changed while running takes over from the next frame.
TEST(Engine, TheCaptureTapSeesEveryFrameAndCanBeChangedWhileRunning) {
  constexpr int kFrames = 60;
  auto source = std::make_unique<FlakySource>(0, kFrames, 200);
  const std::shared_future<void> ended = source->Ended();
  Result<std::unique_ptr<Engine>> engine =
      Engine::Create(std::move(source), pipeline::PipelineConfig{}, nullptr);
  ASSERT_TRUE(engine.ok()) << engine.error().message;
  std::mutex mu;
  std::condition_variable cv;
  std::vector<int64_t> first, second;  // source indices each tap saw
  (*engine)->SetCaptureTap([&](const StereoFrame& f) {
    std::lock_guard lock(mu);
    first.push_back(f.index);
    cv.notify_all();
  });
  (*engine)->Start();
  {
    std::unique_lock lock(mu);
    ASSERT_TRUE(cv.wait_for(lock, std::chrono::seconds(60), [&] { return first.size() >= 10; }));
  }
  (*engine)->SetCaptureTap([&](const StereoFrame& f) {
    std::lock_guard lock(mu);
    second.push_back(f.index);
  });
  ASSERT_EQ(ended.wait_for(std::chrono::seconds(60)), std::future_status::ready);
  (*engine)->Stop();
  std::lock_guard lock(mu);
  ASSERT_FALSE(second.empty()) << "the new tap saw nothing";
  std::vector<int64_t> all = first;
  all.insert(all.end(), second.begin(), second.end());
  ASSERT_EQ(all.size(), static_cast<size_t>(kFrames)) << "each frame reaches exactly one tap";
  for (int i = 0; i < kFrames; ++i) EXPECT_EQ(all[i], i);
  const EngineStatus status = (*engine)->Status();
  EXPECT_EQ(status.frames_captured, static_cast<uint64_t>(kFrames));
}

// SetRig() mid-run: once a frame is processed with the new rig, every later frame is, and its
// ranges follow the new rig's geometry (a doubled baseline doubles every depth for a disparity).
TEST(Engine, ARigSwappedMidRunRangesEveryLaterFrame) {
  // Enough frames that 10 reach the sink after the swap, also where more are dropped.
  constexpr int kFrames = testing::kSanitized ? 400 : 40;
  Collector collector;
  auto source = std::make_unique<FlakySource>(0, kFrames, 100);
  const std::shared_future<void> ended = source->Ended();
  const std::shared_ptr<const geometry::StereoRig> old_rig = source->Rig();
  Result<std::unique_ptr<Engine>> engine =
      Engine::Create(std::move(source), pipeline::PipelineConfig{}, collector.Sink());
  ASSERT_TRUE(engine.ok()) << engine.error().message;
  (*engine)->Start();
  ASSERT_TRUE(collector.WaitForCount(5));
  const auto doubled = std::make_shared<const geometry::StereoRig>(
      geometry::StereoRig::Ideal(old_rig->image_size(), old_rig->f_px(), 2 * old_rig->baseline_m(),
                                 old_rig->cx(), old_rig->cy(), "doubled"));
  (*engine)->SetRig(doubled);
  EXPECT_EQ((*engine)->rig(), doubled);
  ASSERT_TRUE(collector.WaitForSourceIndex(kFrames - 1));
  ASSERT_EQ(ended.wait_for(std::chrono::seconds(60)), std::future_status::ready);
  (*engine)->Stop();

  std::lock_guard lock(collector.mu);
  bool swapped = false;
  int with_new = 0, detections_checked = 0;
  for (const auto& r : collector.results) {
    ASSERT_NE(r->rig, nullptr);
    if (r->rig->calibration_id() == "doubled") {
      swapped = true;
      ++with_new;
    } else {
      EXPECT_FALSE(swapped) << "frame " << r->source_index << " went back to the old rig";
    }
    const double fb = r->rig->f_px() * r->rig->baseline_m();
    for (const detection::Detection& d : r->detections) {
      EXPECT_NEAR(d.depth_m, fb / d.disparity_px, 1e-6 * d.depth_m) << "frame " << r->source_index;
      ++detections_checked;
    }
  }
  EXPECT_GE(with_new, 10);
  EXPECT_GT(detections_checked, 0);
}

// Frames are worked on by several workers at once and finish out of order: the source runs at
// 400 fps, faster than a frame is processed, so several are in flight, and a frame of noise takes
// longer than a flat one (stevi-bench-stages' BM_Extract on such frames; no timing is asserted
// here). The sink still gets them in the order they were captured, with consecutive frame ids.
class AlternatingSource : public drivers::StereoSource {
 public:
  explicit AlternatingSource(int frames) : frames_(frames) {
    rig_ = std::make_shared<const geometry::StereoRig>(
        geometry::StereoRig::Ideal(cv::Size(320, 240), 350, 0.6, 160, 120));
    noise_ = cv::Mat1b(240, 320);
    cv::RNG rng(7);
    rng.fill(noise_, cv::RNG::UNIFORM, 0, 256);
    flat_ = cv::Mat1b(240, 320, uchar{128});
  }
  std::string Describe() const override { return "alternating"; }
  std::shared_ptr<const geometry::StereoRig> Rig() const override { return rig_; }
  double NominalFps() const override { return 400; }
  Result<StereoFrame> Next() override {
    if (next_ >= frames_) return OutOfRange("end");
    StereoFrame f;
    f.index = next_;
    f.t_ns = int64_t{next_} * 2'500'000;
    f.rectified = true;
    // Two of every three frames are noise (slow), the third is flat (fast).
    const cv::Mat1b& image = next_ % 3 == 2 ? flat_ : noise_;
    f.left = image;
    f.right = image;
    ++next_;
    return f;
  }

 private:
  int frames_, next_ = 0;
  std::shared_ptr<const geometry::StereoRig> rig_;
  cv::Mat1b noise_, flat_;
};

TEST(Engine, FramesThatFinishOutOfOrderReachTheSinkInCaptureOrder) {
  constexpr int kFrames = testing::kSanitized ? 900 : 90;
  Collector collector;
  pipeline::PipelineConfig config;
  config.algorithm = pipeline::Algorithm::kSteViE;
  Result<std::unique_ptr<Engine>> engine =
      Engine::Create(std::make_unique<AlternatingSource>(kFrames), config, collector.Sink());
  ASSERT_TRUE(engine.ok()) << engine.error().message;
  (*engine)->Start(/*workers=*/4);
  ASSERT_TRUE(collector.WaitForSourceIndex(kFrames - 1));
  (*engine)->Stop();
  std::lock_guard lock(collector.mu);
  ASSERT_GE(collector.results.size(), 10u);
  for (size_t i = 0; i < collector.results.size(); ++i) {
    const pipeline::FrameResult& r = *collector.results[i];
    EXPECT_EQ(r.frame_id, i + 1);
    if (i > 0) {
      EXPECT_GT(r.source_index, collector.results[i - 1]->source_index);
    }
  }
  const EngineStatus status = (*engine)->Status();
  EXPECT_EQ(status.workers, 4u);
  EXPECT_EQ(status.frames_processed + status.frames_dropped_capture + status.frames_failed,
            status.frames_captured);
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
