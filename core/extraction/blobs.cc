#include "core/extraction/blobs.h"

#include <cstdlib>
#include <vector>

#include <opencv2/imgproc.hpp>

namespace stevi::extraction {
namespace {

struct Shape {
  double perimeter_px = 0;
  cv::Moments moments;
};

// Raw moments of a region moved by (dx, dy): sum of (x + dx)^p (y + dy)^q over the pixels. The
// central and normalised moments do not change.
cv::Moments Shifted(const cv::Moments& m, double dx, double dy) {
  cv::Moments s = m;
  const double dx2 = dx * dx, dy2 = dy * dy;
  s.m10 = m.m10 + dx * m.m00;
  s.m01 = m.m01 + dy * m.m00;
  s.m20 = m.m20 + 2 * dx * m.m10 + dx2 * m.m00;
  s.m11 = m.m11 + dx * m.m01 + dy * m.m10 + dx * dy * m.m00;
  s.m02 = m.m02 + 2 * dy * m.m01 + dy2 * m.m00;
  s.m30 = m.m30 + 3 * dx * m.m20 + 3 * dx2 * m.m10 + dx2 * dx * m.m00;
  s.m21 = m.m21 + dy * m.m20 + 2 * dx * m.m11 + 2 * dx * dy * m.m10 + dx2 * m.m01 +
          dx2 * dy * m.m00;
  s.m12 = m.m12 + dx * m.m02 + 2 * dy * m.m11 + 2 * dx * dy * m.m01 + dy2 * m.m10 +
          dx * dy2 * m.m00;
  s.m03 = m.m03 + 3 * dy * m.m02 + 3 * dy2 * m.m01 + dy2 * dy * m.m00;
  return s;
}

// Length of the outer contour of `label` inside `bbox` of `labels`, and the label's moments.
// Works on the ROI only, padded by one pixel so that contours touching the box's edge are closed
// like any other.
Shape BlobShape(const cv::Mat1i& labels, int label, const cv::Rect& bbox) {
  cv::Mat1b roi_mask(bbox.height + 2, bbox.width + 2, uchar{0});
  const cv::Mat1i roi = labels(bbox);
  for (int y = 0; y < roi.rows; ++y) {
    const int* src = roi[y];
    uchar* dst = roi_mask[y + 1] + 1;
    for (int x = 0; x < roi.cols; ++x) dst[x] = src[x] == label ? 255 : 0;
  }
  Shape shape;
  // Moments in ROI coordinates (small numbers, no cancellation), then moved to the image.
  const cv::Moments local =
      cv::moments(roi_mask(cv::Rect(1, 1, bbox.width, bbox.height)), /*binaryImage=*/true);
  shape.moments = Shifted(local, bbox.x, bbox.y);
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(roi_mask, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_NONE);
  // One 8-connected component gives one outer contour; take the longest to be safe.
  for (const auto& contour : contours) {
    const double length = contour.size() == 1 ? 0.0 : cv::arcLength(contour, /*closed=*/true);
    if (length > shape.perimeter_px) shape.perimeter_px = length;
  }
  return shape;
}

// The root of pixel i's set, halving the path on the way.
int Find(std::vector<int>& parent, int i) {
  while (parent[i] != i) {
    parent[i] = parent[parent[i]];
    i = parent[i];
  }
  return i;
}

}  // namespace

BlobSet ExtractDisparityBlobs(const cv::Mat1b& mask, const cv::Mat1s& disparity, int max_step,
                              int min_area_px) {
  BlobSet set;
  if (mask.empty()) return set;
  CV_Assert(disparity.size() == mask.size());
  const int w = mask.cols, h = mask.rows;
  // Union-find over pixel indices. Only mask pixels are ever read, and each is set to itself when
  // the raster scan reaches it, before any union with its (earlier) neighbours: the buffer needs
  // no initialisation and is reused from call to call on this thread (no allocation per frame).
  thread_local std::vector<int> parent_buffer;
  const size_t pixels = static_cast<size_t>(w) * h;
  if (parent_buffer.size() < pixels) parent_buffer.resize(pixels);
  std::vector<int>& parent = parent_buffer;
  const auto joins = [&](int16_t a, int16_t b) { return std::abs(a - b) <= max_step; };
  for (int y = 0; y < h; ++y) {
    const uchar* m = mask[y];
    const int16_t* d = disparity[y];
    const uchar* m_up = y > 0 ? mask[y - 1] : nullptr;
    const int16_t* d_up = y > 0 ? disparity[y - 1] : nullptr;
    for (int x = 0; x < w; ++x) {
      if (m[x] == 0) continue;
      const int i = y * w + x;
      // `root`: the root of i's set so far (i alone, or its left neighbour's); each joining
      // neighbour above merges its set in, the smaller index staying the root.
      int root = i;
      if (x > 0 && m[x - 1] != 0 && joins(d[x], d[x - 1])) root = Find(parent, i - 1);
      if (m_up != nullptr) {
        for (int dx = -1; dx <= 1; ++dx) {
          const int xn = x + dx;
          if (xn < 0 || xn >= w || m_up[xn] == 0 || !joins(d[x], d_up[xn])) continue;
          const int other = Find(parent, i - w + dx);
          if (other < root) {
            if (root != i) parent[root] = other;
            root = other;
          } else if (other > root) {
            parent[other] = root;
          }
        }
      }
      parent[i] = root;
    }
  }
  // Consecutive labels from 1, in raster order of each blob's first pixel, with the statistics of
  // each. A union always makes the smaller index the root, so a pixel's parent comes before it in
  // the scan and has already been pointed at its root: one step finds every root.
  set.labels = cv::Mat1i(h, w, 0);
  int* labels = set.labels.ptr<int>(0);  // continuous: index y * w + x
  struct Acc {
    int area = 0, x0 = 0, y0 = 0, x1 = 0, y1 = 0;
    double sx = 0, sy = 0;
  };
  std::vector<Acc> acc(1);
  for (int y = 0; y < h; ++y) {
    const uchar* m = mask[y];
    for (int x = 0; x < w; ++x) {
      if (m[x] == 0) continue;
      const int i = y * w + x;
      int label;
      if (parent[i] == i) {
        label = static_cast<int>(acc.size());
        acc.push_back({0, x, y, x, y, 0, 0});
      } else {
        const int root = parent[parent[i]];
        parent[i] = root;
        label = labels[root];
      }
      labels[i] = label;
      Acc& a = acc[label];
      ++a.area;
      a.x0 = std::min(a.x0, x);
      a.x1 = std::max(a.x1, x);
      a.y1 = y;
      a.sx += x;
      a.sy += y;
    }
  }
  for (int label = 1; label < static_cast<int>(acc.size()); ++label) {
    const Acc& a = acc[label];
    if (a.area < min_area_px) continue;
    Blob blob;
    blob.label = label;
    blob.bbox = cv::Rect(a.x0, a.y0, a.x1 - a.x0 + 1, a.y1 - a.y0 + 1);
    blob.centroid_px = cv::Point2d(a.sx / a.area, a.sy / a.area);
    blob.area_px = a.area;
    const Shape shape = BlobShape(set.labels, label, blob.bbox);
    blob.perimeter_px = shape.perimeter_px;
    blob.moments = shape.moments;
    set.blobs.push_back(blob);
  }
  return set;
}

BlobSet ExtractBlobs(const cv::Mat1b& mask, int min_area_px) {
  BlobSet set;
  if (mask.empty()) return set;
  cv::Mat stats;
  cv::Mat centroids;
  cv::Mat labels;
  const int n =
      cv::connectedComponentsWithStats(mask, labels, stats, centroids, /*connectivity=*/8, CV_32S);
  set.labels = labels;
  for (int label = 1; label < n; ++label) {
    const int area = stats.at<int>(label, cv::CC_STAT_AREA);
    if (area < min_area_px) continue;
    Blob blob;
    blob.label = label;
    blob.bbox =
        cv::Rect(stats.at<int>(label, cv::CC_STAT_LEFT), stats.at<int>(label, cv::CC_STAT_TOP),
                 stats.at<int>(label, cv::CC_STAT_WIDTH), stats.at<int>(label, cv::CC_STAT_HEIGHT));
    blob.centroid_px = cv::Point2d(centroids.at<double>(label, 0), centroids.at<double>(label, 1));
    blob.area_px = area;
    const Shape shape = BlobShape(set.labels, label, blob.bbox);
    blob.perimeter_px = shape.perimeter_px;
    blob.moments = shape.moments;
    set.blobs.push_back(blob);
  }
  return set;
}

}  // namespace stevi::extraction
