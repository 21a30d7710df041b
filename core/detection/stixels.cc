// The stixel world (stixels.h, README.md "The stixel world"): the columns' cells measured, their
// costs under the ground, object and sky models, each column labelled by dynamic programming and
// walked back into stixels. stixel_obstacles.cc groups the object stixels into obstacles.
#include "core/detection/stixels.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace stevi::detection {
namespace {

constexpr double kSqrtTwoPi = 2.5066282746310002;
// A cell whose model cannot hold it (ground above the ground's horizon) costs this much.
constexpr float kImpossible = 1e4f;
// A segment's measured weight (sum of its cells' inlier probabilities) below this is unmeasured.
constexpr double kMinWeight = 1e-3;
// A cell whose inlier probability is below this is unmeasured when an object's extent is trimmed.
constexpr double kMeasuredCell = 0.1;

// One cell of a column: the median disparity of its matched pixels, and the probability that it
// is an inlier (0 when nothing was matched).
struct Cell {
  float d = -1;
  float p = 0;
};

// The geometry of the columns and cells of one image.
struct Grid {
  int width = 0, height = 0;
  int column_width = 0, cell_height = 0;
  int columns = 0, cells = 0;

  // Cell k counts from the bottom: rows [Top(k), Bottom(k)].
  int Bottom(int k) const { return height - 1 - k * cell_height; }
  int Top(int k) const { return std::max(0, height - (k + 1) * cell_height); }
  int X0(int c) const { return c * column_width; }
  int Width(int c) const { return std::min(column_width, width - X0(c)); }
};

Grid MakeGrid(cv::Size size, const StixelOptions& options) {
  Grid g;
  g.width = size.width;
  g.height = size.height;
  g.column_width =
      std::max(2, static_cast<int>(std::lround(size.width * options.column_width_fraction)));
  g.cell_height =
      std::max(1, static_cast<int>(std::lround(size.width * options.cell_height_fraction)));
  g.columns = (size.width + g.column_width - 1) / g.column_width;
  g.cells = (size.height + g.cell_height - 1) / g.cell_height;
  return g;
}

// The noise model shared by the labelling and the grouping.
struct Model {
  double sigma_px = 0.25;  // a cell's disparity noise
  double object_spread = 0.05;
  double ground_spread = 0.1;
  double floor_px = 1;  // trusted disparity floor (processed pixels)
  double uniform = 64;  // the outlier's span of disparities (its density is 1 / uniform)
  double max_p = 0.95;
  double min_confidence = 0.5;  // pixels less sure than this are not measured
  double baseline_m = 1;        // the rig's
  double max_gap_m = 1;         // StixelOptions::max_gap_m

  double ObjectSigma(double f) const {
    return std::sqrt(sigma_px * sigma_px + object_spread * object_spread * f * f);
  }
  double GroundSigma(double g) const {
    return std::sqrt(sigma_px * sigma_px + ground_spread * ground_spread * g * g);
  }
  double SkySigma() const { return std::max(sigma_px, floor_px / 3); }
};

// -log of the Gaussian-plus-outlier likelihood of disparity d under a model (mean mu, sigma s),
// relative to the outlier alone (so an unmatched cell costs 0 under every model).
float MixtureCost(float d, float p, double mu, double s, double uniform) {
  if (p <= 0) return 0.0f;
  const double z = (d - mu) / s;
  const double k = uniform / (s * kSqrtTwoPi);
  return static_cast<float>(-std::log(1.0 - p + p * k * std::exp(-0.5 * z * z)));
}

// The object disparity bins: spaced 0.75 of the object's sigma, so that rounding a segment's
// disparity to its bin moves it by at most 0.4 sigma.
struct Bins {
  std::vector<double> centre;
  std::vector<double> sigma;      // the object's sigma at each centre
  std::vector<int> of_sixteenth;  // disparity x 16 (rounded) -> nearest bin

