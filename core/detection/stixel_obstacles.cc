// The obstacles of a stixel world (ObstaclesFromStixels, README.md "Obstacles"): the object
// stixels that stand out from the ground, joined by union-find across neighbouring columns (split
// by the edges cue when asked), each group measured as one Detection.
#include <algorithm>
#include <cmath>
#include <optional>
#include <vector>

#include "core/detection/stereo_blobs.h"
#include "core/detection/stixels.h"
#include "core/extraction/edges.h"
#include "core/stereo/matcher.h"

namespace stevi::detection {

namespace {

// An object stixel that may become part of an obstacle.
struct Candidate {
  const Stixel* stixel = nullptr;
  int parent = 0;  // union-find
};

int Find(std::vector<Candidate>& c, int i) {
  while (c[static_cast<size_t>(i)].parent != i) {
    c[static_cast<size_t>(i)].parent =
        c[static_cast<size_t>(c[static_cast<size_t>(i)].parent)].parent;
    i = c[static_cast<size_t>(i)].parent;
  }
  return i;
}

bool Keeps(const Stixel& s, const StixelWorld& world, const geometry::StereoRig& rig,
           const std::optional<GroundPlane>& ground, const geometry::RangeOptions& range,
           const StixelOptions& options) {
  if (s.label != StixelClass::kObject) return false;
  const int cells = (s.bottom_row - s.top_row + world.cell_height) / world.cell_height;
  if (cells < options.min_cells) return false;
  // At least one cell's worth of confident measurement.
  if (s.confidence * cells < 1.0) return false;
  if (!geometry::IsTrustedDisparity(s.disparity_px, rig.f_px(), rig.baseline_m(), range)) {
    return false;
  }
  if (ground && s.measured_cells >= 3 && ground->b > 0 &&
      s.slope_px_per_row > options.max_slope_fraction * ground->b) {
    return false;
  }
  if (ground) {
    const double u = s.x0 + 0.5 * (s.width - 1);
    // The height must hold with the disparity smaller by the noise (the point farther along its
    // ray: lower below the horizon, which is where a lying surface can pass for a standing one).
    const double d_far =
        std::max(0.5 * s.disparity_px, s.disparity_px - options.height_sigmas * world.noise_px);
    if (HeightAboveGround(*ground, rig, u, s.top_row, d_far) < options.min_height_above_ground_m) {
      return false;
    }
    const bool standing = ground->DisparityAt(u, s.bottom_row) > 0 &&
                          HeightAboveGround(*ground, rig, u, s.bottom_row, s.disparity_px) < 1.0;
    const double height_m = (s.bottom_row - s.top_row + 1) * rig.baseline_m() / s.disparity_px;
    if (standing && height_m < options.min_standing_height_m) return false;
  }
  return true;
}

// The distance (metres) between the centres of two stixels' columns at their disparities, on
// their shared middle row.
double Gap3d(const Stixel& a, const Stixel& b, const geometry::StereoRig& rig) {
  const double v = 0.5 * (std::max(a.top_row, b.top_row) + std::min(a.bottom_row, b.bottom_row));
  const auto point = [&](const Stixel& s) {
    const double z = rig.f_px() * rig.baseline_m() / s.disparity_px;
    return cv::Vec3d((s.x0 + 0.5 * (s.width - 1) - rig.cx()) * z / rig.f_px(),
                     (v - rig.cy()) * z / rig.f_px(), z);
  };
  return cv::norm(point(a) - point(b));
}

// The edges cue: at a boundary between columns, the fraction of the shared rows where the left
// image has an edge pixel within 2 px of it. An edge running down most of the boundary, with
// disparities that differ by more than the noise, says two objects meet there.
struct EdgeCue {
  cv::Mat1b edges;  // empty: no cue

