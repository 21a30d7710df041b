#include "tests/testing/gt_obstacles.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>

#include "tests/testing/truth_match.h"

namespace stevi::testing {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kMinIoU = 0.3;
constexpr double kInsideFraction = 0.5;

struct Point {
  float u, v, d;
};

double InlierBand(const GtObstacleOptions& o, double plane_d) {
  return o.ground_inlier_px + o.ground_inlier_fraction * std::max(0.0, plane_d);
}

// Least squares d = a u + b v + c over `points` (at least 3, not collinear).
bool FitPlane(const std::vector<Point>& points, double& a, double& b, double& c) {
  cv::Matx33d ata = cv::Matx33d::zeros();
  cv::Vec3d atb(0, 0, 0);
  for (const Point& p : points) {
    const cv::Vec3d row(p.u, p.v, 1.0);
    ata += row * row.t();
    atb += row * static_cast<double>(p.d);
  }
  cv::Vec3d x;
  if (!cv::solve(ata, atb, x, cv::DECOMP_CHOLESKY)) return false;
  a = x[0];
  b = x[1];
  c = x[2];
  return true;
}

// The plane's normal (unit, camera frame, y down) and the camera height above it; false when the
// plane is not ground-like (normal beyond the tilt limit from the down axis, or the plane above).
bool GroundGeometry(double a, double b, double c, double f_px, double baseline_m, double cx,
                    double cy, double max_tilt_deg, cv::Vec3d& normal, double& height_m) {
  const cv::Vec3d m(a, b, (a * cx + b * cy + c) / f_px);
  const double norm = cv::norm(m);
  if (norm <= 0 || b <= 0) return false;
  normal = m / norm;
  height_m = baseline_m / norm;
  return std::acos(std::clamp(normal[1], -1.0, 1.0)) <= max_tilt_deg * kPi / 180.0;
}

std::optional<GroundPlane> FitGround(const cv::Mat1f& truth, double f_px, double baseline_m,
                                     double cx, double cy, const GtObstacleOptions& o) {
  std::vector<Point> points;
  for (int v = 0; v < truth.rows; ++v) {
    for (int u = 0; u < truth.cols; ++u) {
      if (truth(v, u) > 0)
        points.push_back({static_cast<float>(u), static_cast<float>(v), truth(v, u)});
    }
  }
  if (points.size() < 100) return std::nullopt;
  // Support is counted on every 7th point (enough for the count, a seventh of the time).
  std::vector<Point> subset;
  for (size_t i = 0; i < points.size(); i += 7) subset.push_back(points[i]);
  auto count_inliers = [&](const std::vector<Point>& pts, double a, double b, double c,
                           std::vector<Point>* inliers) {
    int n = 0;
    for (const Point& p : pts) {
      const double plane = a * p.u + b * p.v + c;
      if (std::abs(p.d - plane) <= InlierBand(o, plane)) {
        ++n;
        if (inliers) inliers->push_back(p);
      }
    }
    return n;
  };
  std::mt19937_64 rng(o.seed);
  std::uniform_int_distribution<size_t> pick(0, points.size() - 1);
  int best = -1;
  double ba = 0, bb = 0, bc = 0;
  for (int it = 0; it < o.ransac_iterations; ++it) {
    const Point p[3] = {points[pick(rng)], points[pick(rng)], points[pick(rng)]};
    double a = 0, b = 0, c = 0;
    if (!FitPlane({p[0], p[1], p[2]}, a, b, c)) continue;
    cv::Vec3d normal;
    double height = 0;
    if (!GroundGeometry(a, b, c, f_px, baseline_m, cx, cy, o.max_ground_tilt_deg, normal, height)) {
      continue;
    }
    const int n = count_inliers(subset, a, b, c, nullptr);
    if (n > best) {
      best = n;
      ba = a;
      bb = b;
      bc = c;
    }
  }
  if (best < 0) return std::nullopt;
  // Least squares over all inliers, three times (the band follows the plane).
  GroundPlane g;
  for (int round = 0; round < 3; ++round) {
    std::vector<Point> inliers;
    count_inliers(points, ba, bb, bc, &inliers);
    if (inliers.size() < 3 || !FitPlane(inliers, ba, bb, bc)) return std::nullopt;
  }
  cv::Vec3d normal;
  if (!GroundGeometry(ba, bb, bc, f_px, baseline_m, cx, cy, o.max_ground_tilt_deg, normal,
                      g.height_m)) {
    return std::nullopt;
  }
  g.a = ba;
  g.b = bb;
  g.c = bc;
  g.inliers = count_inliers(points, ba, bb, bc, nullptr);
  g.pitch_deg = std::atan2(normal[2], normal[1]) * 180.0 / kPi;
  g.roll_deg = std::atan2(normal[0], normal[1]) * 180.0 / kPi;
  return g;
}

int Find(std::vector<int>& parent, int i) {
  while (parent[static_cast<size_t>(i)] != i) {
    parent[static_cast<size_t>(i)] = parent[static_cast<size_t>(parent[static_cast<size_t>(i)])];
    i = parent[static_cast<size_t>(i)];
  }
  return i;
}

double Percentile(std::vector<float>& values, double q) {
  if (values.empty()) return 0.0;
  const size_t k = std::min(values.size() - 1, static_cast<size_t>(q * (values.size() - 1) + 0.5));
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(k), values.end());
  return values[k];
}

}  // namespace