  int Of(double d) const {
    const int i =
        std::clamp(static_cast<int>(d * 16 + 0.5), 0, static_cast<int>(of_sixteenth.size()) - 1);
    return of_sixteenth[static_cast<size_t>(i)];
  }
};

Bins MakeBins(const Model& model, double max_d) {
  Bins bins;
  for (double f = 0; f <= max_d + 1e-9; f += 0.75 * model.ObjectSigma(f)) {
    bins.centre.push_back(f);
    bins.sigma.push_back(model.ObjectSigma(f));
  }
  const int n = static_cast<int>(std::ceil(max_d * 16)) + 1;
  bins.of_sixteenth.resize(static_cast<size_t>(n));
  size_t b = 0;
  for (int i = 0; i < n; ++i) {
    const double d = i / 16.0;
    while (b + 1 < bins.centre.size() &&
           std::abs(bins.centre[b + 1] - d) <= std::abs(bins.centre[b] - d)) {
      ++b;
    }
    bins.of_sixteenth[static_cast<size_t>(i)] = static_cast<int>(b);
  }
  return bins;
}

// Measures the cells of column c.
void MeasureColumn(const stereo::DisparityMap& map, const Grid& grid, int c, const Model& model,
                   std::vector<float>& values, std::vector<Cell>& cells) {
  const int x0 = grid.X0(c), w = grid.Width(c);
  const bool has_conf = !map.confidence.empty();
  cells.assign(static_cast<size_t>(grid.cells), Cell{});
  for (int k = 0; k < grid.cells; ++k) {
    values.clear();
    double conf_sum = 0;
    const int top = grid.Top(k), bottom = grid.Bottom(k);
    for (int y = top; y <= bottom; ++y) {
      const int16_t* drow = map.fixed.ptr<int16_t>(y);
      const uint8_t* crow = has_conf ? map.confidence.ptr<uint8_t>(y) : nullptr;
      for (int x = x0; x < x0 + w; ++x) {
        if (drow[x] < 0) continue;
        const double conf = has_conf ? crow[x] / 255.0 : model.max_p;
        if (conf < model.min_confidence) continue;
        values.push_back(static_cast<float>(drow[x]) / stereo::DisparityMap::kScale);
        conf_sum += conf;
      }
    }
    if (values.empty()) continue;
    const size_t mid = values.size() / 2;
    std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(mid),
                     values.end());
    const int area = (bottom - top + 1) * w;
    // The cell's median trusted disparity; its inlier probability is their summed confidence over
    // half the cell's area: a cell half covered by sure values is sure, a textureless sky with a
    // few confident speckles is not.
    Cell& cell = cells[static_cast<size_t>(k)];
    cell.d = values[mid];
    cell.p = static_cast<float>(std::min(model.max_p, conf_sum / (0.5 * area)));
  }
}

// Prefix sums of one column's costs under each model, and of its measurements.
struct ColumnCosts {
  int n = 0, bins = 0;
  std::vector<float> ground, sky;          // n + 1
  std::vector<float> object;               // (n + 1) x bins
  std::vector<double> weight, weighted_d;  // n + 1: sum of p, of p d
  std::vector<double> ground_d;            // n: the ground's disparity at each cell (<= 0: none)
  std::vector<double> ground_sigma;        // n: its sigma
  // The cells a segment may start at: the bottom one, every measured one, the first of each
  // unmeasured run and the first above the ground's horizon. An unmeasured cell costs every model
  // the same (nothing), so a boundary inside an unmeasured run may as well lie at its start.
  std::vector<int> starts;

  float Object(int i, int j, int b) const {  // cells i..j
    return object[static_cast<size_t>(j + 1) * bins + b] -
           object[static_cast<size_t>(i) * bins + b];
  }
  float Ground(int i, int j) const { return ground[j + 1] - ground[i]; }
  float Sky(int i, int j) const { return sky[j + 1] - sky[i]; }
  double Weight(int i, int j) const { return weight[j + 1] - weight[i]; }
  double MeanD(int i, int j) const {
    const double w = Weight(i, j);
    return w > kMinWeight ? (weighted_d[j + 1] - weighted_d[i]) / w : -1;
  }
};

