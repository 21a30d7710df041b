#include "core/detection/ground_plane.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include <Eigen/Dense>

namespace stevi::detection {
namespace {

constexpr double kPi = 3.14159265358979323846;
// The ground layer's half-width in log depth: the disparity's relative error at the floor.
constexpr double kLayerHalfWidth = 0.08;
// Candidate layers tried, deepest first.
constexpr size_t kMaxLayers = 4;

struct Sample {
  float u, v, d;
};

struct Plane {
  double a = 0, b = 0, c = 0;
  double Disparity(const Sample& s) const { return a * s.u + b * s.v + c; }
};

// Least squares d = a u + b v + c over `points` (exact for three); false when degenerate.
bool FitPlane(const std::vector<Sample>& points, Plane& plane) {
  Eigen::Matrix3d normal = Eigen::Matrix3d::Zero();
  Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
  for (const Sample& p : points) {
    const Eigen::Vector3d x(p.u, p.v, 1.0);
    normal += x * x.transpose();
    rhs += x * p.d;
  }
  const Eigen::FullPivLU<Eigen::Matrix3d> lu(normal);
  if (lu.rank() < 3) return false;
  const Eigen::Vector3d abc = lu.solve(rhs);
  plane = {abc.x(), abc.y(), abc.z()};
  return abc.allFinite();
}

// Whether the plane is ground-like (its normal within the tilt of `down`, the camera above it),
// and the camera's distance from it: the plane's disparity is w . (u - cx, v - cy, f) with
// w = (B / height) n for its unit normal n.
bool GroundGeometry(const Plane& p, const geometry::StereoRig& rig, const Eigen::Vector3d& down,
                    double cos_max_tilt, double* height_m) {
  const Eigen::Vector3d w(p.a, p.b, (p.c + p.a * rig.cx() + p.b * rig.cy()) / rig.f_px());
  const double norm = w.norm();
  if (!(norm > 1e-12) || w.dot(down) < cos_max_tilt * norm) return false;
  *height_m = rig.baseline_m() / norm;
  return true;
}

// +1 on the plane, -1 clearly beyond it (where it is ahead of the camera), else 0.
int Vote(const Plane& plane, const Sample& s, const GroundPlaneOptions& o) {
  const double g = plane.Disparity(s);
  if (g <= 0) return 0;
  if (std::abs(s.d - g) <= std::max(o.inlier_px, o.inlier_fraction * g)) return 1;
  return s.d < g - std::max(o.margin_px, o.margin_fraction * g) ? -1 : 0;
}

// A sample's depth below the camera along `down` (metres; <= 0 at or above the camera's level).
double DepthBelow(const Sample& s, const geometry::StereoRig& rig, const Eigen::Vector3d& down) {
  const double along =
      down.x() * (s.u - rig.cx()) + down.y() * (s.v - rig.cy()) + down.z() * rig.f_px();
  return rig.baseline_m() * along / s.d;
}

// The depths below the camera (metres) that at least `need` samples share within kLayerHalfWidth
// (in log z): the local maxima of that count, deepest first, at most kMaxLayers. The ground is the
// lowest surface; roofs, hilltops and what stands on the ground are higher, and mismatches below
// it are sparse.
std::vector<double> LayerCandidates(const std::vector<Sample>& samples,
                                    const geometry::StereoRig& rig, const Eigen::Vector3d& down,
                                    size_t need) {
  constexpr double kBinLog = 0.01;  // 1 % bins
  constexpr double kMinZ = 0.05;
  const int half = static_cast<int>(std::lround(kLayerHalfWidth / kBinLog));
  std::vector<int> counts;
  for (const Sample& s : samples) {
    const double z = DepthBelow(s, rig, down);
    if (!(z > kMinZ)) continue;
    const size_t bin = static_cast<size_t>(std::log(z / kMinZ) / kBinLog);
    if (bin >= counts.size()) counts.resize(bin + 1, 0);
    ++counts[bin];
  }
  const int n = static_cast<int>(counts.size());
  // window[b]: the samples in bins [b - half, b + half].
  std::vector<int> window(static_cast<size_t>(n), 0);
  int sum = 0;
  for (int b = -half; b < n + half; ++b) {
    if (b + half < n) sum += counts[b + half];
    if (b - half - 1 >= 0) sum -= counts[b - half - 1];
    if (b >= 0 && b < n) window[b] = sum;
  }
  std::vector<double> layers;
  for (int b = n - 1; b >= 0 && layers.size() < kMaxLayers; --b) {
    if (window[b] < static_cast<int>(need)) continue;
    // A local maximum over the window's width (ties: the deepest).
    bool peak = true;
    for (int k = std::max(0, b - half); k <= std::min(n - 1, b + half) && peak; ++k) {
      peak = window[k] < window[b] || (window[k] == window[b] && k <= b);
    }
    if (peak) layers.push_back(kMinZ * std::exp((b + 0.5) * kBinLog));
  }
  return layers;
}

// The plane at distance B / kappa from the camera with the normal `down`: d = kappa (down . ray).
Plane LevelPlane(double kappa, const geometry::StereoRig& rig, const Eigen::Vector3d& down) {
  const Eigen::Vector3d w = kappa * down;
  return {w.x(), w.y(), w.z() * rig.f_px() - w.x() * rig.cx() - w.y() * rig.cy()};
}

// Least squares kappa of d = kappa (down . ray) over `points`.
double LevelFit(const std::vector<Sample>& points, const geometry::StereoRig& rig,
                const Eigen::Vector3d& down) {
  double de = 0, ee = 0;
  for (const Sample& p : points) {
    const double e =
        down.x() * (p.u - rig.cx()) + down.y() * (p.v - rig.cy()) + down.z() * rig.f_px();
    de += p.d * e;
    ee += e * e;
  }
  return ee > 0 ? de / ee : 0.0;
}

std::vector<Sample> GridSamples(const cv::Mat1s& fixed, int step, int floor16) {
  std::vector<Sample> samples;
  for (int v = step / 2; v < fixed.rows; v += step) {
    const int16_t* row = fixed[v];
    for (int u = step / 2; u < fixed.cols; u += step) {
      if (row[u] >= floor16) {
        samples.push_back({static_cast<float>(u), static_cast<float>(v),
                           static_cast<float>(row[u]) / stereo::DisparityMap::kScale});
      }
    }
  }
  return samples;
}

// The columns the middle 90 % of `points` span: the ground spreads across the view, while the
// strip a level plane cuts from a wall, or an aircraft seen from above, is compact (a few
// scattered pixels elsewhere must not widen it).
double ColumnSpread(std::vector<Sample> points) {
  if (points.empty()) return 0.0;
  const auto by_u = [](const Sample& x, const Sample& y) { return x.u < y.u; };
  const size_t lo = points.size() / 20, hi = points.size() - 1 - points.size() / 20;
  std::nth_element(points.begin(), points.begin() + static_cast<std::ptrdiff_t>(lo), points.end(),
                   by_u);
  const float u_lo = points[lo].u;
  std::nth_element(points.begin(), points.begin() + static_cast<std::ptrdiff_t>(hi), points.end(),
                   by_u);
  return points[hi].u - u_lo;
}

// A layer refined into a plane: from the level plane at its depth, least squares over the
// plane's samples, three times (the band follows the plane): the full plane where it stays within
// the tilt and keeps as many samples, else the level one where it keeps more (a far strip of
// ground fixes its depth, not its tilt).
struct Candidate {
  bool valid = false;
  Plane plane;
  std::vector<Sample> on;
  int beyond = 0;
  double height_m = 0;
};

Candidate RefineLayer(const std::vector<Sample>& samples, const geometry::StereoRig& rig,
                      const Eigen::Vector3d& down, double layer_m, double cos_max_tilt,
                      const GroundPlaneOptions& options) {
  Candidate c;
  c.plane = LevelPlane(rig.baseline_m() / layer_m, rig, down);
  const auto collect = [&](const Plane& plane) {
    c.on.clear();
    c.beyond = 0;
    for (const Sample& s : samples) {
      const int vote = Vote(plane, s, options);
      if (vote > 0) c.on.push_back(s);
      c.beyond += vote < 0;
    }
    return c.on.size();
  };
  double unused = 0;
  for (int round = 0; round < 3; ++round) {
    const size_t count = collect(c.plane);
    if (count < 3) return c;
    // The full and the level least squares over the plane's samples: the one that keeps more of
    // them (the full one on a tie), or the plane as it was.
    Plane full;
    const bool full_ok =
        FitPlane(c.on, full) && GroundGeometry(full, rig, down, cos_max_tilt, &unused);
    const Plane level = LevelPlane(LevelFit(c.on, rig, down), rig, down);
    Plane best = c.plane;
    size_t best_count = count;
    if (full_ok) {
      const size_t n = collect(full);
      if (n >= best_count) {
        best = full;
        best_count = n;
      }
    }
    if (collect(level) > best_count) best = level;
    c.plane = best;
  }
  collect(c.plane);
  c.valid = GroundGeometry(c.plane, rig, down, cos_max_tilt, &c.height_m);
  return c;
}

}  // namespace

std::optional<GroundPlane> FitGroundPlane(const stereo::DisparityMap& disparity,
                                          const geometry::StereoRig& rig,
                                          const Eigen::Vector3d& down_in_cam, double floor_px,
                                          const GroundPlaneOptions& options) {
  if (!options.enabled || disparity.empty()) return std::nullopt;
  const cv::Mat1s& fixed = disparity.fixed;
  // About 160 samples across, whatever the image's size.
  const int step = std::max(1, fixed.cols / 160);
  const int floor16 =
      std::max(1, static_cast<int>(std::ceil(floor_px * stereo::DisparityMap::kScale)));
  const std::vector<Sample> samples = GridSamples(fixed, step, floor16);
  const size_t min_samples =
      static_cast<size_t>(std::max(3, (options.min_pixels + step * step - 1) / (step * step)));
  if (samples.size() < min_samples) return std::nullopt;
  const double cos_max_tilt = std::cos(options.max_tilt_deg * kPi / 180.0);
  const Eigen::Vector3d down = down_in_cam.normalized();

  // Candidate layers: each sample's depth below the camera along `down`, z = B (down . ray) / d.
  // Each is refined into a plane and scored by its samples less twice those clearly beyond it
  // (seen through it: nothing real is), so that the lowest surface with support wins.
  std::optional<GroundPlane> best;
  int best_score = 0;
  for (const double layer : LayerCandidates(samples, rig, down, min_samples)) {
    Candidate c = RefineLayer(samples, rig, down, layer, cos_max_tilt, options);
    if (!c.valid || c.on.size() < min_samples) continue;
    const int score = static_cast<int>(c.on.size()) - 2 * c.beyond;
    if (score <= best_score) continue;
    if (ColumnSpread(c.on) < options.min_spread * fixed.cols) continue;
    best_score = score;
    best = GroundPlane{c.plane.a, c.plane.b, c.plane.c, static_cast<int>(c.on.size()) * step * step,
                       c.height_m};
  }
  return best;
}

bool StandsOutFromPlane(const std::optional<GroundPlane>& plane, double u, double v, double d_px,
                        const GroundPlaneOptions& options) {
  if (!plane) return true;
  const double g = std::max(0.0, plane->DisparityAt(u, v));
  return d_px > g + std::max(options.margin_px, options.margin_fraction * g);
}

}  // namespace stevi::detection
