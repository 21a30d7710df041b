// Accuracy of the matchers on the Middlebury 2001/2003 pairs (tsukuba, venus, teddy, cones).
// Bad pixels: |d - gt| > 1 px over the non-occluded mask where the ground truth is known.
// "raw" counts unmatched pixels as bad; "filled" first fills holes along each row from the left
// neighbour's disparity; "matched" is the fraction of evaluated pixels with a disparity.
#include <cstdio>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "core/stereo/matcher.h"
#include "tests/testing/data.h"
#include "tests/testing/real_pairs.h"

namespace stevi::stereo {
namespace {

// The pairs and their truth come from the shared loader (tests/testing/real_pairs.h).
using MiddleburyPair = testing::RealPair;

struct Score {
  double raw_bad = 0, filled_bad = 0, matched = 0;  // percent of evaluated pixels
};

// Fills unmatched pixels along each row from the nearest matched pixel to the left (from the
// right for a row's leading hole).
cv::Mat1f Filled(const DisparityMap& map) {
  cv::Mat1f out(map.fixed.size(), -1.0f);
  for (int y = 0; y < out.rows; ++y) {
    float last = -1.0f;
    for (int x = 0; x < out.cols; ++x) {
      if (const std::optional<float> d = map.At(x, y)) last = *d;
      out(y, x) = last;
    }
    int first = 0;
    while (first < out.cols && out(y, first) < 0) ++first;
    for (int x = 0; x < first && first < out.cols; ++x) out(y, x) = out(y, first);
  }
  return out;
}

Score Evaluate(const DisparityMap& map, const MiddleburyPair& pair) {
  EXPECT_EQ(map.fixed.size(), pair.truth_px.size()) << pair.name;
  const cv::Mat1f filled = Filled(map);
  long evaluated = 0, raw_bad = 0, filled_bad = 0, matched = 0;
  for (int y = 0; y < pair.truth_px.rows; ++y) {
    for (int x = 0; x < pair.truth_px.cols; ++x) {
      if (!pair.evaluated(y, x)) continue;
      ++evaluated;
      const float truth = pair.truth_px(y, x);
      const std::optional<float> d = map.At(x, y);
      if (d) ++matched;
      if (!d || std::abs(*d - truth) > 1.0f) ++raw_bad;
      if (filled(y, x) < 0 || std::abs(filled(y, x) - truth) > 1.0f) ++filled_bad;
    }
  }
  EXPECT_GT(evaluated, 50000) << pair.name;
  const double n = std::max<long>(1, evaluated);
  return {100.0 * raw_bad / n, 100.0 * filled_bad / n, 100.0 * matched / n};
}

struct Config {
  std::string name;
  MatcherOptions options;
};

// One row of the table: the score per pair and the average of the four.
struct Row {
  std::vector<Score> per_pair;
  Score average;
};

Row RunConfig(const Config& config, const std::vector<MiddleburyPair>& pairs) {
  EXPECT_TRUE(config.options.Validate().empty()) << config.name;
  std::unique_ptr<DisparityMatcher> matcher = MakeMatcher(config.options);
  Row row;
  for (const MiddleburyPair& pair : pairs) {
    row.per_pair.push_back(Evaluate(matcher->Compute(pair.left, pair.right), pair));
    row.average.raw_bad += row.per_pair.back().raw_bad / pairs.size();
    row.average.filled_bad += row.per_pair.back().filled_bad / pairs.size();
    row.average.matched += row.per_pair.back().matched / pairs.size();
  }
  std::printf("%-34s", config.name.c_str());
  for (const Score& s : row.per_pair) {
    std::printf(" | %5.2f %5.2f %5.1f", s.raw_bad, s.filled_bad, s.matched);
  }
  std::printf(" | %5.2f %5.2f %5.1f\n", row.average.raw_bad, row.average.filled_bad,
              row.average.matched);
  return row;
}

class Middlebury : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::optional<std::string> data = testing::DataDir();
    if (!data) {
      GTEST_SKIP() << "reference data folder not found: " << testing::DataDirWanted()
                   << " (set STEVI_DATA_DIR)";
    }
    std::string missing;
    pairs_ = testing::LoadRealPairs(*data, testing::MiddleburyPairNames(false), missing);
    if (pairs_.empty()) GTEST_SKIP() << "Middlebury data not found: " << missing;
    std::printf("%-34s", "bad %: raw, filled; matched %");
    for (const MiddleburyPair& p : pairs_) std::printf(" | %-17s", p.name.c_str());
    std::printf(" | %-17s\n", "average");
  }

  // 64 disparities cover every pair's ground truth (the largest, cones, reaches 55 px).
  // Without the texture gate: see SemiGlobalTextureGateCost for why and what it costs here.
  static MatcherOptions SemiGlobal(bool pad_left) {
    MatcherOptions options;
    options.kind = MatcherKind::kSemiGlobal;
    options.semi_global.num_disparities = 64;
    options.semi_global.mode = SemiGlobalOptions::Mode::kThreeWay;
    options.semi_global.pad_left = pad_left;
    options.semi_global.texture_threshold = 0;
    return options;
  }
  static MatcherOptions BlockMatching(bool pad_left) {
    MatcherOptions options;
    options.kind = MatcherKind::kBlockMatching;
    options.block_matching.block_size = 9;
    // The halo gate trims disparities in flat areas; Middlebury's flat areas are nearly noise-free
    // and matched well, so it is off here (it is for a noisy sky).
    options.block_matching.local_texture_threshold = 0;
    options.block_matching.num_disparities = 64;
    options.block_matching.pad_left = pad_left;
    return options;
  }

