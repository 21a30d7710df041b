// The preview hub without gRPC: frames from the real pipeline on the synthetic scene, handed over
// one at a time (Offer, then WaitIdle: the hub's own "done" event, never a sleep).
#include "server/runtime/preview_hub.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <map>
#include <optional>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/pipeline/annotate.h"
#include "core/stereo/disparity.h"
#include "drivers/synthetic/synthetic_source.h"

namespace stevi::server {
namespace {

using ::testing::HasSubstr;

constexpr auto kWait = std::chrono::seconds(30);

// A processed frame of the demo scene with confirmed tracks (the pipeline's own output), made once.
const pipeline::FrameResult& ProcessedFrame() {
  static const pipeline::FrameResult frame = [] {
    drivers::SyntheticRenderer renderer{drivers::SyntheticOptions{}};
    const auto rig = std::make_shared<const geometry::StereoRig>(renderer.Rig());
    pipeline::ConfigStore store;
    pipeline::Pipeline pipeline;
    pipeline::FrameResult last;
    for (int64_t index = 0; index < 8; ++index) {
      Result<pipeline::FrameResult> result =
          pipeline.Process(renderer.Render(index), pipeline::Snapshot{store.Get(), rig});
      if (result.ok()) last = std::move(result).value();
    }
    return last;
  }();
  return frame;
}

// The processed frame again as frame `id` captured at `t_ns` (the images are shared, not copied).
std::shared_ptr<const pipeline::FrameResult> FrameAt(uint64_t id, int64_t t_ns) {
  auto frame = std::make_shared<pipeline::FrameResult>(ProcessedFrame());
  frame->frame_id = id;
  frame->capture_time_ns = t_ns;
  frame->capture_unix_time_ns = 1'700'000'000'000'000'000 + t_ns;
  return frame;
}

// Hands frame `id` of a `fps` sequence to the hub and waits until the hub has handled it.
void Feed(PreviewHub& hub, uint64_t id, double fps) {
  hub.Offer(FrameAt(id, static_cast<int64_t>(std::llround(static_cast<double>(id) * 1e9 / fps))));
  ASSERT_TRUE(hub.WaitIdle(kWait));
}

PreviewRequest Request(std::vector<PreviewKind> kinds, double rate_hz = 30, int max_width = 640,
                       int quality = 80) {
  PreviewRequest r;
  r.kinds = std::move(kinds);
  r.rate_hz = rate_hz;
  r.max_width_px = max_width;
  r.jpeg_quality = quality;
  return r;
}

// Everything queued for `sub` now.
std::vector<PreviewPtr> Drain(PreviewSubscription& sub) {
  std::vector<PreviewPtr> out;
  while (true) {
    PreviewSubscription::Popped p = sub.Pop();
    if (p.state != PreviewSubscription::PopState::kItem) return out;
    out.push_back(*p.item);
  }
}

cv::Mat Decode(const Preview& p) {
  return cv::imdecode(std::vector<uchar>(p.jpeg.begin(), p.jpeg.end()), cv::IMREAD_UNCHANGED);
}

// Peak signal-to-noise ratio of `a` against `b` (same size and type), dB.
double Psnr(const cv::Mat& a, const cv::Mat& b) {
  const double mse =
      std::pow(cv::norm(a, b, cv::NORM_L2), 2) / static_cast<double>(a.total()) / a.channels();
  return mse == 0 ? 99.0 : 10.0 * std::log10(255.0 * 255.0 / mse);
}

// The mean of each 2x2 block, written out (an independent reference for a halving).
cv::Mat HalveByHand(const cv::Mat& image) {
  cv::Mat out(image.rows / 2, image.cols / 2, image.type());
  const int channels = image.channels();
  for (int y = 0; y < out.rows; ++y) {
    for (int x = 0; x < out.cols; ++x) {
      for (int c = 0; c < channels; ++c) {
        int sum = 0;
        for (int dy = 0; dy < 2; ++dy) {
          for (int dx = 0; dx < 2; ++dx) {
            sum += image.ptr<uchar>(2 * y + dy)[(2 * x + dx) * channels + c];
          }
        }
        out.ptr<uchar>(y)[x * channels + c] = static_cast<uchar>((sum + 2) / 4);
      }
    }
  }
  return out;
}

TEST(PreviewHub, EncodesNothingWithoutSubscribers) {
  PreviewHub hub;
  for (uint64_t id = 1; id <= 20; ++id) Feed(hub, id, 20);
  EXPECT_EQ(hub.stats().frames_offered, 0u) << "Offer() does nothing without subscribers";
  EXPECT_EQ(hub.stats().encodes, 0u);

  // A subscriber: encodings begin; gone again: they stop.
  std::shared_ptr<PreviewSubscription> sub =
      hub.Subscribe("viewer", Request({PreviewKind::kAnnotatedLeft}));
  ASSERT_NE(sub, nullptr);
  for (uint64_t id = 21; id <= 25; ++id) Feed(hub, id, 20);
  EXPECT_EQ(hub.stats().encodes, 5u);
  hub.Unsubscribe(sub->id());
  for (uint64_t id = 26; id <= 40; ++id) Feed(hub, id, 20);
  EXPECT_EQ(hub.stats().encodes, 5u);
  EXPECT_EQ(hub.stats().frames_offered, 5u);
}

// Six subscribers asking for three distinct things, each due on every frame: three encodings a
// frame, and the subscribers of one request share the very same preview.
TEST(PreviewHub, OneEncodingPerFramePerDistinctRequestSharedBySubscribers) {
  PreviewHubOptions options;
  options.queue_per_kind = 2;
  PreviewHub hub(options);
  std::vector<std::shared_ptr<PreviewSubscription>> same;  // annotated, 640, q 80
  for (int i = 0; i < 3; ++i) {
    same.push_back(
        hub.Subscribe("same" + std::to_string(i), Request({PreviewKind::kAnnotatedLeft})));
  }
  // Annotated and disparity at 320: the annotated one's encoding is distinct from the 640 one.
  std::shared_ptr<PreviewSubscription> both = hub.Subscribe(
      "both", Request({PreviewKind::kDisparity, PreviewKind::kAnnotatedLeft}, 30, 320));
  std::shared_ptr<PreviewSubscription> disparity =
      hub.Subscribe("disparity", Request({PreviewKind::kDisparity}, 30, 320));
  std::shared_ptr<PreviewSubscription> slower =
      hub.Subscribe("slower", Request({PreviewKind::kDisparity}, 10, 320));  // every other frame
  for (const auto& s : {same[0], same[1], same[2], both, disparity, slower}) ASSERT_NE(s, nullptr);

  constexpr uint64_t kFrames = 10;
  for (uint64_t id = 1; id <= kFrames; ++id) {
    Feed(hub, id, 20);
    std::vector<std::vector<PreviewPtr>> got;
    for (const auto& s : same) got.push_back(Drain(*s));
    const std::vector<PreviewPtr> b = Drain(*both), d = Drain(*disparity), w = Drain(*slower);
    for (const auto& g : got) {
      ASSERT_EQ(g.size(), 1u);
      EXPECT_EQ(g[0], got[0][0]) << "one encoding, shared";
      EXPECT_EQ(g[0]->frame_id, id);
      EXPECT_EQ(g[0]->kind, PreviewKind::kAnnotatedLeft);
      EXPECT_EQ(g[0]->width, 640);
    }
    ASSERT_EQ(b.size(), 2u);
    EXPECT_EQ(b[0]->kind, PreviewKind::kDisparity) << "in the order asked for";
    EXPECT_EQ(b[1]->kind, PreviewKind::kAnnotatedLeft);
    EXPECT_EQ(b[1]->width, 320);
    ASSERT_EQ(d.size(), 1u);
    EXPECT_EQ(d[0], b[0]) << "disparity at 320, q 80: the same encoding as both's";
    // 10 Hz of a 20 fps sequence: the first at once (frame 1, at 50 ms), then one per 100 ms
    // slot of capture time (the even frames).
    EXPECT_EQ(w.size(), id == 1 || id % 2 == 0 ? 1u : 0u);
    if (!w.empty()) {
      EXPECT_EQ(w[0], b[0]);
    }
    EXPECT_EQ(hub.stats().encodes, 3 * id) << "annotated 640, annotated 320, disparity 320";
  }
  for (const auto& s : {same[0], both, slower}) EXPECT_EQ(s->dropped(), 0u);
}

// The rate follows the frames' capture times: over 10 s of frames, rate x 10 previews (the first
// with the first frame), whatever the frame rate.
TEST(PreviewHub, RateIsHonouredOverAKnownNumberOfFrames) {
  for (const double fps : {30.0, 20.0, 12.5}) {
    SCOPED_TRACE("frames at " + std::to_string(fps) + " fps");
    PreviewHub hub;
    std::map<double, std::shared_ptr<PreviewSubscription>> subs;
    for (const double rate : {1.0, 2.5, 5.0, 7.0, 30.0}) {
      subs[rate] = hub.Subscribe("r", Request({PreviewKind::kLeft}, rate, 160));
    }
    std::map<double, std::vector<uint64_t>> ids;
    const uint64_t frames = static_cast<uint64_t>(std::llround(10 * fps));  // 10 s
    for (uint64_t id = 0; id < frames; ++id) {
      Feed(hub, id, fps);
      for (auto& [rate, sub] : subs) {
        for (const PreviewPtr& p : Drain(*sub)) ids[rate].push_back(p->frame_id);
      }
    }
    for (const auto& [rate, got] : ids) {
      // At most one preview a frame: 30 Hz of slower frames is every frame.
      const double expected = std::min(rate, fps) * 10;
      EXPECT_NEAR(static_cast<double>(got.size()), expected, 1.0) << rate << " Hz";
      ASSERT_FALSE(got.empty());
      EXPECT_EQ(got.front(), 0u) << "the first frame after subscribing";
      // Evenly spread: no two closer than one frame less than the period.
      for (size_t i = 1; i < got.size(); ++i) {
        EXPECT_GE(static_cast<double>(got[i] - got[i - 1]), std::floor(fps / rate)) << rate;
      }
    }
    std::printf(
        "frames at %.1f fps for 10 s: %zu, %zu, %zu, %zu, %zu previews at 1, 2.5, 5, 7, 30 Hz\n",
        fps, ids[1.0].size(), ids[2.5].size(), ids[5.0].size(), ids[7.0].size(), ids[30.0].size());
  }
}

// Subscribers at one rate, or at a multiple of it, are due on the same frames whenever they came
// (slots of capture time shared by all): their previews are the same encodings.
TEST(PreviewHub, SubscribersAtOneRateShareTheirFramesWheneverTheyCame) {
  PreviewHub hub;
  std::shared_ptr<PreviewSubscription> early =
      hub.Subscribe("early", Request({PreviewKind::kAnnotatedLeft}, 5));
  for (uint64_t id = 0; id < 10; ++id) Feed(hub, id, 20);
  Drain(*early);
  std::shared_ptr<PreviewSubscription> late =
      hub.Subscribe("late", Request({PreviewKind::kAnnotatedLeft}, 5));
  std::shared_ptr<PreviewSubscription> faster =
      hub.Subscribe("faster", Request({PreviewKind::kAnnotatedLeft}, 10));
  const uint64_t encodes_before = hub.stats().encodes;
  std::map<uint64_t, PreviewPtr> by_frame;  // the early subscriber's
  int shared = 0, late_count = 0, faster_count = 0;
  for (uint64_t id = 10; id < 110; ++id) {  // 5 s at 20 fps
    Feed(hub, id, 20);
    for (const PreviewPtr& p : Drain(*early)) by_frame[p->frame_id] = p;
    for (const PreviewPtr& p : Drain(*late)) {
      ++late_count;
      if (by_frame.count(p->frame_id) && by_frame[p->frame_id] == p) ++shared;
    }
    faster_count += static_cast<int>(Drain(*faster).size());
  }
  // Early: frames 12, 16, ..., 108 (each 200 ms slot); late: frame 10 at once, then the same;
  // faster: frame 10, then every 100 ms slot (the even frames), a superset.
  EXPECT_EQ(by_frame.size(), 25u);
  EXPECT_EQ(late_count, 26);
  EXPECT_EQ(shared, 25) << "every one after the first is the early subscriber's encoding";
  EXPECT_EQ(faster_count, 50);
  EXPECT_EQ(hub.stats().encodes - encodes_before, 50u) << "one per frame any of them was due on";
}

TEST(PreviewHub, MaxWidthIsHonouredAndTheAspectKept) {
  PreviewHub hub;
  struct Case {
    int max_width;
    cv::Size expected;
  };
  const std::vector<Case> cases = {{640, {640, 480}},
                                   {1000, {640, 480}},
                                   {320, {320, 240}},
                                   {200, {200, 150}},
                                   {100, {100, 75}}};
  std::vector<std::shared_ptr<PreviewSubscription>> subs;
  for (const Case& c : cases) {
    subs.push_back(hub.Subscribe("w", Request({PreviewKind::kDisparity}, 30, c.max_width)));
  }
  Feed(hub, 1, 20);
  for (size_t i = 0; i < cases.size(); ++i) {
    const std::vector<PreviewPtr> got = Drain(*subs[i]);
    ASSERT_EQ(got.size(), 1u);
    const cv::Mat image = Decode(*got[0]);
    EXPECT_EQ(image.size(), cases[i].expected) << "max width " << cases[i].max_width;
    EXPECT_EQ(got[0]->width, cases[i].expected.width);
    EXPECT_EQ(got[0]->height, cases[i].expected.height);
    EXPECT_DOUBLE_EQ(got[0]->scale, cases[i].expected.width / 640.0);
    EXPECT_EQ(got[0]->calibration_id, ProcessedFrame().rig->calibration_id());
  }
  // An awkward size: the height rounded to keep the aspect.
  const cv::Mat odd(479, 631, CV_8UC3, cv::Scalar(10, 20, 30));
  EXPECT_EQ(FitWidth(odd, 100).size(), cv::Size(100, 76));  // 479 * 100 / 631 = 75.9
  EXPECT_EQ(FitWidth(odd, 631).data, odd.data) << "not wider: shared, not copied";
}

// Peak signal-to-noise ratio of the luma (BT.601 Y, what JPEG keeps at full resolution) of two BGR
// or grey images, dB.
double LumaPsnr(const cv::Mat& a, const cv::Mat& b) {
  const auto luma = [](const cv::Mat& m) {
    if (m.channels() == 1) return m;
    cv::Mat ycrcb;
    cv::cvtColor(m, ycrcb, cv::COLOR_BGR2YCrCb);
    cv::Mat y;
    cv::extractChannel(ycrcb, y, 0);
    return y;
  };
  return Psnr(luma(a), luma(b));
}

// Each kind decoded against its reference, made here from the same frame: the tracks drawn by
// AnnotateTracks, the colour disparity, the left image, each halved by hand (2x2 means). The luma
// is within 30 dB at quality 80; the colour kinds' full BGR PSNR is bounded lower by JPEG's 4:2:0
// chroma subsampling, which smears the thin saturated boxes and labels (annotated: 27 dB at
// quality 80, and no more than 27.6 dB at 95; OpenCV 4.6 cannot encode 4:4:4).
TEST(PreviewHub, JpegsMatchAnIndependentReference) {
  const pipeline::FrameResult& frame = ProcessedFrame();
  ASSERT_FALSE(frame.tracks.empty()) << "the annotated preview must show something";
  PreviewHub hub;
  std::shared_ptr<PreviewSubscription> sub = hub.Subscribe(
      "viewer",
      Request({PreviewKind::kAnnotatedLeft, PreviewKind::kDisparity, PreviewKind::kLeft}, 5, 320));
  std::shared_ptr<PreviewSubscription> low =
      hub.Subscribe("low", Request({PreviewKind::kLeft}, 5, 320, 40));
  std::shared_ptr<PreviewSubscription> high =
      hub.Subscribe("high", Request({PreviewKind::kLeft}, 5, 320, 95));
  Feed(hub, 7, 20);
  const std::vector<PreviewPtr> got = Drain(*sub);
  ASSERT_EQ(got.size(), 3u);
  cv::Mat left_bgr;
  cv::cvtColor(frame.rectified_left, left_bgr, cv::COLOR_GRAY2BGR);
  const std::map<PreviewKind, cv::Mat> references = {
      {PreviewKind::kAnnotatedLeft, HalveByHand(pipeline::AnnotateTracks(frame))},
      {PreviewKind::kDisparity, HalveByHand(stereo::ToColour(frame.disparity))},
      {PreviewKind::kLeft, HalveByHand(frame.rectified_left)}};
  for (const PreviewPtr& p : got) {
    const cv::Mat& reference = references.at(p->kind);
    const cv::Mat image = Decode(*p);
    ASSERT_EQ(image.size(), reference.size());
    ASSERT_EQ(image.type(), reference.type());
    const double luma = LumaPsnr(image, reference), full = Psnr(image, reference);
    std::printf(
        "kind %d: %dx%d JPEG of %zu bytes, PSNR against the reference: luma %.1f dB, "
        "all channels %.1f dB\n",
        static_cast<int>(p->kind), p->width, p->height, p->jpeg.size(), luma, full);
    EXPECT_GT(luma, 30.0);
    EXPECT_GT(full, 25.0);
    EXPECT_EQ(p->frame_id, 7u);
    EXPECT_EQ(p->capture_time_ns, 350'000'000);  // frame 7 at 20 fps
    if (p->kind == PreviewKind::kAnnotatedLeft) {
      // The drawing is there: the plain left image is much further from it.
      const double plain = LumaPsnr(image, HalveByHand(left_bgr));
      std::printf("annotated against the plain left image: luma %.1f dB\n", plain);
      EXPECT_LT(plain, luma - 10);
    }
  }
  // The quality asked for is the one used: more bytes, closer to the reference.
  const std::vector<PreviewPtr> l = Drain(*low), h = Drain(*high);
  ASSERT_EQ(l.size(), 1u);
  ASSERT_EQ(h.size(), 1u);
  const cv::Mat& reference = references.at(PreviewKind::kLeft);
  const double psnr_low = Psnr(Decode(*l[0]), reference),
               psnr_high = Psnr(Decode(*h[0]), reference);
  std::printf("left at quality 40: %zu bytes, %.1f dB; at 95: %zu bytes, %.1f dB\n",
              l[0]->jpeg.size(), psnr_low, h[0]->jpeg.size(), psnr_high);
  EXPECT_GT(h[0]->jpeg.size(), l[0]->jpeg.size());
  EXPECT_GT(psnr_high, psnr_low + 3);
}

// A subscriber that reads nothing loses its oldest previews (counted) while one that reads keeps
// getting every one; the producer never waits.
TEST(PreviewHub, ASlowSubscriberLosesPreviewsWhileAFastOneGetsAll) {
  PreviewHubOptions options;
  options.queue_per_kind = 2;
  PreviewHub hub(options);
  std::shared_ptr<PreviewSubscription> fast =
      hub.Subscribe("fast", Request({PreviewKind::kAnnotatedLeft}));
  std::shared_ptr<PreviewSubscription> slow =
      hub.Subscribe("slow", Request({PreviewKind::kAnnotatedLeft}));
  std::vector<uint64_t> fast_ids;
  constexpr uint64_t kFrames = 20;
  for (uint64_t id = 1; id <= kFrames; ++id) {
    Feed(hub, id, 20);
    for (const PreviewPtr& p : Drain(*fast)) fast_ids.push_back(p->frame_id);
  }
  ASSERT_EQ(fast_ids.size(), kFrames);
  for (uint64_t i = 0; i < kFrames; ++i) EXPECT_EQ(fast_ids[i], i + 1);
  EXPECT_EQ(fast->dropped(), 0u);
  EXPECT_EQ(slow->dropped(), kFrames - 2);
  const PreviewSubscription::Popped first = slow->Pop();
  ASSERT_EQ(first.state, PreviewSubscription::PopState::kItem);
  EXPECT_EQ((*first.item)->frame_id, kFrames - 1) << "the newest two are kept";
  EXPECT_EQ(first.dropped, kFrames - 2);
  EXPECT_EQ(hub.stats().encodes, kFrames);
}

// Frames offered faster than the hub takes them: the latest wins, and every frame is accounted
// for (handled or replaced).
TEST(PreviewHub, OfferNeverWaitsAndTheLatestFrameWins) {
  PreviewHub hub;
  std::shared_ptr<PreviewSubscription> sub =
      hub.Subscribe("viewer", Request({PreviewKind::kAnnotatedLeft}));
  constexpr uint64_t kFrames = 200;
  for (uint64_t id = 1; id <= kFrames; ++id)
    hub.Offer(FrameAt(id, static_cast<int64_t>(id) * 50'000'000));
  ASSERT_TRUE(hub.WaitIdle(kWait));
  const PreviewHub::Stats stats = hub.stats();
  EXPECT_EQ(stats.frames_offered, kFrames);
  EXPECT_EQ(stats.frames_handled + stats.frames_replaced, kFrames);
  std::vector<PreviewPtr> got = Drain(*sub);
  ASSERT_FALSE(got.empty());
  EXPECT_EQ(got.back()->frame_id, kFrames) << "the last frame is never replaced";
  std::printf("200 frames offered at once: %llu handled, %llu replaced\n",
              static_cast<unsigned long long>(stats.frames_handled),
              static_cast<unsigned long long>(stats.frames_replaced));
}

TEST(PreviewHub, SubscribersAreBoundedAndCloseEndsThem) {
  PreviewHubOptions options;
  options.max_subscribers = 2;
  PreviewHub hub(options);
  auto a = hub.Subscribe("a", Request({PreviewKind::kLeft}));
  auto b = hub.Subscribe("b", Request({PreviewKind::kLeft}));
  ASSERT_NE(a, nullptr);
  ASSERT_NE(b, nullptr);
  EXPECT_EQ(hub.Subscribe("c", Request({PreviewKind::kLeft})), nullptr);
  hub.Unsubscribe(a->id());
  auto c = hub.Subscribe("c", Request({PreviewKind::kLeft}));
  ASSERT_NE(c, nullptr);
  EXPECT_EQ(hub.size(), 2u);
  EXPECT_EQ(hub.Close(), 2u);
  EXPECT_TRUE(hub.closed());
  EXPECT_EQ(b->Pop().state, PreviewSubscription::PopState::kEnded);
  EXPECT_EQ(c->Pop().state, PreviewSubscription::PopState::kEnded);
  EXPECT_EQ(hub.Subscribe("d", Request({PreviewKind::kLeft})), nullptr);
  hub.Offer(FrameAt(1, 0));  // after Close: ignored, no crash
}

TEST(PreviewRequest, ValidateNamesEveryBadField) {
  EXPECT_TRUE(Request({PreviewKind::kLeft}, 5, 640, 80).Validate().empty());
  EXPECT_TRUE(
      Request({PreviewKind::kLeft, PreviewKind::kDisparity}, 30, 64, 10).Validate().empty());
  EXPECT_TRUE(Request({PreviewKind::kLeft}, 0.1, 4096, 100).Validate().empty());
  const std::vector<std::string> problems =
      Request({PreviewKind::kLeft, PreviewKind::kLeft}, 31, 63, 101).Validate();
  EXPECT_THAT(problems,
              ::testing::ElementsAre(HasSubstr("kinds[1]"), HasSubstr("rate_hz"),
                                     HasSubstr("max_width_px"), HasSubstr("jpeg_quality")));
  EXPECT_THAT(Request({}, 0, 4097, 9).Validate(),
              ::testing::ElementsAre(HasSubstr("kinds"), HasSubstr("rate_hz"),
                                     HasSubstr("max_width_px"), HasSubstr("jpeg_quality")));
  EXPECT_THAT(Request({PreviewKind::kLeft}, std::nan(""), 640, 80).Validate(),
              ::testing::ElementsAre(HasSubstr("rate_hz")));
}

}  // namespace
}  // namespace stevi::server