void ComputeColumnCosts(const std::vector<Cell>& cells, const Grid& grid, int c,
                        const std::optional<GroundPlane>& ground, const Model& model,
                        const Bins& bins, ColumnCosts& out) {
  const int n = grid.cells;
  const int nb = static_cast<int>(bins.centre.size());
  out.n = n;
  out.bins = nb;
  out.ground.assign(static_cast<size_t>(n + 1), 0.0f);
  out.sky.assign(static_cast<size_t>(n + 1), 0.0f);
  out.object.assign(static_cast<size_t>(n + 1) * nb, 0.0f);
  out.weight.assign(static_cast<size_t>(n + 1), 0.0);
  out.weighted_d.assign(static_cast<size_t>(n + 1), 0.0);
  out.ground_d.assign(static_cast<size_t>(n), 0.0);
  out.ground_sigma.assign(static_cast<size_t>(n), 0.0);
  out.starts.clear();
  const double u = grid.X0(c) + 0.5 * (grid.Width(c) - 1);
  const double sky_sigma = model.SkySigma();
  for (int k = 0; k < n; ++k) {
    const Cell& cell = cells[static_cast<size_t>(k)];
    const double v = 0.5 * (grid.Top(k) + grid.Bottom(k));
    const double g = ground ? ground->DisparityAt(u, v) : 0.0;
    out.ground_d[static_cast<size_t>(k)] = g;
    out.ground_sigma[static_cast<size_t>(k)] = model.GroundSigma(g);
    // A start at the bottom, at a measured cell, at the first cell of an unmeasured run, and where
    // the ground's horizon is crossed.
    const bool after_measured = k > 0 && cells[static_cast<size_t>(k - 1)].p > 0;
    const bool horizon = k > 0 && out.ground_d[static_cast<size_t>(k - 1)] > 0 && g <= 0;
    if (k == 0 || cell.p > 0 || after_measured || horizon) out.starts.push_back(k);
    float cg = kImpossible;
    if (g > 0) {
      cg = MixtureCost(cell.d, cell.p, g, out.ground_sigma[static_cast<size_t>(k)], model.uniform);
    }
    out.ground[k + 1] = out.ground[k] + cg;
    out.sky[k + 1] = out.sky[k] + MixtureCost(cell.d, cell.p, 0.0, sky_sigma, model.uniform);
    out.weight[k + 1] = out.weight[k] + cell.p;
    out.weighted_d[k + 1] = out.weighted_d[k] + (cell.p > 0 ? cell.p * cell.d : 0.0);
    const float* prev = &out.object[static_cast<size_t>(k) * nb];
    float* row = &out.object[static_cast<size_t>(k + 1) * nb];
    if (cell.p <= 0) {
      std::copy(prev, prev + nb, row);
      continue;
    }
    // Far from the cell's disparity every bin costs the same (the outlier term): -log(1 - p).
    const float far = static_cast<float>(-std::log(1.0 - cell.p));
    for (int b = 0; b < nb; ++b) row[b] = prev[b] + far;
    const double d = cell.d;
    for (int b = bins.Of(d); b >= 0; --b) {
      const double s = bins.sigma[static_cast<size_t>(b)];
      if (d - bins.centre[b] > 6 * s) break;
      row[b] = prev[b] + MixtureCost(cell.d, cell.p, bins.centre[b], s, model.uniform);
    }
    for (int b = bins.Of(d) + 1; b < nb; ++b) {
      const double s = bins.sigma[static_cast<size_t>(b)];
      if (bins.centre[b] - d > 6 * s) break;
      row[b] = prev[b] + MixtureCost(cell.d, cell.p, bins.centre[b], s, model.uniform);
    }
  }
}

// The best labelling of rows 0..j whose last segment has a class: its cost, where the segment
// starts, the class before it (-1: none) and, for objects, its disparity bin.
struct Best {
  float cost = std::numeric_limits<float>::infinity();
  int start = 0;
  int prev = -1;
  int bin = -1;
};

constexpr int kG = 0, kO = 1, kS = 2;

// The transition cost into an object segment of disparity f starting at cell i, after the
// labelling `before` (class `cls`) of cells 0..i-1.
float IntoObject(int cls, const Best& before, int b, int i, const ColumnCosts& costs,
                 const Bins& bins, const StixelOptions& options) {
  const double f = bins.centre[static_cast<size_t>(b)];
  const double s = bins.sigma[static_cast<size_t>(b)];
  if (cls == kG) {
    const double g = costs.ground_d[static_cast<size_t>(i)];
    if (g <= 0) return 0.0f;
    const double sg = costs.ground_sigma[static_cast<size_t>(i)];
    const double tol = 3 * std::sqrt(s * s + sg * sg);
    if (f < g - tol) return static_cast<float>(options.sinking_penalty);
    if (f > g + tol) return static_cast<float>(options.floating_penalty);
    return 0.0f;
  }
  if (cls == kO && before.bin >= 0) {
    const double below = bins.centre[static_cast<size_t>(before.bin)];
    const double sb = bins.sigma[static_cast<size_t>(before.bin)];
    if (f > below + 3 * std::sqrt(s * s + sb * sb)) {
      return static_cast<float>(options.overhang_penalty);
    }
  }
  return 0.0f;
}