  std::vector<MiddleburyPair> pairs_;
};

TEST_F(Middlebury, GroundTruthFitsTheSearchRange) {
  for (const MiddleburyPair& p : pairs_) {
    double top = 0;
    cv::minMaxLoc(p.truth_px, nullptr, &top);
    EXPECT_LT(top, 64.0) << p.name;
    EXPECT_EQ(p.left.size(), p.truth_px.size()) << p.name;
  }
}

TEST_F(Middlebury, SemiGlobalThreeWayPaddedMeetsTheReference) {
  const Row padded = RunConfig({"SGBM 3-way, padded, no texture gate", SemiGlobal(true)}, pairs_);
  const Row unpadded = RunConfig({"SGBM 3-way, not padded", SemiGlobal(false)}, pairs_);
  MatcherOptions tuned = SemiGlobal(true);
  tuned.semi_global.block_size = 3;
  tuned.semi_global.prefilter_cap = 31;
  const Row small_block = RunConfig({"SGBM 3-way, padded, block 3 cap 31", tuned}, pairs_);

  // Reference (data README, OpenCV 4.6): about 3.7 % filled, 98.7 % matched.
  EXPECT_LE(padded.average.filled_bad, 5.0);
  EXPECT_LE(padded.average.raw_bad, 6.0);
  EXPECT_GE(padded.average.matched, 97.0);
  EXPECT_LE(small_block.average.filled_bad, 4.2);
  // The padding is what recovers the leftmost num_disparities columns.
  EXPECT_LT(padded.average.filled_bad, unpadded.average.filled_bad);
  EXPECT_LT(padded.average.raw_bad, unpadded.average.raw_bad - 5.0);
  for (std::size_t i = 0; i < pairs_.size(); ++i) {
    EXPECT_LE(padded.per_pair[i].raw_bad, unpadded.per_pair[i].raw_bad) << pairs_[i].name;
  }
}

// The default texture gate (SemiGlobalOptions::texture_threshold) is tuned for noisy flying
// imagery: it removes SGBM's random matches on a flat sky with pixel noise of sigma 2. These pairs
// are nearly noise-free, and SGM fills their low-texture areas correctly, so the gate drops many
// good matches (matched 98 % -> 60 %) and the row-wise hole filling (wrong across occlusion
// edges) makes the filled rate worse: 4.7 % -> 8.5 % with the default 14 (OpenCV 4.6), against
// 5.5 % at 6 and 6.7 % at 10; no threshold that clears the noisy sky (>= 10) stays within 0.3
// points of the ungated rate. Use texture_threshold 0 for such low-noise imagery.
TEST_F(Middlebury, SemiGlobalTextureGateCost) {
  const Row ungated = RunConfig({"SGBM 3-way, padded, texture 0", SemiGlobal(true)}, pairs_);
  MatcherOptions options = SemiGlobal(true);
  options.semi_global.texture_threshold = SemiGlobalOptions().texture_threshold;
  const Row gated = RunConfig(
      {"SGBM 3-way, padded, texture " + std::to_string(options.semi_global.texture_threshold),
       options},
      pairs_);
  options.semi_global.texture_threshold = 6;
  RunConfig({"SGBM 3-way, padded, texture 6", options}, pairs_);

  // The gate only removes matches, the ones on the least textured surfaces.
  EXPECT_LT(gated.average.matched, ungated.average.matched - 20.0);
  EXPECT_GT(gated.average.matched, 50.0);
  // Of what is left, no more is wrong than without the gate.
  EXPECT_LE(gated.average.raw_bad - (100.0 - gated.average.matched),
            ungated.average.raw_bad - (100.0 - ungated.average.matched) + 0.1);
  // The measured cost with holes filled (8.45 % at 14, OpenCV 4.6).
  EXPECT_LE(gated.average.filled_bad, 9.0);
}

TEST_F(Middlebury, BlockMatchingPaddedMeetsTheReference) {
  const Row padded = RunConfig({"BM block 9, x-Sobel, padded", BlockMatching(true)}, pairs_);
  const Row unpadded = RunConfig({"BM block 9, x-Sobel, not padded", BlockMatching(false)}, pairs_);
  MatcherOptions normalized = BlockMatching(true);
  normalized.block_matching.prefilter_type = BlockMatchingOptions::PreFilter::kNormalizedResponse;
  const Row normalized_row = RunConfig({"BM block 9, normalized, padded", normalized}, pairs_);

  // Reference (data README): 7-8 % filled, 15-20 % raw, 82-88 % matched.
  EXPECT_LE(padded.average.filled_bad, 10.0);
  EXPECT_LE(padded.average.raw_bad, 20.0);
  EXPECT_GE(padded.average.matched, 82.0);
  EXPECT_LT(padded.average.raw_bad, unpadded.average.raw_bad);
  // Why x-Sobel is the default pre-filter.
  EXPECT_LT(padded.average.filled_bad, normalized_row.average.filled_bad);
}

}  // namespace
}  // namespace stevi::stereo