  double Fraction(int x, int top, int bottom) const {
    if (edges.empty() || bottom < top) return 0.0;
    const int x0 = std::max(0, x - 2), x1 = std::min(edges.cols - 1, x + 1);
    int hit = 0;
    for (int y = top; y <= bottom; ++y) {
      const uint8_t* row = edges.ptr<uint8_t>(y);
      for (int xx = x0; xx <= x1; ++xx) {
        if (row[xx]) {
          ++hit;
          break;
        }
      }
    }
    return static_cast<double>(hit) / (bottom - top + 1);
  }
};

EdgeCue MakeEdgeCue(const cv::Mat& left, const StixelOptions& options) {
  EdgeCue cue;
  if (options.split != StixelOptions::Split::kEdges || left.empty() || left.type() != CV_8UC1) {
    return cue;
  }
  // SteViE's edges: thresholds for a pixel noise of 2 grey levels, scaled by the frame's.
  extraction::EdgeOptions edge_options;
  const double scale = std::clamp(stereo::EstimateNoiseSigma(left) / 2.0, 0.5, 2.0);
  edge_options.canny_low *= scale;
  edge_options.canny_high *= scale;
  cue.edges = extraction::DetectEdges(left, edge_options);
  return cue;
}

// Joins the candidates of neighbouring columns whose rows overlap and disparities agree, unless
// the edge cue separates them.
void JoinNeighbours(std::vector<Candidate>& cands, const geometry::StereoRig& rig, double noise_px,
                    int column_width, int cell_height, const EdgeCue& cue,
                    const StixelOptions& options) {
  for (size_t i = 0; i < cands.size(); ++i) {
    const Stixel& a = *cands[i].stixel;
    for (size_t j = i + 1; j < cands.size(); ++j) {
      const Stixel& b = *cands[j].stixel;
      const int gap = b.column - a.column;
      if (gap > 1 + options.max_gap_columns) break;  // sorted by column
      // Neighbouring columns must share rows; in one column, the stixels must touch.
      const int slack = gap == 0 ? cell_height : 0;
      if (b.top_row > a.bottom_row + slack || a.top_row > b.bottom_row + slack) continue;
      // The depths differ by no more than the disparity noise allows, or the 3-D gap is small
      // (a car's side, a wall at a slant).
      if (std::abs(a.disparity_px - b.disparity_px) >
              options.join_sigmas * std::sqrt(2.0) * noise_px &&
          Gap3d(a, b, rig) > options.max_gap_m) {
        continue;
      }
      if (gap > 0 && std::abs(a.disparity_px - b.disparity_px) > std::sqrt(2.0) * noise_px) {
        // Every column boundary between them (a gap skips columns).
        bool cut = false;
        for (int k = a.column + 1; k <= b.column && !cut; ++k) {
          cut = cue.Fraction(k * column_width, std::max(a.top_row, b.top_row),
                             std::min(a.bottom_row, b.bottom_row)) >= options.split_edge_fraction;
        }
        if (cut) continue;
      }
      const int ra = Find(cands, static_cast<int>(i)), rb = Find(cands, static_cast<int>(j));
      if (ra != rb) cands[static_cast<size_t>(rb)].parent = ra;
    }
  }
}

// The detection of one group: the median of its pixels that agree with their stixels.
std::optional<Detection> GroupDetection(const std::vector<const Stixel*>& group,
                                        const stereo::DisparityMap& disparity,
                                        const geometry::StereoRig& rig,
                                        const geometry::RangeOptions& range,
                                        std::vector<float>& values) {
  values.clear();
  cv::Rect box;
  double area = 0, cx = 0, cy = 0, conf = 0;
  for (const Stixel* s : group) {
    const cv::Rect r(s->x0, s->top_row, s->width, s->bottom_row - s->top_row + 1);
    box = box.area() == 0 ? r : (box | r);
    const double a = r.area();
    area += a;
    cx += a * (r.x + 0.5 * (r.width - 1));
    cy += a * (r.y + 0.5 * (r.height - 1));
    conf += a * s->confidence;
    const double tol = 3 * s->sigma_px;
    for (int y = r.y; y < r.y + r.height; ++y) {
      const int16_t* row = disparity.fixed.ptr<int16_t>(y);
      for (int x = r.x; x < r.x + r.width; ++x) {
        if (row[x] < 0) continue;
        const float d = static_cast<float>(row[x]) / stereo::DisparityMap::kScale;
        if (std::abs(d - s->disparity_px) <= tol) values.push_back(d);
      }
    }
  }
  if (values.empty() || area <= 0) return std::nullopt;
  const size_t mid = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(mid), values.end());
  const double median = values[mid];
  for (float& v : values) v = std::abs(v - static_cast<float>(median));
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(mid), values.end());
  const double spread = 1.4826 * values[mid];
  // About one independent value per half-window square (the matcher's errors are correlated over
  // its window), and the matcher's own systematic error on top.
  const double half = std::max(1.0, disparity.block_size / 2.0);
  const double n_eff = std::max(1.0, static_cast<double>(values.size()) / (half * half));
  Detection d;
  d.bbox = box;
  d.centroid_px = cv::Point2d(cx / area, cy / area);
  d.area_px = static_cast<int>(area);
  d.perimeter_px = 2.0 * (box.width + box.height);
  d.disparity_px = median;
  d.valid_disparities = static_cast<int>(values.size());
  d.valid_fraction = values.size() / area;
  d.disparity_sigma_px =
      std::sqrt(range.disparity_sigma_px * range.disparity_sigma_px + spread * spread / n_eff);
  d.score = conf / area;
  d.extractor = "stixels";
  FillRange(d, rig, range);
  return d;
}

}  // namespace

std::vector<Detection> ObstaclesFromStixels(const StixelWorld& world,
                                            const stereo::DisparityMap& disparity,
                                            const cv::Mat& left, const geometry::StereoRig& rig,
                                            const std::optional<GroundPlane>& ground,
                                            const geometry::RangeOptions& range,
                                            const StixelOptions& options) {
  std::vector<Candidate> cands;
  for (const Stixel& s : world.stixels) {
    if (Keeps(s, world, rig, ground, range, options)) {
      cands.push_back({&s, static_cast<int>(cands.size())});
    }
  }
  const double noise_px =
      options.disparity_sigma_px > 0 ? options.disparity_sigma_px : range.disparity_sigma_px;
  JoinNeighbours(cands, rig, noise_px, world.column_width, world.cell_height,
                 MakeEdgeCue(left, options), options);
  std::vector<std::vector<const Stixel*>> groups(cands.size());
  for (size_t i = 0; i < cands.size(); ++i) {
    groups[static_cast<size_t>(Find(cands, static_cast<int>(i)))].push_back(cands[i].stixel);
  }
  std::vector<Detection> out;
  std::vector<float> values;
  for (const std::vector<const Stixel*>& group : groups) {
    if (group.empty()) continue;
    int lo = group.front()->column, hi = lo;
    for (const Stixel* s : group) {
      lo = std::min(lo, s->column);
      hi = std::max(hi, s->column);
    }
    if (hi - lo + 1 < options.min_columns) continue;
    double support = 0;  // confident pixels
    for (const Stixel* st : group) {
      support += st->confidence * st->width * (st->bottom_row - st->top_row + 1);
    }
    if (support < options.min_support_px) continue;
    std::optional<Detection> d = GroupDetection(group, disparity, rig, range, values);
    if (d) out.push_back(std::move(*d));
  }
  std::sort(out.begin(), out.end(),
            [](const Detection& a, const Detection& b) { return a.range_m < b.range_m; });
  return out;
}

}  // namespace stevi::detection
