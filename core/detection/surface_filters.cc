// The surface tests of RangeRegions' filters (surface_filters.h): the share of a hypothesis' ring
// at its own range (AttachedFraction) and how far the surface under it leans back (LeanBack).
#include "core/detection/surface_filters.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include <opencv2/imgproc.hpp>

namespace stevi::detection {
namespace {

constexpr int kScale = stereo::DisparityMap::kScale;

}  // namespace

double AttachedFraction(const stereo::DisparityMap& disparity, const cv::Mat1i& labels, int label,
                        const cv::Rect& box, double median_px, double min_disparity_px, int ring_in,
                        int ring_out) {
  constexpr int kMinRingPixels = 20;
  const cv::Rect outer =
      (box + cv::Point(-ring_out, -ring_out) + cv::Size(2 * ring_out, 2 * ring_out)) &
      cv::Rect(0, 0, labels.cols, labels.rows);
  const cv::Mat1b mask = (labels(outer) == label);
  cv::Mat1b inner_disc, outer_disc;
  cv::dilate(mask, inner_disc,
             cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * ring_in + 1, 2 * ring_in + 1)));
  cv::dilate(
      mask, outer_disc,
      cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * ring_out + 1, 2 * ring_out + 1)));
  const double band = std::max(1.0, 0.1 * median_px);
  const double lo = std::max(median_px - band, min_disparity_px) * kScale;
  const double hi = (median_px + band) * kScale;
  int ring = 0, attached = 0;
  for (int y = 0; y < outer.height; ++y) {
    const int16_t* d = disparity.fixed[outer.y + y] + outer.x;
    const uchar* in = inner_disc[y];
    const uchar* out = outer_disc[y];
    for (int x = 0; x < outer.width; ++x) {
      if (!out[x] || in[x] || d[x] < min_disparity_px * kScale) continue;
      ++ring;
      if (d[x] >= lo && d[x] <= hi) ++attached;
    }
  }
  return ring < kMinRingPixels ? -1.0 : static_cast<double>(attached) / ring;
}

double LeanBack(const stereo::DisparityMap& disparity, const cv::Mat1i& labels, int label,
                const cv::Rect& box, double median_px, const geometry::StereoRig& rig,
                int min_rows) {
  if (box.height < min_rows) return 0;
  const double lo = 0.7 * median_px * kScale;
  const double hi = 1.3 * median_px * kScale;
  double suu = 0, suv = 0, su = 0, svv = 0, sv = 0, sud = 0, svd = 0, sd = 0, dd = 0;
  int n = 0;
  const double u0 = box.x + 0.5 * box.width, v0 = box.y + 0.5 * box.height;
  for (int y = box.y; y < box.y + box.height; ++y) {
    const int* lab = labels[y];
    const int16_t* d = disparity.fixed[y];
    const double v = y - v0;
    double row_u = 0, row_uu = 0, row_d = 0, row_ud = 0, row_dd = 0;
    int row_n = 0;
    for (int x = box.x; x < box.x + box.width; ++x) {
      if (lab[x] != label || d[x] < lo || d[x] > hi) continue;
      const double value = static_cast<double>(d[x]) / kScale;
      const double u = x - u0;
      row_u += u;
      row_uu += u * u;
      row_d += value;
      row_ud += u * value;
      row_dd += value * value;
      ++row_n;
    }
    suu += row_uu;
    su += row_u;
    suv += v * row_u;
    svv += v * v * row_n;
    sv += v * row_n;
    sud += row_ud;
    svd += v * row_d;
    sd += row_d;
    dd += row_dd;
    n += row_n;
  }
  const cv::Matx33d ata(suu, suv, su, suv, svv, sv, su, sv, n);
  const cv::Vec3d atd(sud, svd, sd);
  if (n < 30) return 0;
  cv::Matx33d inverse;
  if (cv::invert(ata, inverse, cv::DECOMP_CHOLESKY) == 0) return 0;
  const cv::Vec3d p = inverse * atd;  // alpha, beta, disparity at the box centre
  const double residual = std::max(0.0, dd - p.dot(atd));
  const double sigma2 = std::max(residual / std::max(1, n - 3), 1e-4);
  // A block matcher's neighbouring disparities share most of their window: about one
  // independent value per half-window square, so the fit's standard error is that much larger.
  const int block = std::max(1, disparity.block_size);
  const double correlated = std::max(1.0, 0.25 * block * block);
  const double beta_se =
      std::sqrt(sigma2 * inverse(1, 1) * std::min(correlated, static_cast<double>(n)));
  // The lean that the fit shows beyond doubt: beta less three standard errors.
  const double beta = p[1] - 3.0 * beta_se;
  if (!(beta > 0)) return 0;
  // gamma + alpha cx + beta cy with gamma the disparity at (0, 0): the plane's disparity at the
  // principal point.
  const double at_principal = p[2] + p[0] * (rig.cx() - u0) + beta * (rig.cy() - v0);
  const double numerator = beta * rig.f_px();
  if (at_principal <= 0) return std::numeric_limits<double>::infinity();
  return numerator / at_principal;
}

}  // namespace stevi::detection