GtScene ExtractGtObstacles(const cv::Mat1f& truth_px, double f_px, double baseline_m, double cx,
                           double cy, const GtObstacleOptions& o) {
  GtScene scene;
  scene.classes = cv::Mat1b::zeros(truth_px.size());
  scene.labels = cv::Mat1i::zeros(truth_px.size());
  const int rows = truth_px.rows, cols = truth_px.cols;
  const auto agree = [&](float d, float e) {
    return std::abs(d - e) <= o.join_px + o.join_fraction * std::max(d, e);
  };

  // Fill between scan lines: unknown runs of at most fill_gap_px rows between two agreeing values.
  scene.dense_px = truth_px.clone();
  for (int u = 0; u < cols; ++u) {
    int last = -1;
    for (int v = 0; v < rows; ++v) {
      const float d = truth_px(v, u);
      if (d <= 0) continue;
      if (last >= 0 && v - last > 1 && v - last - 1 <= o.fill_gap_px &&
          agree(truth_px(last, u), d)) {
        const float d0 = truth_px(last, u);
        for (int y = last + 1; y < v; ++y) {
          scene.dense_px(y, u) =
              d0 + (d - d0) * static_cast<float>(y - last) / static_cast<float>(v - last);
        }
      }
      last = v;
    }
  }
  scene.ground = FitGround(truth_px, f_px, baseline_m, cx, cy, o);
  if (!scene.ground) return scene;
  const GroundPlane& g = *scene.ground;
  const cv::Mat1f& dense = scene.dense_px;

  // Height above the plane: h (d - d_plane) / d (the point's offset along the plane's normal).
  cv::Mat1f height(truth_px.size(), 0.0f);
  for (int v = 0; v < rows; ++v) {
    for (int u = 0; u < cols; ++u) {
      const float d = dense(v, u);
      if (d <= 0) continue;
      const double h = g.height_m * (d - g.DisparityAt(u, v)) / d;
      height(v, u) = static_cast<float>(h);
      scene.classes(v, u) = h >= o.min_height_m ? kGtAbove : kGtGround;
    }
  }

  // Depth-consistent components of the obstacle pixels.
  std::vector<int> parent(static_cast<size_t>(rows * cols));
  std::iota(parent.begin(), parent.end(), 0);
  const int r = o.join_radius_px;
  for (int v = 0; v < rows; ++v) {
    for (int u = 0; u < cols; ++u) {
      if (scene.classes(v, u) != kGtAbove) continue;
      const float d = dense(v, u);
      for (int dy = 0; dy <= r; ++dy) {
        for (int dx = -r; dx <= r; ++dx) {
          if (dy == 0 && dx <= 0) continue;
          const int y = v + dy, x = u + dx;
          if (y >= rows || x < 0 || x >= cols || scene.classes(y, x) != kGtAbove) continue;
          if (!agree(d, dense(y, x))) continue;
          const int a = Find(parent, v * cols + u), b = Find(parent, y * cols + x);
          if (a != b) parent[static_cast<size_t>(std::max(a, b))] = std::min(a, b);
        }
      }
    }
  }
  struct Component {
    std::vector<float> d;
    int x0 = 1 << 30, y0 = 1 << 30, x1 = -1, y1 = -1;
    float top = 0;
  };
  std::vector<int> root_of(static_cast<size_t>(rows * cols), -1);
  std::vector<Component> comps;
  std::vector<int> comp_index(static_cast<size_t>(rows * cols), -1);
  for (int v = 0; v < rows; ++v) {
    for (int u = 0; u < cols; ++u) {
      if (scene.classes(v, u) != kGtAbove) continue;
      const int root = Find(parent, v * cols + u);
      int& k = comp_index[static_cast<size_t>(root)];
      if (k < 0) {
        k = static_cast<int>(comps.size());
        comps.emplace_back();
      }
      Component& c = comps[static_cast<size_t>(k)];
      c.d.push_back(dense(v, u));
      c.x0 = std::min(c.x0, u);
      c.y0 = std::min(c.y0, v);
      c.x1 = std::max(c.x1, u);
      c.y1 = std::max(c.y1, v);
      c.top = std::max(c.top, height(v, u));
      root_of[static_cast<size_t>(v * cols + u)] = k;
    }
  }
  scene.components = static_cast<int>(comps.size());
  const double fB = f_px * baseline_m;
  std::vector<int> kept_of(comps.size(), 0);
  std::vector<std::pair<double, int>> order;  // (depth, component)
  for (size_t k = 0; k < comps.size(); ++k) {
    Component& c = comps[k];
    if (static_cast<int>(c.d.size()) < o.min_pixels || c.y1 - c.y0 + 1 < o.min_box_height_px) {
      continue;
    }
    const double median = Percentile(c.d, 0.5);
    if (median <= 0 || fB / median > o.max_depth_m) continue;
    order.emplace_back(fB / median, static_cast<int>(k));
  }
  std::sort(order.begin(), order.end());
  for (const auto& [depth, k] : order) {
    Component& c = comps[static_cast<size_t>(k)];
    GtObstacle ob;
    ob.id = static_cast<int>(scene.obstacles.size()) + 1;
    ob.bbox = cv::Rect(c.x0, c.y0, c.x1 - c.x0 + 1, c.y1 - c.y0 + 1);
    ob.pixels = static_cast<int>(c.d.size());
    ob.median_disparity_px = Percentile(c.d, 0.5);
    ob.median_depth_m = depth;
    ob.depth_p10_m = fB / Percentile(c.d, 0.9);  // the 90th disparity percentile is the near end
    ob.depth_p90_m = fB / Percentile(c.d, 0.1);
    ob.height_top_m = c.top;
    kept_of[static_cast<size_t>(k)] = ob.id;
    scene.obstacles.push_back(ob);
  }
  for (int v = 0; v < rows; ++v) {
    for (int u = 0; u < cols; ++u) {
      const int k = root_of[static_cast<size_t>(v * cols + u)];
      if (k >= 0) scene.labels(v, u) = kept_of[static_cast<size_t>(k)];
    }
  }
  return scene;
}

