// SadBlockMatcher against cv::StereoBM, the independent reference: pixel-for-pixel equality on
// synthetic frames, noise, small and odd sizes, parameter sweeps and the Middlebury pairs, through
// both the AVX2 and the portable path.
#include "core/stereo/block_matcher.h"

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "drivers/synthetic/synthetic_source.h"
#include "tests/testing/data.h"
#include "tests/testing/stereo_bm.h"

namespace stevi::stereo {
namespace {

// The left padding of our pipeline: num_disparities + block_size / 2 columns.
constexpr int kPad = 64 + 7;

int16_t Unmatched(const SadBlockMatcherParams& p) {
  return static_cast<int16_t>((p.min_disparity - 1) * 16);
}

std::string Describe(const SadBlockMatcherParams& p) {
  std::ostringstream s;
  s << "{nd " << p.num_disparities << ", min " << p.min_disparity << ", block " << p.block_size
    << ", cap " << p.prefilter_cap << ", texture " << p.texture_threshold << ", uniq "
    << p.uniqueness_ratio << ", speckle " << p.speckle_window_size << "/" << p.speckle_range << "}";
  return s.str();
}

// cv::StereoBM with `p` on one thread (with several, its row stripes race at their boundaries:
// see the top of block_matcher.cc). The output is preset to the unmatched marker: cv::StereoBM
// leaves it untouched when no column is valid. nullopt when cv::StereoBM rejects the input (block
// not smaller than the image).
std::optional<cv::Mat> Reference(const cv::Mat& left, const cv::Mat& right,
                                 const SadBlockMatcherParams& p) {
  cv::setNumThreads(1);
  cv::Ptr<cv::StereoBM> bm = testing::StereoBMFor(p);
  cv::Mat out(left.size(), CV_16SC1, cv::Scalar(Unmatched(p)));
  try {
    bm->compute(left, right, out);
  } catch (const cv::Exception&) {
    return std::nullopt;
  }
  return out;
}

std::string FirstDifferences(const cv::Mat& ours, const cv::Mat& expected) {
  std::ostringstream s;
  int shown = 0;
  for (int y = 0; y < ours.rows && shown < 8; ++y) {
    for (int x = 0; x < ours.cols && shown < 8; ++x) {
      if (ours.at<int16_t>(y, x) != expected.at<int16_t>(y, x)) {
        s << " (" << x << "," << y << "): ours " << ours.at<int16_t>(y, x) << " cv "
          << expected.at<int16_t>(y, x) << ";";
        ++shown;
      }
    }
  }
  return s.str();
}

// Number of pixels where `matcher` (through the current path) differs from cv::StereoBM, with a
// failure message naming the case.
void ExpectSame(SadBlockMatcher& matcher, const cv::Mat& left, const cv::Mat& right,
                const std::optional<cv::Mat>& expected, const std::string& what) {
  const SadBlockMatcherParams& p = matcher.params();
  const std::string path = SadBlockMatcher::UsesAvx2() ? "avx2" : "portable";
  cv::Mat ours;
  matcher.Compute(left, right, ours);
  ASSERT_EQ(ours.type(), CV_16SC1) << what;
  ASSERT_EQ(ours.size(), left.size()) << what;
  if (!expected) {
    // cv::StereoBM throws: ours is all unmatched.
    EXPECT_EQ(cv::countNonZero(ours != Unmatched(p)), 0)
        << what << " " << Describe(p) << " " << path;
    return;
  }
  const int differing = cv::countNonZero(ours != *expected);
  EXPECT_EQ(differing, 0) << what << " " << left.cols << "x" << left.rows << " " << Describe(p)
                          << " " << path << ":" << FirstDifferences(ours, *expected);
}

// Both paths, each with a fresh matcher, in one stripe and in three (each on a thread).
void ExpectSameBothPaths(const cv::Mat& left, const cv::Mat& right, const SadBlockMatcherParams& p,
                         const std::string& what) {
  const std::optional<cv::Mat> expected = Reference(left, right, p);
  for (const bool portable : {false, true}) {
    for (const int stripes : {1, 3}) {
      SadBlockMatcher::ForcePortable(portable);
      SadBlockMatcherParams striped = p;
      striped.stripes = stripes;
      SadBlockMatcher matcher(striped);
      ExpectSame(matcher, left, right, expected, what + ", stripes " + std::to_string(stripes));
    }
  }
  SadBlockMatcher::ForcePortable(false);
}

TEST(SadBlockMatcherTest, ForcePortableSelectsThePath) {
  const bool avx2 = SadBlockMatcher::UsesAvx2();
  std::printf("CPU path: %s\n", avx2 ? "AVX2 (and portable, forced)" : "portable only");
  SadBlockMatcher::ForcePortable(true);
  EXPECT_FALSE(SadBlockMatcher::UsesAvx2());
  SadBlockMatcher::ForcePortable(false);
  EXPECT_EQ(SadBlockMatcher::UsesAvx2(), avx2);
}

cv::Mat PadLeft(const cv::Mat& image, int columns) {
  cv::Mat out;
  cv::copyMakeBorder(image, out, 0, 0, columns, 0, cv::BORDER_REPLICATE);
  return out;
}

struct Pair {
  cv::Mat left, right;
};

Pair SyntheticPair(int index) {
  const drivers::SyntheticRenderer renderer{drivers::SyntheticOptions{}};
  const StereoFrame frame = renderer.Render(index);
  return {frame.left, frame.right};
}

// A blurred random texture seen with a constant disparity plus independent pixel noise: matches
// with sub-pixel interpolation everywhere.
Pair ShiftedNoisePair(cv::Size size, int disparity, uint64_t seed) {
  cv::RNG rng(seed);
  cv::Mat texture(size.height, size.width + disparity, CV_8UC1);
  rng.fill(texture, cv::RNG::UNIFORM, 0, 256);
  cv::GaussianBlur(texture, texture, cv::Size(5, 5), 1.2);
  Pair pair;
  pair.left = texture(cv::Rect(0, 0, size.width, size.height)).clone();
  pair.right = texture(cv::Rect(disparity, 0, size.width, size.height)).clone();
  cv::Mat noise(size, CV_16SC1);
  rng.fill(noise, cv::RNG::NORMAL, 0, 3);
  cv::Mat right16;
  pair.right.convertTo(right16, CV_16SC1);
  right16 += noise;
  right16.convertTo(pair.right, CV_8UC1);
  return pair;
}

// Independent uniform noise: hardly anything unique.
Pair NoisePair(cv::Size size, uint64_t seed) {
  cv::RNG rng(seed);
  Pair pair{cv::Mat(size, CV_8UC1), cv::Mat(size, CV_8UC1)};
  rng.fill(pair.left, cv::RNG::UNIFORM, 0, 256);
  rng.fill(pair.right, cv::RNG::UNIFORM, 0, 256);
  return pair;
}

// Flat patches of random grey levels: ties between disparities, zero texture, exact minima.
Pair PatchPair(cv::Size size, int disparity, uint64_t seed) {
  cv::RNG rng(seed);
  cv::Mat coarse((size.height + 7) / 8, (size.width + disparity + 7) / 8, CV_8UC1);
  rng.fill(coarse, cv::RNG::UNIFORM, 0, 4);
  coarse *= 60;
  cv::Mat fine;
  cv::resize(coarse, fine, cv::Size(coarse.cols * 8, coarse.rows * 8), 0, 0, cv::INTER_NEAREST);
  Pair pair;
  pair.left = fine(cv::Rect(0, 0, size.width, size.height)).clone();
  pair.right = fine(cv::Rect(disparity, 0, size.width, size.height)).clone();
  return pair;
}

TEST(SadBlockMatcherTest, SyntheticFramesDefaultParams) {
  const SadBlockMatcherParams p;
  for (const int index : {0, 7, 23}) {
    const Pair pair = SyntheticPair(index);
    ASSERT_EQ(pair.left.type(), CV_8UC1);
    // Not a vacuous comparison: a good part of the frame is matched (the sky is not).
    cv::Mat disparity;
    SadBlockMatcher(p).Compute(pair.left, pair.right, disparity);
    EXPECT_GT(cv::countNonZero(disparity != Unmatched(p)), disparity.total() / 5) << index;
    ExpectSameBothPaths(pair.left, pair.right, p, "synthetic " + std::to_string(index));
    ExpectSameBothPaths(PadLeft(pair.left, kPad), PadLeft(pair.right, kPad), p,
                        "padded synthetic " + std::to_string(index));
  }
}

TEST(SadBlockMatcherTest, SyntheticFrameOneParameterAtATime) {
  const Pair pair = SyntheticPair(3);
  const cv::Mat left = PadLeft(pair.left, kPad);
  const cv::Mat right = PadLeft(pair.right, kPad);
  std::vector<SadBlockMatcherParams> cases;
  const SadBlockMatcherParams base;
  for (const int v : {5, 9, 21, 31, 51}) cases.push_back(base), cases.back().block_size = v;
  for (const int v : {16, 32, 128}) cases.push_back(base), cases.back().num_disparities = v;
  for (const int v : {1, 4, 13}) cases.push_back(base), cases.back().min_disparity = v;
  for (const int v : {0, 100}) cases.push_back(base), cases.back().uniqueness_ratio = v;
  for (const int v : {0, 100, 1000}) cases.push_back(base), cases.back().texture_threshold = v;
  for (const int v : {0, 400}) cases.push_back(base), cases.back().speckle_window_size = v;
  for (const int v : {0, 16}) cases.push_back(base), cases.back().speckle_range = v;
  for (const int v : {1, 15, 32, 63}) cases.push_back(base), cases.back().prefilter_cap = v;
  for (const SadBlockMatcherParams& p : cases) ExpectSameBothPaths(left, right, p, "synthetic 3");
}

// Every combination of the parameter values on small images (texture, noise, flat patches).
TEST(SadBlockMatcherTest, ParameterGrid) {
  const Pair synthetic = SyntheticPair(11);
  const cv::Rect crop(300, 250, 181, 97);
  std::vector<std::pair<std::string, Pair>> images = {
      {"synthetic crop", {synthetic.left(crop).clone(), synthetic.right(crop).clone()}},
      {"shifted noise", ShiftedNoisePair(cv::Size(170, 61), 9, 1)},
      {"patches", PatchPair(cv::Size(163, 50), 21, 2)},
  };
  int cases = 0;
  for (const auto& [name, pair] : images) {
    for (const int block : {5, 9, 15, 21}) {
      for (const int nd : {16, 64, 128}) {
        for (const int min_disparity : {0, 4}) {
          for (const int uniqueness : {0, 15}) {
            for (const int texture : {0, 10, 100}) {
              for (const int speckle : {0, 100}) {
                for (const int cap : {1, 31, 63}) {
                  SadBlockMatcherParams p;
                  p.block_size = block;
                  p.num_disparities = nd;
                  p.min_disparity = min_disparity;
                  p.uniqueness_ratio = uniqueness;
                  p.texture_threshold = texture;
                  p.speckle_window_size = speckle;
                  p.prefilter_cap = cap;
                  ExpectSameBothPaths(pair.left, pair.right, p, name);
                  ++cases;
                }
              }
            }
          }
        }
      }
    }
  }
  EXPECT_EQ(cases, 3 * 4 * 3 * 2 * 2 * 3 * 2 * 3);
}

// Sizes from smaller than the block up to moderate, odd and even, around num_disparities + block.
TEST(SadBlockMatcherTest, SmallAndOddSizes) {
  const std::vector<cv::Size> sizes = {
      {1, 1},   {4, 4},   {5, 5},   {6, 6},    {7, 40},   {40, 7},   {9, 7},     {16, 16},
      {17, 9},  {22, 22}, {30, 21}, {64, 20},  {69, 16},  {70, 17},  {78, 19},   {79, 15},
      {80, 33}, {83, 40}, {86, 23}, {100, 30}, {127, 61}, {143, 26}, {150, 151}, {333, 211}};
  for (const cv::Size size : sizes) {
    const std::vector<std::pair<std::string, Pair>> images = {
        {"noise", NoisePair(size, 3)},
        {"shifted noise", ShiftedNoisePair(size, 5, 4)},
        {"patches", PatchPair(size, 3, 5)},
    };
    for (const auto& [name, pair] : images) {
      for (const int block : {5, 15, 21}) {
        for (const int nd : {16, 64}) {
          for (const int min_disparity : {0, 4}) {
            SadBlockMatcherParams p;
            p.block_size = block;
            p.num_disparities = nd;
            p.min_disparity = min_disparity;
            p.texture_threshold = name == "noise" ? 0 : 10;
            p.uniqueness_ratio = name == "noise" ? 0 : 15;
            ExpectSameBothPaths(pair.left, pair.right, p, name);
          }
        }
      }
    }
  }
}

// Negative minimum disparities (the right image's columns then clamp inside the valid area).
TEST(SadBlockMatcherTest, NegativeMinDisparity) {
  const Pair pair = ShiftedNoisePair(cv::Size(200, 80), 2, 6);
  for (const int min_disparity : {-1, -5, -10, -40, -70, -100}) {
    for (const int block : {5, 15}) {
      SadBlockMatcherParams p;
      p.min_disparity = min_disparity;
      p.block_size = block;
      ExpectSameBothPaths(pair.left, pair.right, p, "shifted noise");
    }
  }
}

// One matcher through frames of different sizes and contents: buffers are reused correctly.
TEST(SadBlockMatcherTest, ReusedAcrossSizes) {
  const Pair synthetic = SyntheticPair(5);
  const std::vector<Pair> pairs = {
      {PadLeft(synthetic.left, kPad), PadLeft(synthetic.right, kPad)},
      ShiftedNoisePair(cv::Size(120, 50), 7, 7),
      {PadLeft(synthetic.left, kPad), PadLeft(synthetic.right, kPad)},
      {synthetic.left, synthetic.right},
      PatchPair(cv::Size(50, 20), 2, 8),
  };
  SadBlockMatcherParams p;
  p.min_disparity = 2;
  for (const bool portable : {false, true}) {
    SadBlockMatcher::ForcePortable(portable);
    SadBlockMatcher matcher(p);
    for (const Pair& pair : pairs) {
      ExpectSame(matcher, pair.left, pair.right, Reference(pair.left, pair.right, p), "reused");
    }
  }
  SadBlockMatcher::ForcePortable(false);
}

TEST(SadBlockMatcherTest, Middlebury) {
  const std::optional<std::string> data = testing::DataDir();
  if (!data) GTEST_SKIP() << "reference data folder not found: " << testing::DataDirWanted();
  const std::vector<std::pair<std::string, std::string>> pairs = {
      {"middlebury2001/tsukuba/scene1.row3.col3.ppm",
       "middlebury2001/tsukuba/scene1.row3.col4.ppm"},
      {"middlebury2001/venus/im2.ppm", "middlebury2001/venus/im6.ppm"},
      {"middlebury2003/teddy/im2.png", "middlebury2003/teddy/im6.png"},
      {"middlebury2003/cones/im2.png", "middlebury2003/cones/im6.png"},
  };
  for (const auto& [left_name, right_name] : pairs) {
    const std::string left_path = *data + "/" + left_name;
    const std::string right_path = *data + "/" + right_name;
    if (!std::filesystem::exists(left_path) || !std::filesystem::exists(right_path)) {
      GTEST_SKIP() << "Middlebury pair not found: " << left_path;
    }
    const cv::Mat left = cv::imread(left_path, cv::IMREAD_GRAYSCALE);
    const cv::Mat right = cv::imread(right_path, cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(left.empty()) << left_path;
    for (const int block : {9, 15}) {
      SadBlockMatcherParams p;
      p.block_size = block;
      ExpectSameBothPaths(left, right, p, left_name);
      const int pad = p.num_disparities + block / 2;
      ExpectSameBothPaths(PadLeft(left, pad), PadLeft(right, pad), p, "padded " + left_name);
    }
  }
}

TEST(SadBlockMatcherTest, RejectsInvalidParams) {
  SadBlockMatcherParams p;
  EXPECT_TRUE(p.Validate().empty());
  p.num_disparities = 40;
  p.block_size = 4;
  EXPECT_EQ(p.Validate().size(), 2u);
  EXPECT_THROW(SadBlockMatcher{p}, cv::Exception);
}

}  // namespace
}  // namespace stevi::stereo
