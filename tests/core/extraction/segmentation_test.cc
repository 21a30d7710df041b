#include "core/extraction/segmentation.h"

#include <algorithm>
#include <map>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

namespace stevi::extraction {
namespace {

using ::testing::HasSubstr;
using ::testing::IsEmpty;
using ::testing::UnorderedElementsAre;

// Adds seeded Gaussian noise (grey levels) to an 8-bit image of any channel count.
cv::Mat AddNoise(const cv::Mat& image, double sigma, uint64_t seed) {
  cv::Mat noise(image.size(), CV_32FC(image.channels()));
  cv::RNG rng(seed);
  rng.fill(noise, cv::RNG::NORMAL, 0.0, sigma);
  cv::Mat f;
  image.convertTo(f, CV_32F);
  f += noise;
  cv::Mat out;
  f.convertTo(out, CV_8U);
  return out;
}

double IoU(const cv::Mat1b& a, const cv::Mat1b& b) {
  const int inter = cv::countNonZero(a & b);
  const int uni = cv::countNonZero(a | b);
  return uni == 0 ? 1.0 : static_cast<double>(inter) / uni;
}

// The most frequent label in `labels` and its share of the pixels.
std::pair<int, double> Majority(const cv::Mat1i& labels) {
  std::map<int, int> counts;
  for (int y = 0; y < labels.rows; ++y) {
    for (int x = 0; x < labels.cols; ++x) ++counts[labels(y, x)];
  }
  const auto best =
      std::max_element(counts.begin(), counts.end(),
                       [](const auto& a, const auto& b) { return a.second < b.second; });
  return {best->first, static_cast<double>(best->second) / labels.total()};
}

// A vertical sky gradient from `top` to `bottom` grey levels with a disc of `disc_level`.
struct SkyScene {
  cv::Mat1b grey;
  cv::Mat1b disc;  // truth mask
};

SkyScene DarkDiscOnSky(int top, int bottom, int disc_level) {
  SkyScene scene;
  const cv::Size size(320, 240);
  scene.grey = cv::Mat1b(size);
  for (int y = 0; y < size.height; ++y) {
    scene.grey.row(y).setTo(top + (bottom - top) * y / (size.height - 1));
  }
  scene.disc = cv::Mat1b(size, uchar{0});
  cv::circle(scene.disc, cv::Point(150, 110), 40, cv::Scalar(255), cv::FILLED);
  scene.grey.setTo(disc_level, scene.disc);
  scene.grey = AddNoise(scene.grey, 4.0, 11);
  return scene;
}

TEST(SegmentByIntensity, FindsADarkDiscOnABrightGradientSky) {
  const SkyScene scene = DarkDiscOnSky(170, 240, 40);
  double threshold = -1;
  const cv::Mat1b mask = SegmentByIntensity(scene.grey, IntensityOptions{}, &threshold);
  EXPECT_GT(IoU(mask, scene.disc), 0.9);
  EXPECT_GT(threshold, 40);
  EXPECT_LT(threshold, 170);
  EXPECT_EQ(cv::countNonZero((mask != 0) & (mask != 255)), 0);
}

TEST(SegmentByIntensity, LeavesTheInputUntouched) {
  const SkyScene scene = DarkDiscOnSky(170, 240, 40);
  const cv::Mat1b before = scene.grey.clone();
  SegmentByIntensity(scene.grey, IntensityOptions{});
  EXPECT_EQ(cv::countNonZero(scene.grey != before), 0);
}

TEST(SegmentByIntensity, FindsABrightDiscOnADarkGradient) {
  SkyScene scene = DarkDiscOnSky(170, 240, 40);
  scene.grey = 255 - scene.grey;  // a bright disc (215) on a dark gradient (15..85)
  IntensityOptions options;
  options.dark_objects = false;
  double threshold = -1;
  const cv::Mat1b mask = SegmentByIntensity(scene.grey, options, &threshold);
  EXPECT_GT(IoU(mask, scene.disc), 0.9);
  EXPECT_GT(threshold, 85);
  EXPECT_LT(threshold, 215);
}

TEST(SegmentByIntensity, OffsetShiftsTheThreshold) {
  const SkyScene scene = DarkDiscOnSky(170, 240, 40);
  double otsu = 0, shifted = 0;
  const cv::Mat1b plain = SegmentByIntensity(scene.grey, IntensityOptions{}, &otsu);
  IntensityOptions options;
  options.offset = 100;  // above the lower part of the sky
  const cv::Mat1b loose = SegmentByIntensity(scene.grey, options, &shifted);
  EXPECT_DOUBLE_EQ(shifted, otsu + 100);
  EXPECT_GT(cv::countNonZero(loose), cv::countNonZero(plain) + 1000);
}

TEST(SegmentByColour, FindsARedSquareOnGreenWithAWrappingHueRange) {
  cv::Mat3b bgr(100, 120, cv::Vec3b(30, 160, 40));  // green
  const cv::Rect square(30, 20, 40, 40);
  bgr(square).setTo(cv::Vec3b(20, 20, 230));                   // red, hue ~0
  bgr(cv::Rect(30, 20, 20, 40)).setTo(cv::Vec3b(60, 0, 230));  // purplish red, hue ~172
  cv::Mat3b hsv;
  cv::cvtColor(bgr, hsv, cv::COLOR_BGR2HSV);
  ASSERT_GT(hsv(30, 35)[0], 165);  // the left half is on the high side of the wrap
  ASSERT_LT(hsv(30, 60)[0], 5);

  HsvRange red;
  red.low = cv::Scalar(165, 100, 80);
  red.high = cv::Scalar(8, 255, 255);
  ASSERT_THAT(red.Validate(), IsEmpty());
  cv::Mat1b want(bgr.size(), uchar{0});
  want(square).setTo(255);
  EXPECT_EQ(cv::countNonZero(SegmentByColour(bgr, {red}) != want), 0);

  // Either half of the wrap alone finds only its half of the square.
  HsvRange high_half = red, low_half = red;
  high_half.high[0] = 179;
  low_half.low[0] = 0;
  EXPECT_EQ(cv::countNonZero(SegmentByColour(bgr, {high_half})), 20 * 40);
  EXPECT_EQ(cv::countNonZero(SegmentByColour(bgr, {low_half})), 20 * 40);
  // The union of both halves is the square again.
  EXPECT_EQ(cv::countNonZero(SegmentByColour(bgr, {high_half, low_half}) != want), 0);
}

TEST(SegmentByColour, GreenRangeFindsTheBackground) {
  cv::Mat3b bgr(60, 80, cv::Vec3b(30, 160, 40));
  bgr(cv::Rect(10, 10, 20, 20)).setTo(cv::Vec3b(20, 20, 230));
  HsvRange green;
  green.low = cv::Scalar(45, 80, 80);
  green.high = cv::Scalar(75, 255, 255);
  EXPECT_EQ(cv::countNonZero(SegmentByColour(bgr, {green})), 60 * 80 - 20 * 20);
  EXPECT_EQ(cv::countNonZero(SegmentByColour(bgr, {})), 0);
}

TEST(SegmentGraph, SeparatesTwoFlatHalves) {
  cv::Mat1b grey(120, 160, uchar{50});
  grey.colRange(80, 160).setTo(200);
  grey = AddNoise(grey, 2.0, 5);
  const cv::Mat1i labels = SegmentGraph(grey, GraphSegmentationOptions{});
  ASSERT_EQ(labels.size(), grey.size());
  const auto [left, left_share] = Majority(labels.colRange(0, 80).clone());
  const auto [right, right_share] = Majority(labels.colRange(80, 160).clone());
  EXPECT_NE(left, right);
  EXPECT_GT(left_share, 0.95);
  EXPECT_GT(right_share, 0.95);
  // Labels are 0..n-1, all used. The smoothing (sigma) blurs the step into the two columns next
  // to it, which may form thin segments of their own: nothing else may.
  double min_label = 0, max_label = 0;
  cv::minMaxLoc(labels, &min_label, &max_label);
  EXPECT_EQ(min_label, 0);
  EXPECT_LE(max_label, 3);
  std::vector<int> used(static_cast<size_t>(max_label) + 1, 0);
  for (int y = 0; y < labels.rows; ++y) {
    for (int x = 0; x < labels.cols; ++x) {
      ++used[labels(y, x)];
      if (x < 79) {
        EXPECT_EQ(labels(y, x), left) << x << "," << y;
      } else if (x > 80) {
        EXPECT_EQ(labels(y, x), right) << x << "," << y;
      }
    }
  }
  EXPECT_THAT(used, ::testing::Each(::testing::Gt(0)));
}

TEST(SegmentGraph, ColourImageAndSmallKGiveMoreSegments) {
  cv::Mat3b bgr(80, 80, cv::Vec3b(200, 40, 40));
  bgr(cv::Rect(20, 20, 40, 40)).setTo(cv::Vec3b(40, 200, 40));
  const cv::Mat3b noisy = AddNoise(bgr, 2.0, 9);
  double max_label = 0;
  cv::minMaxLoc(SegmentGraph(noisy, GraphSegmentationOptions{}), nullptr, &max_label);
  EXPECT_EQ(max_label, 1);  // square and background
  GraphSegmentationOptions fine;
  fine.k = 1;
  fine.min_size = 0;
  fine.sigma = 0;
  cv::minMaxLoc(SegmentGraph(noisy, fine), nullptr, &max_label);
  EXPECT_GT(max_label, 10);
}

TEST(IntensityOptions, ListsEveryProblem) {
  EXPECT_THAT(IntensityOptions{}.Validate(), IsEmpty());
  IntensityOptions options;
  options.offset = 300;
  options.blur_size = 2;
  const std::vector<std::string> problems = options.Validate();
  EXPECT_THAT(problems, UnorderedElementsAre(HasSubstr("offset:"), HasSubstr("blur_size:")));
  for (const std::string& p : problems) EXPECT_THAT(p, HasSubstr("(got ")) << p;
}

TEST(HsvRange, ListsEveryProblem) {
  EXPECT_THAT(HsvRange{}.Validate(), IsEmpty());
  HsvRange range;
  range.low = cv::Scalar(180, 200, -1);
  range.high = cv::Scalar(-2, 100, 300);
  EXPECT_THAT(range.Validate(),
              UnorderedElementsAre(HasSubstr("low.h:"), HasSubstr("high.h:"), HasSubstr("low.v:"),
                                   HasSubstr("high.v:"), HasSubstr("high.s: must be >= low.s")));
  // A wrapping hue range is valid; the prefix names the range.
  HsvRange wrap;
  wrap.low[0] = 170;
  wrap.high[0] = 10;
  EXPECT_THAT(ValidateHsvRanges({wrap, range, wrap}),
              ::testing::Each(::testing::StartsWith("ranges[1].")));
  EXPECT_EQ(ValidateHsvRanges({wrap, range, wrap}).size(), 5u);
}

TEST(GraphSegmentationOptions, ListsEveryProblem) {
  EXPECT_THAT(GraphSegmentationOptions{}.Validate(), IsEmpty());
  GraphSegmentationOptions options;
  options.k = 0;
  options.sigma = -1;
  options.min_size = -5;
  const std::vector<std::string> problems = options.Validate();
  EXPECT_THAT(problems,
              UnorderedElementsAre(HasSubstr("k:"), HasSubstr("sigma:"), HasSubstr("min_size:")));
  for (const std::string& p : problems) EXPECT_THAT(p, HasSubstr("(got ")) << p;
}

}  // namespace
}  // namespace stevi::extraction