// Labels one column: dynamic programming over the segments, then the path back.
void LabelColumn(const ColumnCosts& costs, const Bins& bins, const Model& model,
                 const StixelOptions& options, bool has_ground, std::vector<Best>& dp) {
  const int n = costs.n;
  const float penalty = static_cast<float>(options.segment_penalty);
  dp.assign(static_cast<size_t>(3 * n), Best{});
  auto at = [&](int j, int cls) -> Best& { return dp[static_cast<size_t>(3 * j + cls)]; };
  for (int j = 0; j < n; ++j) {
    for (const int i : costs.starts) {
      if (i > j) break;
      // Costs of cells 0..i-1 by their last class (none when i == 0).
      const Best* before[3] = {nullptr, nullptr, nullptr};
      if (i > 0) {
        for (int cls = 0; cls < 3; ++cls) before[cls] = &at(i - 1, cls);
      }
      // Ground: from the bottom, or behind an object.
      if (has_ground) {
        const float seg = costs.Ground(i, j) + penalty;
        float base = i == 0 ? 0.0f : before[kO]->cost;
        if (base + seg < at(j, kG).cost) at(j, kG) = Best{base + seg, i, i == 0 ? -1 : kO, -1};
      }
      // Sky: from the bottom, above the ground or above an object.
      {
        const float seg = costs.Sky(i, j) + penalty;
        for (int cls : {kG, kO}) {
          const float base = i == 0 ? 0.0f : before[cls]->cost;
          if (base + seg < at(j, kS).cost) at(j, kS) = Best{base + seg, i, i == 0 ? -1 : cls, -1};
          if (i == 0) break;
        }
      }
      // Object: at its measured mean disparity. A segment with no measurement, or one beyond the
      // trusted floor, is no object: the sky (nothing near) explains it as well.
      const double f = costs.MeanD(i, j);
      if (f < model.floor_px) continue;
      const int b = bins.Of(f);
      const float seg = costs.Object(i, j, b) + penalty;
      if (i == 0) {
        if (seg < at(j, kO).cost) at(j, kO) = Best{seg, 0, -1, b};
        continue;
      }
      for (int cls = 0; cls < 3; ++cls) {
        const float base = before[cls]->cost;
        if (!std::isfinite(base)) continue;
        const float total = base + seg + IntoObject(cls, *before[cls], b, i, costs, bins, options);
        if (total < at(j, kO).cost) at(j, kO) = Best{total, i, cls, b};
      }
    }
  }
}

StixelClass ClassOf(int cls) {
  return cls == kG ? StixelClass::kGround : cls == kO ? StixelClass::kObject : StixelClass::kSky;
}

// The confidence-weighted least-squares slope of the measured cells lo..hi (disparity per row).
void FitSlope(const ColumnCosts& costs, const Grid& grid, int lo, int hi, Stixel& s) {
  double sw = 0, sv = 0, sd = 0, svv = 0, svd = 0;
  int measured = 0;
  for (int k = lo; k <= hi; ++k) {
    const double w = costs.Weight(k, k);
    if (w < kMeasuredCell) continue;
    const double v = 0.5 * (grid.Top(k) + grid.Bottom(k));
    const double d = costs.MeanD(k, k);
    ++measured;
    sw += w;
    sv += w * v;
    sd += w * d;
    svv += w * v * v;
    svd += w * v * d;
  }
  s.measured_cells = measured;
  const double var = svv - sv * sv / std::max(sw, 1e-12);
  s.slope_px_per_row = measured >= 3 && var > 0 ? (svd - sv * sd / sw) / var : 0.0;
}

