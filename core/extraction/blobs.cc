#include "core/extraction/blobs.h"

#include <algorithm>
#include <cstdint>
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
  s.m21 =
      m.m21 + dy * m.m20 + 2 * dx * m.m11 + 2 * dx * dy * m.m10 + dx2 * m.m01 + dx2 * dy * m.m00;
  s.m12 =
      m.m12 + dx * m.m02 + 2 * dy * m.m11 + 2 * dx * dy * m.m01 + dy2 * m.m10 + dx * dy2 * m.m00;
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

// One run: pixels y, x0..x1 (inclusive) of the mask, each joining the next along the row.
struct Run {
  int y, x0, x1;
};

// The root of run r's set, halving the path on the way.
int Find(std::vector<int>& parent, int r) {
  while (parent[r] != r) {
    parent[r] = parent[parent[r]];
    r = parent[r];
  }
  return r;
}

// Joins the sets of runs a and b; the smaller index stays the root (the run that comes first in
// raster order, which holds the set's first pixel).
void Unite(std::vector<int>& parent, int a, int b) {
  a = Find(parent, a);
  b = Find(parent, b);
  if (a < b) {
    parent[b] = a;
  } else if (b < a) {
    parent[a] = b;
  }
}

// A blob's area, box and coordinate sums while its runs are labelled.
struct BlobStats {
  int area = 0, x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  int64_t sx = 0, sy = 0;
};

// The runs of `mask` (raster order) into `runs`, and in `parent` their union-find sets: two
// 8-neighbours join when their disparities differ by at most max_step. Union-find over runs, not
// pixels: a run is a stretch of a row whose neighbouring pixels join, so the sets are few and the
// checks against the row above mostly meet a run already joined. `run_at`: two rows of the run of
// each column, for this row and the last.
void FindRuns(const cv::Mat1b& mask, const cv::Mat1s& disparity, int max_step,
              std::vector<Run>& runs, std::vector<int>& parent, std::vector<int>& run_at) {
  const int w = mask.cols, h = mask.rows;
  const auto joins = [&](int16_t a, int16_t b) { return std::abs(a - b) <= max_step; };
  runs.clear();
  parent.clear();
  run_at.resize(2 * static_cast<size_t>(w));
  for (int y = 0; y < h; ++y) {
    const uchar* m = mask[y];
    const int16_t* d = disparity[y];
    const uchar* m_up = y > 0 ? mask[y - 1] : nullptr;
    const int16_t* d_up = y > 0 ? disparity[y - 1] : nullptr;
    int* here = run_at.data() + (y & 1) * w;
    const int* up = run_at.data() + ((y & 1) ^ 1) * w;
    int x = 0;
    while (x < w) {
      if (m[x] == 0) {
        ++x;
        continue;
      }
      const int r = static_cast<int>(runs.size());
      runs.push_back({y, x, x});
      parent.push_back(r);
      int joined_up = -1;  // the run above last joined to r: its other pixels need no check
      while (true) {
        here[x] = r;
        if (m_up != nullptr) {
          for (int xn = std::max(0, x - 1); xn <= std::min(w - 1, x + 1); ++xn) {
            if (m_up[xn] == 0 || up[xn] == joined_up || !joins(d[x], d_up[xn])) continue;
            Unite(parent, r, up[xn]);
            joined_up = up[xn];
          }
        }
        if (x + 1 < w && m[x + 1] != 0 && joins(d[x + 1], d[x])) {
          ++x;
          continue;
        }
        runs[r].x1 = x;
        ++x;
        break;
      }
    }
  }
}

// Consecutive labels from 1 into `labels` (continuous, zeroed), in raster order of each blob's
// first pixel (its root run comes first), with the statistics of each (index 0 unused).
// `run_label`: a buffer, the label of each run.
std::vector<BlobStats> LabelRuns(const std::vector<Run>& runs, std::vector<int>& parent,
                                 std::vector<int>& run_label, cv::Mat1i& labels) {
  const int w = labels.cols;
  int* out = labels.ptr<int>(0);  // continuous: index y * w + x
  std::vector<BlobStats> acc(1);
  run_label.resize(runs.size());
  for (int r = 0; r < static_cast<int>(runs.size()); ++r) {
    const Run& run = runs[r];
    const int root = Find(parent, r);
    int label;
    if (root == r) {
      label = static_cast<int>(acc.size());
      acc.push_back({0, run.x0, run.y, run.x1, run.y, 0, 0});
    } else {
      label = run_label[root];  // root < r: labelled already
    }
    run_label[r] = label;
    const int length = run.x1 - run.x0 + 1;
    std::fill(out + static_cast<size_t>(run.y) * w + run.x0,
              out + static_cast<size_t>(run.y) * w + run.x1 + 1, label);
    BlobStats& a = acc[label];
    a.area += length;
    a.x0 = std::min(a.x0, run.x0);
    a.x1 = std::max(a.x1, run.x1);
    a.y1 = run.y;
    a.sx += int64_t{run.x0 + run.x1} * length / 2;
    a.sy += int64_t{run.y} * length;
  }
  return acc;
}

}  // namespace

BlobSet ExtractDisparityBlobs(const cv::Mat1b& mask, const cv::Mat1s& disparity, int max_step,
                              int min_area_px, bool shapes) {
  BlobSet set;
  if (mask.empty()) return set;
  CV_Assert(disparity.size() == mask.size());
  // The buffers are reused from call to call on this thread (no allocation per frame).
  thread_local std::vector<Run> runs;
  thread_local std::vector<int> parent;
  thread_local std::vector<int> run_at;
  thread_local std::vector<int> run_label;
  FindRuns(mask, disparity, max_step, runs, parent, run_at);
  set.labels = cv::Mat1i(mask.rows, mask.cols, 0);
  const std::vector<BlobStats> acc = LabelRuns(runs, parent, run_label, set.labels);
  for (int label = 1; label < static_cast<int>(acc.size()); ++label) {
    const BlobStats& a = acc[label];
    if (a.area < min_area_px) continue;
    Blob blob;
    blob.label = label;
    blob.bbox = cv::Rect(a.x0, a.y0, a.x1 - a.x0 + 1, a.y1 - a.y0 + 1);
    blob.centroid_px =
        cv::Point2d(static_cast<double>(a.sx) / a.area, static_cast<double>(a.sy) / a.area);
    blob.area_px = a.area;
    if (shapes) {
      const Shape shape = BlobShape(set.labels, label, blob.bbox);
      blob.perimeter_px = shape.perimeter_px;
      blob.moments = shape.moments;
    }
    set.blobs.push_back(blob);
  }
  set.label_count = static_cast<int>(acc.size());
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
  set.label_count = n;
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
