#include "drivers/aravis/stereo_pairer.h"

#include <cstdint>
#include <cstdlib>
#include <optional>
#include <vector>

#include <gtest/gtest.h>

namespace stevi::drivers {
namespace {

constexpr int64_t kPeriodNs = 33'333'333;  // 30 fps
constexpr int64_t kMs = 1'000'000;

// A 4x2 frame whose pixels all hold `tag`, so that a test can tell which frame ended up where.
MonoFrame Frame(int64_t t_ns, uint8_t tag) {
  MonoFrame frame;
  frame.image = cv::Mat(2, 4, CV_8UC1, cv::Scalar(tag));
  frame.t_ns = t_ns;
  frame.unix_time_ns = 1'700'000'000'000'000'000 + t_ns;
  frame.frame_id = tag;
  return frame;
}

uint8_t Tag(const cv::Mat& image) { return image.at<uint8_t>(0, 0); }

PairerOptions HalfPeriod() { return PairerOptions{kPeriodNs / 2, 4}; }

TEST(StereoPairer, PairsFramesAtTheSameInstant) {
  StereoPairer pairer(HalfPeriod());
  for (int k = 0; k < 10; ++k) {
    const int64_t t = 1'000 * kMs + k * kPeriodNs;
    EXPECT_FALSE(pairer.Add(Side::kLeft, Frame(t, static_cast<uint8_t>(k))));
    std::optional<StereoFrame> pair =
        pairer.Add(Side::kRight, Frame(t, static_cast<uint8_t>(100 + k)));
    ASSERT_TRUE(pair) << "frame " << k;
    EXPECT_EQ(pair->index, k);
    EXPECT_EQ(pair->t_ns, t);
    EXPECT_EQ(pair->unix_time_ns, 1'700'000'000'000'000'000 + t);
    EXPECT_EQ(pair->pair_skew_ns, 0);
    EXPECT_FALSE(pair->rectified);
    EXPECT_EQ(Tag(pair->left), k);
    EXPECT_EQ(Tag(pair->right), 100 + k);
  }
  const SourceCounters c = pairer.Counters();
  EXPECT_EQ(c.pairs, 10u);
  EXPECT_EQ(c.unpaired_dropped, 0u);
  EXPECT_EQ(c.max_abs_skew_ns, 0);
  EXPECT_EQ(c.mean_abs_skew_ns, 0.0);
  EXPECT_EQ(pairer.pending(Side::kLeft), 0u);
  EXPECT_EQ(pairer.pending(Side::kRight), 0u);
}

TEST(StereoPairer, PairsJitterWithinTheToleranceInEitherArrivalOrder) {
  StereoPairer pairer(HalfPeriod());
  // right - left, ms; the right frame sometimes arrives first.
  const int64_t jitter_ms[] = {3, -5, 16, -16, 0, 11};
  const bool right_first[] = {false, true, false, true, true, false};
  for (int k = 0; k < 6; ++k) {
    const int64_t t_left = k * kPeriodNs;
    const int64_t t_right = t_left + jitter_ms[k] * kMs;
    std::optional<StereoFrame> pair;
    if (right_first[k]) {
      EXPECT_FALSE(pairer.Add(Side::kRight, Frame(t_right, static_cast<uint8_t>(100 + k))));
      pair = pairer.Add(Side::kLeft, Frame(t_left, static_cast<uint8_t>(k)));
    } else {
      EXPECT_FALSE(pairer.Add(Side::kLeft, Frame(t_left, static_cast<uint8_t>(k))));
      pair = pairer.Add(Side::kRight, Frame(t_right, static_cast<uint8_t>(100 + k)));
    }
    ASSERT_TRUE(pair) << "frame " << k;
    EXPECT_EQ(pair->t_ns, t_left) << "t_ns is the left capture time";
    EXPECT_EQ(pair->pair_skew_ns, jitter_ms[k] * kMs);
    EXPECT_EQ(Tag(pair->left), k);
    EXPECT_EQ(Tag(pair->right), 100 + k);
  }
  const SourceCounters c = pairer.Counters();
  EXPECT_EQ(c.pairs, 6u);
  EXPECT_EQ(c.unpaired_dropped, 0u);
  EXPECT_EQ(c.last_skew_ns, 11 * kMs);
  EXPECT_EQ(c.max_abs_skew_ns, 16 * kMs);
  // (3 + 5 + 16 + 16 + 0 + 11) / 6 ms
  EXPECT_DOUBLE_EQ(c.mean_abs_skew_ns, 51.0 * kMs / 6.0);
}

TEST(StereoPairer, NeverPairsBeyondTheTolerance) {
  StereoPairer pairer(PairerOptions{5 * kMs, 4});
  for (int k = 0; k < 5; ++k) {
    EXPECT_FALSE(pairer.Add(Side::kLeft, Frame(k * kPeriodNs, 1)));
    EXPECT_FALSE(pairer.Add(Side::kRight, Frame(k * kPeriodNs + 7 * kMs, 2)));
  }
  const SourceCounters c = pairer.Counters();
  EXPECT_EQ(c.pairs, 0u);
  // Each right frame is dropped when the next left one overtakes it by more than 5 ms, each left
  // frame when its right neighbour is already 7 ms ahead: all but the last right one.
  EXPECT_EQ(c.unpaired_dropped, 9u);
  EXPECT_EQ(pairer.pending(Side::kRight), 1u);
}

TEST(StereoPairer, DropsTheOrphanOfALostLeftFrame) {
  StereoPairer pairer(HalfPeriod());
  ASSERT_FALSE(pairer.Add(Side::kLeft, Frame(0, 0)));
  ASSERT_TRUE(pairer.Add(Side::kRight, Frame(1 * kMs, 100)));
  // Left frame 1 never arrives; its right partner waits until left frame 2 overtakes it.
  ASSERT_FALSE(pairer.Add(Side::kRight, Frame(kPeriodNs + 1 * kMs, 101)));
  EXPECT_EQ(pairer.pending(Side::kRight), 1u);
  ASSERT_FALSE(pairer.Add(Side::kLeft, Frame(2 * kPeriodNs, 2)));
  EXPECT_EQ(pairer.pending(Side::kRight), 0u);
  EXPECT_EQ(pairer.Counters().unpaired_dropped, 1u);
  std::optional<StereoFrame> pair = pairer.Add(Side::kRight, Frame(2 * kPeriodNs + 1 * kMs, 102));
  ASSERT_TRUE(pair);
  EXPECT_EQ(pair->index, 1);
  EXPECT_EQ(Tag(pair->left), 2);
  EXPECT_EQ(Tag(pair->right), 102);
  EXPECT_EQ(pairer.Counters().pairs, 2u);
  EXPECT_EQ(pairer.Counters().unpaired_dropped, 1u);
}

TEST(StereoPairer, BoundsThePendingFramesOfAStalledSide) {
  StereoPairer pairer(HalfPeriod());
  // The right camera stalls for 10 frames: the left side keeps at most max_pending (4).
  for (int k = 0; k < 10; ++k) {
    EXPECT_FALSE(pairer.Add(Side::kLeft, Frame(k * kPeriodNs, static_cast<uint8_t>(k))));
    EXPECT_LE(pairer.pending(Side::kLeft), 4u);
  }
  EXPECT_EQ(pairer.Counters().unpaired_dropped, 6u);
  // It resumes at frame 10: the 4 waiting left frames are too old for it and go.
  EXPECT_FALSE(pairer.Add(Side::kRight, Frame(10 * kPeriodNs, 110)));
  EXPECT_EQ(pairer.pending(Side::kLeft), 0u);
  EXPECT_EQ(pairer.Counters().unpaired_dropped, 10u);
  std::optional<StereoFrame> pair = pairer.Add(Side::kLeft, Frame(10 * kPeriodNs, 10));
  ASSERT_TRUE(pair);
  EXPECT_EQ(pair->index, 0);
  EXPECT_EQ(Tag(pair->left), 10);
  EXPECT_EQ(Tag(pair->right), 110);
}

TEST(StereoPairer, DropsFramesOlderThanTheOtherSidesNewestMinusTheTolerance) {
  StereoPairer pairer(HalfPeriod());
  ASSERT_FALSE(pairer.Add(Side::kRight, Frame(5 * kPeriodNs, 105)));
  // A left frame from 2 periods earlier can never pair: the right side only gets newer.
  EXPECT_FALSE(pairer.Add(Side::kLeft, Frame(3 * kPeriodNs, 3)));
  EXPECT_EQ(pairer.pending(Side::kLeft), 0u);
  EXPECT_EQ(pairer.Counters().unpaired_dropped, 1u);
  EXPECT_TRUE(pairer.Add(Side::kLeft, Frame(5 * kPeriodNs, 5)));
}

TEST(StereoPairer, DropsFramesThatGoBackInTimeUntilTheSideIsReset) {
  StereoPairer pairer(HalfPeriod());
  ASSERT_FALSE(pairer.Add(Side::kLeft, Frame(10 * kPeriodNs, 10)));
  EXPECT_FALSE(pairer.Add(Side::kLeft, Frame(10 * kPeriodNs, 11)));  // duplicate time
  EXPECT_FALSE(pairer.Add(Side::kLeft, Frame(2 * kPeriodNs, 12)));   // clock stepped back
  EXPECT_EQ(pairer.Counters().unpaired_dropped, 2u);
  EXPECT_EQ(pairer.pending(Side::kLeft), 1u);

  // The camera reconnected with a restarted clock: its pending frame is dropped and the new
  // times are accepted.
  pairer.ResetSide(Side::kLeft);
  EXPECT_EQ(pairer.pending(Side::kLeft), 0u);
  EXPECT_EQ(pairer.Counters().unpaired_dropped, 3u);
  ASSERT_FALSE(pairer.Add(Side::kLeft, Frame(1 * kPeriodNs, 13)));
  std::optional<StereoFrame> pair = pairer.Add(Side::kRight, Frame(1 * kPeriodNs + 2 * kMs, 113));
  ASSERT_TRUE(pair);
  EXPECT_EQ(Tag(pair->left), 13);
  EXPECT_EQ(pair->pair_skew_ns, 2 * kMs);
}

TEST(StereoPairer, PairsWithTheClosestOfSeveralCandidates) {
  // With a tolerance wider than half a period two right frames are candidates for one left one.
  StereoPairer pairer(PairerOptions{30 * kMs, 4});
  ASSERT_FALSE(pairer.Add(Side::kRight, Frame(0, 100)));
  ASSERT_FALSE(pairer.Add(Side::kRight, Frame(kPeriodNs, 101)));
  std::optional<StereoFrame> pair = pairer.Add(Side::kLeft, Frame(kPeriodNs - 4 * kMs, 1));
  ASSERT_TRUE(pair);
  EXPECT_EQ(Tag(pair->right), 101);
  EXPECT_EQ(pair->pair_skew_ns, 4 * kMs);
  // The older candidate can never pair any more.
  EXPECT_EQ(pairer.Counters().unpaired_dropped, 1u);
  EXPECT_EQ(pairer.pending(Side::kRight), 0u);
}

TEST(StereoPairer, SkewStatisticsCoverTheLastHundredPairs) {
  StereoPairer pairer(HalfPeriod());
  // 150 pairs with skews -3..+3 ms in a cycle of 7.
  const auto skew_ms = [](int k) -> int64_t { return k % 7 - 3; };
  for (int k = 0; k < 150; ++k) {
    const int64_t t = k * kPeriodNs;
    ASSERT_FALSE(pairer.Add(Side::kLeft, Frame(t, 0)));
    ASSERT_TRUE(pairer.Add(Side::kRight, Frame(t + skew_ms(k) * kMs, 0)));
  }
  // The window holds pairs 50..149. k = 50..55 has k % 7 = 1..6: |skew| 2+1+0+1+2+3 = 9 ms;
  // k = 56..146 is 13 full cycles of 3+2+1+0+1+2+3 = 12 ms: 156 ms; k = 147..149 has
  // k % 7 = 0..2: 3+2+1 = 6 ms. Sum 171 ms over 100 pairs.
  const SourceCounters c = pairer.Counters();
  EXPECT_EQ(c.pairs, 150u);
  EXPECT_EQ(c.last_skew_ns, skew_ms(149) * kMs);
  EXPECT_EQ(c.last_skew_ns, -1 * kMs);
  EXPECT_EQ(c.max_abs_skew_ns, 3 * kMs);
  EXPECT_DOUBLE_EQ(c.mean_abs_skew_ns, 171.0 * kMs / 100.0);
}

TEST(PairerOptions, ValidateListsEveryProblem) {
  EXPECT_TRUE(PairerOptions{}.Validate().empty());
  const std::vector<std::string> problems = PairerOptions{0, 0}.Validate();
  ASSERT_EQ(problems.size(), 2u);
  EXPECT_EQ(problems[0], "tolerance_ns: must be > 0 (got 0)");
  EXPECT_EQ(problems[1], "max_pending: must be >= 1 (got 0)");
}

}  // namespace
}  // namespace stevi::drivers