// The stixel of cells lo..hi of column c with class cls (from the DP's `best`).
Stixel MakeStixel(const ColumnCosts& costs, const Bins& bins, const Model& model, const Grid& grid,
                  int c, int cls, int lo, int hi, const Best& best) {
  Stixel s;
  s.column = c;
  s.x0 = grid.X0(c);
  s.width = grid.Width(c);
  s.top_row = grid.Top(hi);
  s.bottom_row = grid.Bottom(lo);
  s.label = ClassOf(cls);
  const int cells = hi - lo + 1;
  s.confidence = costs.Weight(lo, hi) / cells;
  if (cls == kO) {
    FitSlope(costs, grid, lo, hi, s);
    s.disparity_px = costs.MeanD(lo, hi);
    if (s.disparity_px < 0) s.disparity_px = bins.centre[static_cast<size_t>(best.bin)];
    s.sigma_px = model.ObjectSigma(s.disparity_px);
  } else if (cls == kG) {
    s.disparity_px =
        0.5 * (costs.ground_d[static_cast<size_t>(lo)] + costs.ground_d[static_cast<size_t>(hi)]);
    s.sigma_px = model.GroundSigma(s.disparity_px);
  } else {
    s.sigma_px = model.SkySigma();
  }
  return s;
}

// Appends the object stixels of an object segment lo..hi: its measured extent, cut where a run of
// unmeasured cells spans more than max_gap_m at the segment's disparity. Unmeasured cells cost
// every model the same, so the DP may bridge them with one segment (a drone above a hangar at the
// same range); nothing was seen in between, and the grouping joins the pieces again when they lie
// within max_gap_m of each other.
void AppendObject(const ColumnCosts& costs, const Bins& bins, const Model& model, const Grid& grid,
                  int c, int lo, int hi, const Best& best, std::vector<Stixel>& out) {
  const double d = costs.MeanD(lo, hi);
  const double max_gap_rows =
      d > 0 ? model.max_gap_m * d / model.baseline_m : std::numeric_limits<double>::infinity();
  int piece_lo = -1, last_measured = -1;
  for (int k = lo; k <= hi + 1; ++k) {
    const bool measured = k <= hi && costs.Weight(k, k) >= kMeasuredCell;
    if (k <= hi && !measured) continue;
    if (piece_lo >= 0 && (k > hi || (k - last_measured - 1) * grid.cell_height > max_gap_rows)) {
      out.push_back(MakeStixel(costs, bins, model, grid, c, kO, piece_lo, last_measured, best));
      piece_lo = -1;
    }
    if (k > hi) break;
    if (piece_lo < 0) piece_lo = k;
    last_measured = k;
  }
  // No measured cell at all: nothing was seen there.
  if (last_measured < 0) out.push_back(MakeStixel(costs, bins, model, grid, c, kS, lo, hi, best));
}

// Walks the labelling of column c back from its top cell, appending its stixels bottom to top.
void Backtrack(const std::vector<Best>& dp, const ColumnCosts& costs, const Bins& bins,
               const Model& model, const Grid& grid, int c, std::vector<Stixel>& out) {
  const int n = grid.cells;
  int cls = kG;
  for (int k = 1; k < 3; ++k) {
    if (dp[static_cast<size_t>(3 * (n - 1) + k)].cost <
        dp[static_cast<size_t>(3 * (n - 1) + cls)].cost) {
      cls = k;
    }
  }
  const size_t first = out.size();
  int j = n - 1;
  while (j >= 0 && cls >= 0) {
    const Best& best = dp[static_cast<size_t>(3 * j + cls)];
    if (cls == kO) {
      // Appended top piece first, like the other segments (reversed below).
      const size_t at = out.size();
      AppendObject(costs, bins, model, grid, c, best.start, j, best, out);
      std::reverse(out.begin() + static_cast<std::ptrdiff_t>(at), out.end());
    } else {
      out.push_back(MakeStixel(costs, bins, model, grid, c, cls, best.start, j, best));
    }
    j = best.start - 1;
    cls = best.prev;
  }
  std::reverse(out.begin() + static_cast<std::ptrdiff_t>(first), out.end());
}

Model MakeModel(const stereo::DisparityMap& disparity, const geometry::StereoRig& rig,
                const geometry::RangeOptions& range, const StixelOptions& options) {
  Model m;
  m.baseline_m = rig.baseline_m();
  m.max_gap_m = options.max_gap_m;
  m.sigma_px =
      options.disparity_sigma_px > 0 ? options.disparity_sigma_px : range.disparity_sigma_px;
  m.object_spread = options.object_spread_fraction;
  m.ground_spread = options.ground_spread_fraction;
  m.floor_px = range.min_disparity_px;
  m.uniform = std::max(16, disparity.min_disparity + disparity.num_disparities);
  m.max_p = 1.0 - options.min_outlier_probability;
  m.min_confidence = range.min_confidence;
  return m;
}

