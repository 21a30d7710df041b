#include "core/extraction/edges.h"

#include <algorithm>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "core/extraction/blobs.h"
#include "core/extraction/morphology.h"

namespace stevi::extraction {
namespace {

using ::testing::HasSubstr;
using ::testing::UnorderedElementsAre;

// A grey image of `size` at `background` with `rect` at `foreground`, plus seeded Gaussian noise
// of standard deviation `noise_sigma` (grey levels).
cv::Mat1b RectangleImage(cv::Size size, const cv::Rect& rect, int background, int foreground,
                         double noise_sigma, uint64_t seed) {
  cv::Mat1f image(size, static_cast<float>(background));
  image(rect).setTo(foreground);
  cv::Mat1f noise(size);
  cv::RNG rng(seed);
  rng.fill(noise, cv::RNG::NORMAL, 0.0, noise_sigma);
  image += noise;
  cv::Mat1b out;
  image.convertTo(out, CV_8U);  // rounds and saturates
  return out;
}

// The largest blob of `mask`; fails the test when there is none.
Blob LargestBlob(const cv::Mat1b& mask) {
  const BlobSet set = ExtractBlobs(mask, 1);
  EXPECT_FALSE(set.blobs.empty());
  if (set.blobs.empty()) return Blob{};
  return *std::max_element(set.blobs.begin(), set.blobs.end(),
                           [](const Blob& a, const Blob& b) { return a.area_px < b.area_px; });
}

// Every side of `got` within `tol` pixels of `want`'s.
void ExpectBoxNear(const cv::Rect& got, const cv::Rect& want, int tol) {
  EXPECT_NEAR(got.x, want.x, tol) << "got " << got << ", want " << want;
  EXPECT_NEAR(got.y, want.y, tol) << "got " << got << ", want " << want;
  EXPECT_NEAR(got.br().x, want.br().x, tol) << "got " << got << ", want " << want;
  EXPECT_NEAR(got.br().y, want.br().y, tol) << "got " << got << ", want " << want;
}

TEST(DetectEdges, StepEdgeLiesAtTheStepOnly) {
  cv::Mat1b grey(60, 80, uchar{50});
  grey.colRange(40, 80).setTo(200);
  const cv::Mat1b edges = DetectEdges(grey, EdgeOptions{});
  ASSERT_EQ(edges.size(), grey.size());
  // Every row has exactly one edge pixel, next to the step (column 39 or 40); nothing else.
  for (int y = 0; y < edges.rows; ++y) {
    std::vector<int> columns;
    for (int x = 0; x < edges.cols; ++x) {
      if (edges(y, x) != 0) {
        EXPECT_EQ(edges(y, x), 255);
        columns.push_back(x);
      }
    }
    ASSERT_EQ(columns.size(), 1u) << "row " << y;
    EXPECT_TRUE(columns[0] == 39 || columns[0] == 40) << "row " << y << ": " << columns[0];
  }
}

TEST(DetectEdges, LeavesTheInputUntouched) {
  const cv::Mat1b grey = RectangleImage({80, 60}, {20, 20, 30, 20}, 50, 200, 3.0, 3);
  const cv::Mat1b before = grey.clone();
  DetectEdges(grey, EdgeOptions{});
  EXPECT_EQ(cv::countNonZero(grey != before), 0);
}

TEST(DetectEdges, FlatNoisyImageHasNoEdges) {
  const cv::Mat1b grey = RectangleImage({160, 120}, {}, 100, 100, 3.0, 7);
  EXPECT_EQ(cv::countNonZero(DetectEdges(grey, EdgeOptions{})), 0);
}

TEST(DetectEdges, HysteresisThresholdsGateAWeakStep) {
  // A 10-level step gives a 3x3 Sobel gradient magnitude of 4 * 10 = 40 next to it.
  cv::Mat1b grey(40, 40, uchar{100});
  grey(cv::Rect(10, 10, 20, 20)).setTo(110);
  EdgeOptions options;
  options.blur_size = 1;
  EXPECT_EQ(cv::countNonZero(DetectEdges(grey, options)), 0);  // 40 < canny_high = 120
  options.canny_low = 20;
  options.canny_high = 35;
  const cv::Mat1b edges = DetectEdges(grey, options);
  // The square's outline, one pixel wide on one side of the step: about 4 * 20 pixels.
  EXPECT_NEAR(cv::countNonZero(edges), 4 * 20, 8);
  EXPECT_EQ(cv::countNonZero(edges(cv::Rect(13, 13, 14, 14))), 0);  // nothing inside
}

TEST(DetectEdgesAndCloseFillOpen, RecoverAFilledRectangleOnANoisyImage) {
  const cv::Rect rect(100, 70, 90, 60);
  const cv::Mat1b grey = RectangleImage({320, 240}, rect, 80, 170, 3.0, 42);
  const cv::Mat1b edges = DetectEdges(grey, EdgeOptions{});
  const cv::Mat1b mask = CloseFillOpen(edges, MorphologyOptions{});
  const BlobSet set = ExtractBlobs(mask, 1);
  ASSERT_EQ(set.blobs.size(), 1u) << "noise left blobs behind";
  ExpectBoxNear(set.blobs[0].bbox, rect, 2);
  EXPECT_NEAR(set.blobs[0].area_px, rect.area(), 0.05 * rect.area());
}

TEST(DetectEdgesAndCloseFillOpen, FillAnOutlinedRectangle) {
  const cv::Rect rect(40, 30, 120, 80);
  cv::Mat1b grey(200, 240, uchar{60});
  cv::rectangle(grey, rect, cv::Scalar(220), 1);  // one-pixel outline on rect's border pixels
  const cv::Mat1b mask = CloseFillOpen(DetectEdges(grey, EdgeOptions{}), MorphologyOptions{});
  const Blob blob = LargestBlob(mask);
  ExpectBoxNear(blob.bbox, rect, 2);
  EXPECT_NEAR(blob.area_px, rect.area(), 0.05 * rect.area());
  // The inside is filled, not just the outline.
  EXPECT_EQ(cv::countNonZero(mask(cv::Rect(60, 50, 80, 40))), 80 * 40);
}

// The reference: OpenCV's Canny on the smoothed image, as the thesis pipeline calls it. DetectEdges
// feeds Canny its own derivatives (for speed); the edges must be the same, pixel for pixel, for
// every aperture, both norms and several thresholds, on smooth, noisy and random images.
TEST(DetectEdges, EqualsCannyOnTheSmoothedImage) {
  cv::RNG rng(91);
  for (int trial = 0; trial < 24; ++trial) {
    const cv::Size size(rng.uniform(3, 200), rng.uniform(3, 150));
    cv::Mat1b image = RectangleImage(
        size, cv::Rect(size.width / 4, size.height / 4, size.width / 2, size.height / 2), 60, 170,
        rng.uniform(0.0, 30.0), 1000 + trial);
    if (trial % 3 == 0) rng.fill(image, cv::RNG::UNIFORM, 0, 256);
    for (const int aperture : {3, 5, 7}) {
      for (const bool l2 : {false, true}) {
        EdgeOptions options;
        options.blur_size = trial % 2 == 0 ? 3 : 1;
        options.canny_aperture = aperture;
        options.l2_gradient = l2;
        options.canny_low = rng.uniform(5.0, 60.0);
        options.canny_high = options.canny_low + rng.uniform(0.0, 120.0);
        cv::Mat1b smoothed;  // a buffer of its own: blurring into `image`'s would change the input
        if (options.blur_size > 1) {
          cv::GaussianBlur(image, smoothed, cv::Size(options.blur_size, options.blur_size), 0, 0);
        } else {
          smoothed = image;
        }
        cv::Mat1b expected;
        cv::Canny(smoothed, expected, options.canny_low, options.canny_high, aperture, l2);
        const cv::Mat1b got = DetectEdges(image, options);
        ASSERT_EQ(got.size(), expected.size());
        EXPECT_EQ(cv::countNonZero(got != expected), 0)
            << "trial " << trial << ", aperture " << aperture << ", l2 " << l2;
      }
    }
  }
}

TEST(EdgeOptions, DefaultsAreValid) { EXPECT_THAT(EdgeOptions{}.Validate(), ::testing::IsEmpty()); }

TEST(EdgeOptions, ListsEveryProblem) {
  EdgeOptions options;
  options.blur_size = 4;
  options.blur_sigma = -1;
  options.canny_low = 50;
  options.canny_high = 20;
  options.canny_aperture = 4;
  const std::vector<std::string> problems = options.Validate();
  EXPECT_THAT(problems,
              UnorderedElementsAre(HasSubstr("blur_size:"), HasSubstr("blur_sigma:"),
                                   HasSubstr("canny_high:"), HasSubstr("canny_aperture:")));
  for (const std::string& p : problems) EXPECT_THAT(p, HasSubstr("(got ")) << p;

  options = EdgeOptions{};
  options.canny_low = -1;
  options.blur_size = 0;
  EXPECT_THAT(options.Validate(),
              UnorderedElementsAre(HasSubstr("canny_low:"), HasSubstr("blur_size:")));
}

}  // namespace
}  // namespace stevi::extraction