const char* BoxVerdictName(BoxVerdict verdict) {
  switch (verdict) {
    case BoxVerdict::kMatched: return "matched";
    case BoxVerdict::kFragment: return "fragment";
    case BoxVerdict::kFpStructure: return "fp-structure";
    case BoxVerdict::kFpWrongDepth: return "fp-wrong-depth";
    case BoxVerdict::kFpFree: return "fp-free";
    case BoxVerdict::kFpNoTruth: return "fp-no-truth";
  }
  return "?";
}

DetectionScore ScoreDetections(const GtScene& scene, double f_px, double baseline_m,
                               const std::vector<ScoredBox>& boxes) {
  const cv::Mat1f& truth_px = scene.dense_px;
  DetectionScore s;
  s.obstacles.resize(scene.obstacles.size());
  s.boxes.assign(boxes.size(), BoxVerdict::kFpFree);
  std::vector<cv::Rect> det_boxes, truth_boxes;
  for (const ScoredBox& b : boxes) det_boxes.push_back(b.bbox);
  for (const GtObstacle& o : scene.obstacles) truth_boxes.push_back(o.bbox);
  std::vector<bool> matched(boxes.size(), false);
  for (const auto& [d, t] : MatchByIoU(det_boxes, truth_boxes, kMinIoU)) {
    const size_t di = static_cast<size_t>(d), ti = static_cast<size_t>(t);
    matched[di] = true;
    s.boxes[di] = BoxVerdict::kMatched;
    ObstacleResult& r = s.obstacles[ti];
    r.detection = d;
    r.iou = IoU(det_boxes[di], truth_boxes[ti]);
    const double truth_depth = scene.obstacles[ti].median_depth_m;
    r.range_error_pct = 100.0 * (boxes[di].depth_m - truth_depth) / truth_depth;
    ++s.found;
  }
  const double fB = f_px * baseline_m;
  const cv::Rect image(0, 0, truth_px.cols, truth_px.rows);
  for (size_t d = 0; d < boxes.size(); ++d) {
    if (matched[d]) continue;
    // A fragment of the obstacle it lies most inside (at least half of it).
    double best = 0;
    int best_t = -1;
    for (size_t t = 0; t < truth_boxes.size(); ++t) {
      const double inside = InsideFraction(det_boxes[d], truth_boxes[t]);
      if (inside >= kInsideFraction && inside > best) {
        best = inside;
        best_t = static_cast<int>(t);
      }
    }
    if (best_t >= 0) {
      s.boxes[d] = BoxVerdict::kFragment;
      ++s.obstacles[static_cast<size_t>(best_t)].fragments;
      ++s.fragments;
      continue;
    }
    // A false positive: what the truth says lies inside its box.
    ++s.fp;
    const cv::Rect box = det_boxes[d] & image;
    const double depth = boxes[d].depth_m;
    long known = 0, above = 0, at_depth = 0;
    for (int v = box.y; v < box.y + box.height; ++v) {
      for (int u = box.x; u < box.x + box.width; ++u) {
        const uint8_t cls = scene.classes(v, u);
        if (cls == kGtUnknown) continue;
        ++known;
        if (cls != kGtAbove) continue;
        ++above;
        if (depth > 0 && std::abs(fB / truth_px(v, u) - depth) <= 0.15 * depth) ++at_depth;
      }
    }
    BoxVerdict verdict;
    if (box.area() == 0 || known < 0.1 * box.area()) {
      verdict = BoxVerdict::kFpNoTruth;
      ++s.fp_no_truth;
    } else if (at_depth >= 0.1 * known) {
      verdict = BoxVerdict::kFpStructure;
      ++s.fp_structure;
    } else if (above >= 0.2 * known) {
      verdict = BoxVerdict::kFpWrongDepth;
      ++s.fp_wrong_depth;
    } else {
      verdict = BoxVerdict::kFpFree;
      ++s.fp_free;
    }
    s.boxes[d] = verdict;
  }
  return s;
}

}  // namespace stevi::testing