// The robust spread (1.4826 MAD about the median) of the confident cells' disparities about the
// ground plane, over the cells below its horizon; 0 without a ground or with too few cells. Most
// such cells are ground in most scenes; the median and MAD hold while fewer than half are not.
double MeasuredNoise(const std::vector<std::vector<Cell>>& columns, const Grid& grid,
                     const std::optional<GroundPlane>& ground, const Model& model,
                     std::vector<float>& residuals) {
  if (!ground) return 0.0;
  residuals.clear();
  for (int c = 0; c < grid.columns; ++c) {
    const double u = grid.X0(c) + 0.5 * (grid.Width(c) - 1);
    const std::vector<Cell>& cells = columns[static_cast<size_t>(c)];
    for (int k = 0; k < grid.cells; ++k) {
      const Cell& cell = cells[static_cast<size_t>(k)];
      if (cell.p < 0.5 * model.max_p) continue;
      const double g = ground->DisparityAt(u, 0.5 * (grid.Top(k) + grid.Bottom(k)));
      if (g < model.floor_px) break;  // bottom to top: the horizon is crossed
      residuals.push_back(static_cast<float>(cell.d - g));
    }
  }
  if (residuals.size() < 50) return 0.0;
  const auto median = [&]() {
    const auto mid = residuals.begin() + static_cast<std::ptrdiff_t>(residuals.size() / 2);
    std::nth_element(residuals.begin(), mid, residuals.end());
    return static_cast<double>(*mid);
  };
  const double centre = median();
  for (float& r : residuals) r = std::abs(r - static_cast<float>(centre));
  return 1.4826 * median();
}

}  // namespace

StixelWorld ComputeStixels(const stereo::DisparityMap& disparity, const geometry::StereoRig& rig,
                           const std::optional<GroundPlane>& ground,
                           const geometry::RangeOptions& range, const StixelOptions& options) {
  StixelWorld world;
  if (disparity.empty()) return world;
  const Grid grid = MakeGrid(disparity.fixed.size(), options);
  world.columns = grid.columns;
  world.column_width = grid.column_width;
  world.cell_height = grid.cell_height;
  const Model model = MakeModel(disparity, rig, range, options);
  std::vector<float> values;
  std::vector<std::vector<Cell>> columns(static_cast<size_t>(grid.columns));
  for (int c = 0; c < grid.columns; ++c) {
    MeasureColumn(disparity, grid, c, model, values, columns[static_cast<size_t>(c)]);
  }
  // The labelling keeps the configured noise: on real roads the plane's misfit inflates the
  // measured spread, and a wider object model then merges a car with the facade behind it.
  world.noise_px = std::max(model.sigma_px, MeasuredNoise(columns, grid, ground, model, values));
  const Bins bins = MakeBins(model, model.uniform);
  ColumnCosts costs;
  std::vector<Best> dp;
  world.stixels.reserve(static_cast<size_t>(grid.columns) * 4);
  for (int c = 0; c < grid.columns; ++c) {
    const std::vector<Cell>& cells = columns[static_cast<size_t>(c)];
    ComputeColumnCosts(cells, grid, c, ground, model, bins, costs);
    LabelColumn(costs, bins, model, options, ground.has_value(), dp);
    Backtrack(dp, costs, bins, model, grid, c, world.stixels);
  }
  return world;
}

double HeightAboveGround(const GroundPlane& ground, const geometry::StereoRig& rig, double u,
                         double v, double d_px) {
  // d = a u + b v + c with u = f X / Z + cx, v = f Y / Z + cy, d = f B / Z gives the plane
  // a f X + b f Y + (a cx + b cy + c) Z = f B; the camera lies on its positive side.
  const double f = rig.f_px(), base = rig.baseline_m();
  const double nx = ground.a * f, ny = ground.b * f,
               nz = ground.a * rig.cx() + ground.b * rig.cy() + ground.c;
  const double norm = std::sqrt(nx * nx + ny * ny + nz * nz);
  if (!(norm > 0) || !(d_px > 0)) return 0.0;
  const double z = f * base / d_px;
  const double x = (u - rig.cx()) * z / f, y = (v - rig.cy()) * z / f;
  return (f * base - (nx * x + ny * y + nz * z)) / norm;
}

}  // namespace stevi::detection
