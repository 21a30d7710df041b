#include "core/detection/ground.h"

#include <algorithm>
#include <cstdint>
#include <cmath>
#include <cstdio>
#include <random>

namespace stevi::detection {
namespace {

// A constant disparity that explains this share of a ground line's supporting rows makes them a
// wall (see FitGround).
constexpr double kWallShare = 0.8;
// ... unless the rows are filled across at least this fraction of the width, as ground fills them.
constexpr double kGroundSpread = 0.6;

struct RowMode {
  double row;
  double disparity_px;  // the mode bin's mean disparity
  int count;
  double spread;  // the mode's pixels' extent across the row, as a fraction of the width
};

}  // namespace

std::vector<std::string> GroundOptions::Validate() const { return fields::Check(*this); }

namespace {

// The mode of each row (1 px bins), kept when it dominates the row.
std::vector<RowMode> RowModes(const cv::Mat1s& fixed, int max_bin, const GroundOptions& options) {
  std::vector<RowMode> modes;
  std::vector<int> bins(max_bin);
  std::vector<int64_t> sums(max_bin);  // of fixed-point values: exact
  std::vector<int> first_x(max_bin), last_x(max_bin);
  for (int y = 0; y < fixed.rows; ++y) {
    std::fill(bins.begin(), bins.end(), 0);
    std::fill(sums.begin(), sums.end(), 0);
    const int16_t* row = fixed[y];
    int matched = 0;
    for (int x = 0; x < fixed.cols; ++x) {
      if (row[x] < stereo::DisparityMap::kScale) continue;  // unmatched, or below 1 px
      const int bin = std::min(max_bin - 1, row[x] / stereo::DisparityMap::kScale);
      if (bins[bin]++ == 0) first_x[bin] = x;  // x only grows: the first is the smallest
      sums[bin] += row[x];
      last_x[bin] = x;
      ++matched;
    }
    // The row's three most common disparities may each be the ground's: an obstacle standing on
    // the ground can hold more of a row's pixels than the ground does.
    for (int rank = 0; rank < 3; ++rank) {
      const auto best = std::max_element(bins.begin(), bins.end());
      const int bin = static_cast<int>(best - bins.begin());
      if (*best < options.min_row_pixels) break;
      if (*best >= options.min_row_fraction * matched / (rank + 1) &&
          last_x[bin] - first_x[bin] >= options.min_row_spread * fixed.cols) {
        const double mode_px =
            static_cast<double>(sums[bin]) / *best / stereo::DisparityMap::kScale;
        const double spread = static_cast<double>(last_x[bin] - first_x[bin]) / fixed.cols;
        if (mode_px >= options.min_mode_px)
          modes.push_back({static_cast<double>(y), mode_px, *best, spread});
      }
      *best = 0;
    }
  }
  return modes;
}

// Model selection against the other surface that fills rows at one disparity per row: a
// fronto-parallel wall (a building front, a hangar) is a line of slope 0 in v-disparity. When
// one constant disparity explains nearly as many of the supporting rows as the slanted line
// does, and those rows are filled only across part of the view (the ground fills its rows from
// edge to edge, bar what stands on it), the rows are a wall seen where the ground went
// unmatched, and no ground is modelled: taking the wall for ground would drop the obstacle as
// terrain. (Far ground seen from high up also spans little disparity, but fills its rows.)
bool LooksLikeAWall(const std::vector<const RowMode*>& inliers, double best_score,
                    const GroundOptions& options) {
  std::vector<double> ds, spreads;
  ds.reserve(inliers.size());
  spreads.reserve(inliers.size());
  for (const RowMode* m : inliers) {
    ds.push_back(m->disparity_px);
    spreads.push_back(m->spread);
  }
  std::nth_element(ds.begin(), ds.begin() + static_cast<std::ptrdiff_t>(ds.size() / 2), ds.end());
  std::nth_element(spreads.begin(),
                   spreads.begin() + static_cast<std::ptrdiff_t>(spreads.size() / 2),
                   spreads.end());
  const double wall_d = ds[ds.size() / 2];
  const double median_spread = spreads[spreads.size() / 2];
  double wall_score = 0, last_row = -1;
  for (const RowMode* m : inliers) {
    if (std::abs(m->disparity_px - wall_d) <= options.inlier_px && m->row != last_row) {
      wall_score += 1;
      last_row = m->row;
    }
  }
  return wall_score >= kWallShare * best_score && median_spread < kGroundSpread;
}

// Least squares d = s * row + c over the inlier rows, weighted by their pixel counts; nullopt when
// the line does not get nearer towards the bottom or its horizon is far off the image.
std::optional<GroundModel> FitLine(const std::vector<const RowMode*>& inliers, int rows,
                                   double best_score) {
  double sw = 0, sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (const RowMode* m : inliers) {
    const double w = m->count;
    sw += w;
    sx += w * m->row;
    sy += w * m->disparity_px;
    sxx += w * m->row * m->row;
    sxy += w * m->row * m->disparity_px;
  }
  const double denominator = sw * sxx - sx * sx;
  if (std::abs(denominator) < 1e-9) return std::nullopt;
  const double slope = (sw * sxy - sx * sy) / denominator;
  const double intercept = (sy - slope * sx) / sw;
  if (!(slope > 1e-3)) return std::nullopt;
  GroundModel model;
  model.slope = slope;
  model.horizon_row = -intercept / slope;
  if (model.horizon_row < -rows || model.horizon_row > 2.0 * rows) return std::nullopt;
  model.support_rows = static_cast<int>(best_score);
  return model;
}

}  // namespace

std::optional<GroundModel> FitGround(const stereo::DisparityMap& disparity,
                                     const GroundOptions& options) {
  const cv::Mat1s& fixed = disparity.fixed;
  if (fixed.empty()) return std::nullopt;
  const int max_bin = std::max(1, disparity.min_disparity + disparity.num_disparities) + 1;

  const std::vector<RowMode> modes = RowModes(fixed, max_bin, options);
  if (static_cast<int>(modes.size()) < options.min_support_rows) return std::nullopt;

  // RANSAC over pairs of rows: the line with the most supporting rows. Rows count alike: far
  // terrain fills its rows with many pixels, the ground near the camera often matches sparsely.
  std::mt19937 rng(12345);  // seeded: the same map gives the same model
  std::uniform_int_distribution<size_t> pick(0, modes.size() - 1);
  double best_slope = 0, best_horizon = 0, best_score = -1;
  const auto inliers_of = [&](double slope, double horizon, std::vector<const RowMode*>* out) {
    double score = 0;
    double last_row = -1;
    for (const RowMode& m : modes) {
      if (std::abs(slope * (m.row - horizon) - m.disparity_px) <= options.inlier_px) {
        if (m.row != last_row) score += 1;  // rows count once
        last_row = m.row;
        if (out) out->push_back(&m);
      }
    }
    return score;
  };
  for (int iteration = 0; iteration < 200; ++iteration) {
    const RowMode& a = modes[pick(rng)];
    const RowMode& b = modes[pick(rng)];
    if (std::abs(a.row - b.row) < 5) continue;
    const double slope = (b.disparity_px - a.disparity_px) / (b.row - a.row);
    if (!(slope > 1e-3)) continue;  // ground gets nearer towards the bottom of the image
    const double horizon = a.row - a.disparity_px / slope;
    // A level or moderately pitched camera sees its horizon near the image.
    if (horizon < -fixed.rows || horizon > 2.0 * fixed.rows) continue;
    const double score = inliers_of(slope, horizon, nullptr);
    if (score > best_score) {
      best_score = score;
      best_slope = slope;
      best_horizon = horizon;
    }
  }
  if (best_score < 0) return std::nullopt;
  std::vector<const RowMode*> inliers;
  if (inliers_of(best_slope, best_horizon, &inliers) < options.min_support_rows)
    return std::nullopt;
  double lo = inliers.front()->disparity_px, hi = lo;
  for (const RowMode* m : inliers) {
    lo = std::min(lo, m->disparity_px);
    hi = std::max(hi, m->disparity_px);
  }
  if (hi - lo < options.min_span_px) return std::nullopt;
  if (LooksLikeAWall(inliers, best_score, options)) return std::nullopt;
  return FitLine(inliers, fixed.rows, best_score);
}

bool StandsOutFromGround(const std::optional<GroundModel>& ground, double row, double d_px,
                         const GroundOptions& options) {
  if (!ground) return true;
  const double ground_d = ground->DisparityAt(row);
  return d_px > ground_d + std::max(options.margin_px, options.margin_fraction * ground_d);
}

}  // namespace stevi::detection
