#include "core/extraction/morphology.h"

#include <cstdlib>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

namespace stevi::extraction {
namespace {

using ::testing::IsEmpty;
using ::testing::UnorderedElementsAre;

// Number of pixels where two masks differ.
int Differences(const cv::Mat1b& a, const cv::Mat1b& b) {
  EXPECT_EQ(a.size(), b.size());
  if (a.size() != b.size()) return -1;
  return cv::countNonZero(a != b);
}

cv::Mat1b RectMask(cv::Size size, const cv::Rect& rect) {
  cv::Mat1b mask(size, uchar{0});
  mask(rect).setTo(255);
  return mask;
}

TEST(Dilate, DotWithA5x5RectIsA5x5Square) {
  cv::Mat1b dot(21, 21, uchar{0});
  dot(10, 10) = 255;
  const cv::Mat1b out = Dilate(dot, StructuringShape::kRect, 5);
  EXPECT_EQ(Differences(out, RectMask(dot.size(), cv::Rect(8, 8, 5, 5))), 0);
}

TEST(Dilate, DotWithA5x5CrossIsAPlusOf9Pixels) {
  cv::Mat1b dot(21, 21, uchar{0});
  dot(10, 10) = 255;
  cv::Mat1b want(21, 21, uchar{0});
  want(cv::Rect(8, 10, 5, 1)).setTo(255);
  want(cv::Rect(10, 8, 1, 5)).setTo(255);
  EXPECT_EQ(Differences(Dilate(dot, StructuringShape::kCross, 5), want), 0);
}

TEST(Dilate, DotWithAnEllipseIsSymmetricAndInsideTheBox) {
  cv::Mat1b dot(31, 31, uchar{0});
  dot(15, 15) = 255;
  const cv::Mat1b out = Dilate(dot, StructuringShape::kEllipse, 7);
  const cv::Rect box = cv::boundingRect(out);
  EXPECT_EQ(box, cv::Rect(12, 12, 7, 7));
  // Corners are cut (not a square), and the shape is symmetric.
  EXPECT_LT(cv::countNonZero(out), 49);
  EXPECT_EQ(out(12, 12), 0);
  cv::Mat1b flipped;
  cv::flip(out, flipped, -1);
  EXPECT_EQ(Differences(out, flipped), 0);
}

TEST(Erode, ShrinksASquareByTheElementRadius) {
  const cv::Mat1b square = RectMask({30, 30}, cv::Rect(5, 5, 9, 9));
  EXPECT_EQ(Differences(Erode(square, StructuringShape::kRect, 5),
                        RectMask({30, 30}, cv::Rect(7, 7, 5, 5))),
            0);
}

TEST(Erode, DoesNotEatInFromTheImageBorder) {
  const cv::Mat1b full(20, 20, uchar{255});
  EXPECT_EQ(cv::countNonZero(Erode(full, StructuringShape::kRect, 5)), 400);
}

TEST(Open, RemovesA2x2SpeckleAndKeepsALargeSquare) {
  cv::Mat1b mask = RectMask({40, 40}, cv::Rect(20, 20, 12, 12));
  mask(cv::Rect(4, 4, 2, 2)).setTo(255);
  EXPECT_EQ(Differences(Open(mask, StructuringShape::kRect, 3),
                        RectMask({40, 40}, cv::Rect(20, 20, 12, 12))),
            0);
}

TEST(Open, CutsAOnePixelBridge) {
  cv::Mat1b mask = RectMask({60, 30}, cv::Rect(5, 5, 15, 15));
  mask(cv::Rect(35, 5, 15, 15)).setTo(255);
  mask(cv::Rect(20, 12, 15, 1)).setTo(255);  // bridge
  cv::Mat labels;
  EXPECT_EQ(cv::connectedComponents(mask, labels), 2);  // background + one
  EXPECT_EQ(cv::connectedComponents(Open(mask, StructuringShape::kRect, 3), labels), 3);
}

TEST(Close, JoinsAGapNarrowerThanTheElement) {
  cv::Mat1b mask = RectMask({40, 20}, cv::Rect(5, 5, 10, 10));
  mask(cv::Rect(17, 5, 10, 10)).setTo(255);  // 2-pixel gap at x = 15, 16
  const cv::Mat1b out = Close(mask, StructuringShape::kRect, 5);
  EXPECT_EQ(Differences(out, RectMask({40, 20}, cv::Rect(5, 5, 22, 10))), 0);
}

TEST(SingleOps, SizeOneIsABinaryCopy) {
  cv::Mat1b mask(10, 10, uchar{0});
  mask(3, 4) = 7;  // any non-zero value is foreground
  for (const auto& op : {Dilate, Erode, Open, Close}) {
    const cv::Mat1b out = op(mask, StructuringShape::kEllipse, 1);
    EXPECT_EQ(out(3, 4), 255);
    EXPECT_EQ(cv::countNonZero(out), 1);
  }
}

TEST(FillHoles, FillsARingButNotARegionOpenToTheBorder) {
  cv::Mat1b mask(100, 100, uchar{0});
  cv::circle(mask, cv::Point(60, 60), 20, cv::Scalar(255), 2, cv::LINE_8);
  // A "U" against the left border: the region it encloses with the border is open, not a hole.
  mask(cv::Rect(0, 5, 30, 2)).setTo(255);
  mask(cv::Rect(0, 25, 30, 2)).setTo(255);
  mask(cv::Rect(28, 5, 2, 22)).setTo(255);

  const cv::Mat1b filled = FillHoles(mask);
  // The ring's inside is filled, and nothing outside its outer edge is added.
  EXPECT_EQ(cv::countNonZero(filled(cv::Rect(45, 45, 30, 30))), 30 * 30);
  cv::Mat1b disc(100, 100, uchar{0});
  cv::circle(disc, cv::Point(60, 60), 22, cv::Scalar(255), cv::FILLED, cv::LINE_8);
  EXPECT_EQ(cv::countNonZero(filled & ~mask & ~disc), 0);
  // The U's inside stays background; the U itself stays foreground.
  EXPECT_EQ(cv::countNonZero(filled(cv::Rect(0, 7, 28, 18))), 0);
  EXPECT_EQ(cv::countNonZero(filled & mask), cv::countNonZero(mask));
}

TEST(FillHoles, EightConnectedOutlineEnclosesAHole) {
  // A diamond |dx| + |dy| = r is 8-connected; its inside is a hole for 4-connected background.
  const int r = 10, c = 15;
  cv::Mat1b mask(31, 31, uchar{0});
  for (int y = 0; y < mask.rows; ++y) {
    for (int x = 0; x < mask.cols; ++x) {
      if (std::abs(x - c) + std::abs(y - c) == r) mask(y, x) = 255;
    }
  }
  EXPECT_EQ(cv::countNonZero(FillHoles(mask)), 2 * r * r + 2 * r + 1);
}

TEST(FillHoles, RegionCutByTheBorderIsNotFilled) {
  // A ring whose centre is in the corner: its inside touches the image border.
  cv::Mat1b mask(50, 50, uchar{0});
  cv::circle(mask, cv::Point(0, 0), 20, cv::Scalar(255), 2, cv::LINE_8);
  EXPECT_EQ(Differences(FillHoles(mask), mask), 0);
}

TEST(CloseFillOpen, ClosesAGappedOutlineFillsItAndDropsSpecks) {
  const cv::Rect rect(20, 20, 60, 40);
  cv::Mat1b edges(100, 120, uchar{0});
  cv::rectangle(edges, rect, cv::Scalar(255), 1);
  edges(cv::Rect(40, 20, 3, 1)).setTo(0);  // 3-pixel gaps in the outline
  edges(cv::Rect(79, 35, 1, 3)).setTo(0);
  edges(90, 80) = 255;  // isolated speck
  const cv::Mat1b mask = CloseFillOpen(edges, MorphologyOptions{});
  EXPECT_EQ(mask(90, 80), 0);
  EXPECT_EQ(cv::countNonZero(mask(cv::Rect(22, 22, 56, 36))), 56 * 36);
  EXPECT_NEAR(cv::countNonZero(mask), rect.area(), 0.05 * rect.area());

  // Without filling, the inside stays empty.
  MorphologyOptions no_fill;
  no_fill.fill_holes = false;
  no_fill.open_size = 1;
  EXPECT_EQ(cv::countNonZero(CloseFillOpen(edges, no_fill)(cv::Rect(30, 30, 40, 20))), 0);
}

TEST(MorphologyOptions, DefaultsAreValid) {
  EXPECT_THAT(MorphologyOptions{}.Validate(), IsEmpty());
}

TEST(MorphologyOptions, ListsEveryProblem) {
  MorphologyOptions options;
  options.shape = static_cast<StructuringShape>(7);
  options.close_size = 4;
  options.open_size = 0;
  EXPECT_THAT(options.Validate(),
              UnorderedElementsAre("shape: unknown value 7",
                                   "close_size: must be in [1, 101] pixels and odd (got 4)",
                                   "open_size: must be in [1, 101] pixels and odd (got 0)"));
}

}  // namespace
}  // namespace stevi::extraction
