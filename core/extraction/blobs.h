// Connected blobs of a binary mask, with their statistics.
#pragma once

#include <vector>

#include <opencv2/core.hpp>

namespace stevi::extraction {

struct Blob {
  int label = 0;  // the blob's value in BlobSet::labels
  cv::Rect bbox;  // pixels, in the image
  cv::Point2d centroid_px;
  int area_px = 0;          // pixel count
  double perimeter_px = 0;  // length of the outer contour
  // Spatial moments of the blob's pixels (each pixel weighs 1) in image coordinates, pixels:
  // m00 = area_px, (m10, m01) / m00 = centroid_px. The central (mu) and normalised (nu) moments
  // are translation invariant.
  cv::Moments moments;
};

struct BlobSet {
  cv::Mat1i labels;  // 0 = background, else the blob's label (labels of dropped blobs are kept)
  std::vector<Blob> blobs;
  int label_count = 0;  // every label in `labels` is below this (dropped blobs' included)
};

// Connected components (8-connectivity) of `mask` (non-zero = foreground) with at least
// min_area_px pixels.
BlobSet ExtractBlobs(const cv::Mat1b& mask, int min_area_px);

// Like ExtractBlobs, but two 8-neighbours of `mask` join only when their values in `disparity`
// (fixed point, CV_16S, the mask's size) differ by at most max_step: surfaces at different ranges
// that touch in the image come out as separate blobs. Mask pixels must hold valid disparities.
BlobSet ExtractDisparityBlobs(const cv::Mat1b& mask, const cv::Mat1s& disparity, int max_step,
                              int min_area_px, bool shapes = true);

}  // namespace stevi::extraction
