#include "core/extraction/blobs.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <optional>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

namespace stevi::extraction {
namespace {

// The blob whose bounding box contains `p`, if any.
std::optional<Blob> BlobAt(const BlobSet& set, cv::Point p) {
  for (const Blob& b : set.blobs) {
    if (b.bbox.contains(p)) return b;
  }
  return std::nullopt;
}

TEST(ExtractBlobs, RectanglesHaveExactAreaBoxAndCentroid) {
  cv::Mat1b mask(120, 200, uchar{0});
  const cv::Rect a(10, 20, 30, 15);   // 30 x 15
  const cv::Rect b(100, 50, 41, 27);  // odd sizes
  mask(a).setTo(255);
  mask(b).setTo(255);

  const BlobSet set = ExtractBlobs(mask, 1);
  ASSERT_EQ(set.blobs.size(), 2u);
  ASSERT_EQ(set.labels.size(), mask.size());
  for (const cv::Rect& r : {a, b}) {
    std::optional<Blob> blob = BlobAt(set, r.tl());
    ASSERT_TRUE(blob.has_value()) << r;
    EXPECT_EQ(blob->bbox, r);
    EXPECT_EQ(blob->area_px, r.area());
    EXPECT_DOUBLE_EQ(blob->centroid_px.x, r.x + (r.width - 1) / 2.0);
    EXPECT_DOUBLE_EQ(blob->centroid_px.y, r.y + (r.height - 1) / 2.0);
    // The outer contour through the border pixels' centres: 2 (w - 1) + 2 (h - 1).
    const double want = 2.0 * (r.width + r.height - 2);
    EXPECT_NEAR(blob->perimeter_px, want, 0.05 * want) << r;
    // Every pixel of the rectangle carries the blob's label.
    EXPECT_EQ(cv::countNonZero(set.labels(r) == blob->label), r.area());
  }
}

TEST(ExtractBlobs, DiscHasExactAreaAndCentroid) {
  cv::Mat1b mask(100, 100, uchar{0});
  cv::circle(mask, cv::Point(60, 40), 20, cv::Scalar(255), cv::FILLED, cv::LINE_8);
  const int area = cv::countNonZero(mask);

  const BlobSet set = ExtractBlobs(mask, 1);
  ASSERT_EQ(set.blobs.size(), 1u);
  const Blob& blob = set.blobs[0];
  EXPECT_EQ(blob.area_px, area);
  EXPECT_EQ(blob.bbox, cv::Rect(40, 20, 41, 41));
  // A symmetric disc: the centroid is its centre.
  EXPECT_NEAR(blob.centroid_px.x, 60.0, 1e-9);
  EXPECT_NEAR(blob.centroid_px.y, 40.0, 1e-9);
  // The circumference 2 pi r, within the digitisation error of a chain code.
  EXPECT_NEAR(blob.perimeter_px, 2 * CV_PI * 20, 0.1 * 2 * CV_PI * 20);
}

TEST(ExtractBlobs, MinAreaDropsSmallBlobsButKeepsTheirLabels) {
  cv::Mat1b mask(50, 50, uchar{0});
  mask(cv::Rect(2, 2, 3, 3)).setTo(255);      // 9 px: dropped
  mask(cv::Rect(20, 20, 10, 10)).setTo(255);  // 100 px: kept
  const BlobSet set = ExtractBlobs(mask, 10);
  ASSERT_EQ(set.blobs.size(), 1u);
  EXPECT_EQ(set.blobs[0].area_px, 100);
  EXPECT_EQ(set.blobs[0].bbox, cv::Rect(20, 20, 10, 10));
  // The dropped blob's pixels are still labelled (non-zero, different from the kept blob).
  const int small_label = set.labels(3, 3);
  EXPECT_NE(small_label, 0);
  EXPECT_NE(small_label, set.blobs[0].label);

  // At the threshold itself the blob is kept.
  EXPECT_EQ(ExtractBlobs(mask, 9).blobs.size(), 2u);
}

TEST(ExtractBlobs, DiagonallyTouchingSquaresAreOneBlob) {
  cv::Mat1b mask(40, 40, uchar{0});
  mask(cv::Rect(5, 5, 10, 10)).setTo(255);
  mask(cv::Rect(15, 15, 10, 10)).setTo(255);  // touches (14,14) at a corner only
  const BlobSet set = ExtractBlobs(mask, 1);
  ASSERT_EQ(set.blobs.size(), 1u);
  EXPECT_EQ(set.blobs[0].area_px, 200);
  EXPECT_EQ(set.blobs[0].bbox, cv::Rect(5, 5, 20, 20));
}

TEST(ExtractBlobs, EmptyMaskGivesNoBlobs) {
  const BlobSet set = ExtractBlobs(cv::Mat1b(30, 30, uchar{0}), 1);
  EXPECT_TRUE(set.blobs.empty());
  EXPECT_EQ(set.labels.size(), cv::Size(30, 30));
  EXPECT_EQ(cv::countNonZero(set.labels), 0);
}

TEST(ExtractBlobs, BlobAtTheImageBorderHasAClosedPerimeter) {
  cv::Mat1b mask(30, 30, uchar{0});
  mask(cv::Rect(0, 0, 12, 8)).setTo(255);
  const BlobSet set = ExtractBlobs(mask, 1);
  ASSERT_EQ(set.blobs.size(), 1u);
  EXPECT_NEAR(set.blobs[0].perimeter_px, 2.0 * (12 + 8 - 2), 0.05 * 2.0 * (12 + 8 - 2));
}

// Every raw, central and normalised moment of `got` near `want` (relative, with a floor).
void ExpectMomentsNear(const cv::Moments& got, const cv::Moments& want) {
  const double g[] = {got.m00,  got.m10,  got.m01,  got.m20,  got.m11,  got.m02,
                      got.m30,  got.m21,  got.m12,  got.m03,  got.mu20, got.mu11,
                      got.mu02, got.mu30, got.mu21, got.mu12, got.mu03, got.nu20,
                      got.nu11, got.nu02, got.nu30, got.nu21, got.nu12, got.nu03};
  const double w[] = {want.m00,  want.m10,  want.m01,  want.m20,  want.m11,  want.m02,
                      want.m30,  want.m21,  want.m12,  want.m03,  want.mu20, want.mu11,
                      want.mu02, want.mu30, want.mu21, want.mu12, want.mu03, want.nu20,
                      want.nu11, want.nu02, want.nu30, want.nu21, want.nu12, want.nu03};
  for (size_t i = 0; i < std::size(g); ++i) {
    EXPECT_NEAR(g[i], w[i], 1e-9 * std::max(1.0, std::abs(w[i]))) << "moment #" << i;
  }
}

TEST(ExtractBlobs, MomentsAreThoseOfTheBlobInImageCoordinates) {
  cv::Mat1b mask(200, 300, uchar{0});
  cv::ellipse(mask, cv::Point(210, 140), cv::Size(40, 18), 30, 0, 360, cv::Scalar(255), cv::FILLED);
  mask(cv::Rect(20, 30, 25, 40)).setTo(255);
  const BlobSet set = ExtractBlobs(mask, 1);
  ASSERT_EQ(set.blobs.size(), 2u);
  for (const Blob& blob : set.blobs) {
    const cv::Moments& m = blob.moments;
    EXPECT_DOUBLE_EQ(m.m00, blob.area_px);
    EXPECT_NEAR(m.m10 / m.m00, blob.centroid_px.x, 1e-9);
    EXPECT_NEAR(m.m01 / m.m00, blob.centroid_px.y, 1e-9);
    // The reference: OpenCV's moments of the blob's pixels over the whole image.
    ExpectMomentsNear(m, cv::moments(set.labels == blob.label, /*binaryImage=*/true));
  }
  // The tilted ellipse's orientation from the central moments: 30 degrees (y down).
  const Blob& ellipse = set.blobs[0].bbox.x > 100 ? set.blobs[0] : set.blobs[1];
  const cv::Moments& m = ellipse.moments;
  const double angle_deg = 0.5 * std::atan2(2 * m.mu11, m.mu20 - m.mu02) * 180 / CV_PI;
  EXPECT_NEAR(angle_deg, 30.0, 1.0);
}

TEST(ExtractDisparityBlobs, MomentsAreThoseOfEachBlob) {
  // Two touching rectangles at different disparities come out as two blobs.
  cv::Mat1b mask(120, 160, uchar{0});
  cv::Mat1s disparity(mask.size(), int16_t{0});
  mask(cv::Rect(30, 40, 50, 30)).setTo(255);
  disparity(cv::Rect(30, 40, 50, 30)).setTo(400);
  mask(cv::Rect(80, 35, 40, 50)).setTo(255);
  disparity(cv::Rect(80, 35, 40, 50)).setTo(160);
  const BlobSet set = ExtractDisparityBlobs(mask, disparity, 16, 1);
  ASSERT_EQ(set.blobs.size(), 2u);
  for (const Blob& blob : set.blobs) {
    EXPECT_DOUBLE_EQ(blob.moments.m00, blob.area_px);
    EXPECT_NEAR(blob.moments.m10 / blob.moments.m00, blob.centroid_px.x, 1e-9);
    EXPECT_NEAR(blob.moments.m01 / blob.moments.m00, blob.centroid_px.y, 1e-9);
    ExpectMomentsNear(blob.moments, cv::moments(set.labels == blob.label, true));
  }
}

// The independent reference: a breadth-first flood fill over the 8 neighbours, joining two mask
// pixels when their disparities differ by at most max_step; labels from 1 in raster order of each
// component's first pixel.
cv::Mat1i FloodFillLabels(const cv::Mat1b& mask, const cv::Mat1s& disparity, int max_step,
                          std::vector<int>* areas) {
  cv::Mat1i labels(mask.size(), 0);
  areas->assign(1, 0);
  std::vector<cv::Point> queue;
  for (int y = 0; y < mask.rows; ++y) {
    for (int x = 0; x < mask.cols; ++x) {
      if (mask(y, x) == 0 || labels(y, x) != 0) continue;
      const int label = static_cast<int>(areas->size());
      areas->push_back(0);
      labels(y, x) = label;
      queue.assign(1, cv::Point(x, y));
      for (size_t k = 0; k < queue.size(); ++k) {
        const cv::Point p = queue[k];
        ++(*areas)[label];
        for (int dy = -1; dy <= 1; ++dy) {
          for (int dx = -1; dx <= 1; ++dx) {
            const cv::Point q(p.x + dx, p.y + dy);
            if ((dx == 0 && dy == 0) || q.x < 0 || q.y < 0 || q.x >= mask.cols ||
                q.y >= mask.rows || mask(q) == 0 || labels(q) != 0 ||
                std::abs(disparity(q) - disparity(p)) > max_step) {
              continue;
            }
            labels(q) = label;
            queue.push_back(q);
          }
        }
      }
    }
  }
  return labels;
}

// Random masks and disparities (sparse to dense, smooth to noisy, with steps): the labels equal
// the flood fill's pixel for pixel, and the blobs are exactly its components of min_area or more.
TEST(ExtractDisparityBlobs, EqualsAFloodFillOnRandomInputs) {
  cv::RNG rng(20261121);
  for (int trial = 0; trial < 60; ++trial) {
    const cv::Size size(rng.uniform(1, 90), rng.uniform(1, 70));
    cv::Mat1f noise(size);
    rng.fill(noise, cv::RNG::UNIFORM, 0.0, 1.0);
    cv::Mat1f smooth;
    cv::GaussianBlur(noise, smooth, cv::Size(0, 0), rng.uniform(0.5, 4.0));
    const double fill = rng.uniform(0.2, 0.9);
    cv::Mat1b mask = smooth > (1.0 - fill) * 0.6 + 0.2;
    cv::Mat1s disparity(size);
    rng.fill(disparity, cv::RNG::UNIFORM, 0, 12);  // noise of a few sixteenths
    disparity += cv::Mat1s(size, static_cast<int16_t>(rng.uniform(16, 600)));
    // Steps: a few vertical bands at other disparities.
    for (int band = 0; band < 3; ++band) {
      const int x0 = rng.uniform(0, size.width);
      const int x1 = std::min(size.width, x0 + rng.uniform(1, 20));
      disparity(cv::Rect(x0, 0, x1 - x0, size.height)) +=
          static_cast<int16_t>(rng.uniform(-200, 200));
    }
    const int max_step = rng.uniform(0, 24);
    const int min_area = rng.uniform(1, 20);
    std::vector<int> areas;
    const cv::Mat1i expected = FloodFillLabels(mask, disparity, max_step, &areas);
    const BlobSet set = ExtractDisparityBlobs(mask, disparity, max_step, min_area);
    ASSERT_EQ(cv::countNonZero(set.labels != expected), 0) << "trial " << trial;
    std::vector<int> kept;
    for (int label = 1; label < static_cast<int>(areas.size()); ++label) {
      if (areas[label] >= min_area) kept.push_back(label);
    }
    ASSERT_EQ(set.blobs.size(), kept.size()) << "trial " << trial;
    for (size_t k = 0; k < kept.size(); ++k) {
      EXPECT_EQ(set.blobs[k].label, kept[k]);
      EXPECT_EQ(set.blobs[k].area_px, areas[kept[k]]);
    }
  }
}

}  // namespace
}  // namespace stevi::extraction
