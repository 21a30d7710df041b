#include "core/detection/range_scan.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

namespace stevi::detection {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDegPerRad = 180.0 / kPi;
constexpr int kScale = stereo::DisparityMap::kScale;

// atan2(y, x) in degrees, to within 1e-4 degrees: a minimax polynomial for the arctangent on
// [0, 1] (several times faster than std::atan2; azimuths only pick a bin).
double Atan2Deg(double y, double x) {
  const double ax = std::abs(x), ay = std::abs(y);
  const double hi = std::max(ax, ay);
  if (hi == 0) return 0.0;
  const double a = std::min(ax, ay) / hi;
  const double s = a * a;
  double r =
      a *
      (0.99997726 +
       s * (-0.33262347 + s * (0.19354346 + s * (-0.11643287 + s * (0.05265332 - s * 0.0117212)))));
  if (ay > ax) r = kPi / 2 - r;
  if (x < 0) r = kPi - r;
  if (y < 0) r = -r;
  return r * kDegPerRad;
}

// Degrees into (-180, 180].
double Wrap180(double deg) {
  double w = std::fmod(deg, 360.0);  // (-360, 360)
  if (w <= -180.0) w += 360.0;
  if (w > 180.0) w -= 360.0;
  return w;
}

// Degrees into [0, 360).
double Wrap360(double deg) {
  double w = std::fmod(deg, 360.0);
  if (w < 0) w += 360.0;
  return w >= 360.0 ? 0.0 : w;
}

// The azimuths the image covers in the body frame: from start_deg over width_deg (360: all).
struct AzimuthSpan {
  double start_deg = 0;
  double width_deg = 0;
};

// The span of the image's border rays, seen from the body's origin both at infinity (the rays'
// directions) and at `near_depth_m` (where the lever arm moves them most). The azimuth of a point
// moving out along a ray is monotonic, and azimuth has no extremum inside a region that does not
// hold the vertical, so the border at the two depths bounds every pixel's azimuth.
AzimuthSpan ImageAzimuthSpan(const geometry::StereoRig& rig, const Eigen::Isometry3d& body_from_cam,
                             double near_depth_m) {
  const Eigen::Matrix3d r = body_from_cam.linear();
  const Eigen::Vector3d t = body_from_cam.translation();
  const double f = rig.f_px(), cx = rig.cx(), cy = rig.cy();
  const double u_lo = -0.5, u_hi = rig.image_size().width - 0.5;
  const double v_lo = -0.5, v_hi = rig.image_size().height - 0.5;
  // The body's vertical (down or up) inside the image: every azimuth is seen.
  for (const double sign : {1.0, -1.0}) {
    const Eigen::Vector3d vertical_in_cam = r.transpose() * Eigen::Vector3d(0, 0, sign);
    if (vertical_in_cam.z() <= 1e-9) continue;
    const double u = cx + f * vertical_in_cam.x() / vertical_in_cam.z();
    const double v = cy + f * vertical_in_cam.y() / vertical_in_cam.z();
    if (u >= u_lo && u <= u_hi && v >= v_lo && v <= v_hi) return {-180.0, 360.0};
  }
  const Eigen::Vector3d axis = r.col(2);
  const double reference_deg = std::atan2(axis.y(), axis.x()) * kDegPerRad;
  double lo = 0, hi = 0;
  const auto add = [&](double x, double y) {
    if (std::hypot(x, y) < 1e-9) return;
    const double rel = Wrap180(std::atan2(y, x) * kDegPerRad - reference_deg);
    lo = std::min(lo, rel);
    hi = std::max(hi, rel);
  };
  const auto add_pixel = [&](double u, double v) {
    const Eigen::Vector3d ray = r * Eigen::Vector3d(u - cx, v - cy, f);
    add(ray.x(), ray.y());
    const Eigen::Vector3d near = t + (near_depth_m / f) * ray;
    add(near.x(), near.y());
  };
  constexpr int kSamples = 256;  // per side
  for (int i = 0; i <= kSamples; ++i) {
    const double a = static_cast<double>(i) / kSamples;
    add_pixel(u_lo + a * (u_hi - u_lo), v_lo);
    add_pixel(u_lo + a * (u_hi - u_lo), v_hi);
    add_pixel(u_lo, v_lo + a * (v_hi - v_lo));
    add_pixel(u_hi, v_lo + a * (v_hi - v_lo));
  }
  if (hi - lo >= 360.0 - 1e-6) return {-180.0, 360.0};
  return {reference_deg + lo, hi - lo};
}

// The scan's bins for a span: centred on multiples of the bin width (edges on its odd halves), so
// that 1-degree bins nest in MAVLink's OBSTACLE_DISTANCE sectors, which PX4 and ArduPilot centre on
// multiples of 5 degrees: a bin never straddles two sectors.
void SetBins(const AzimuthSpan& span, double width_deg, RangeScan& scan) {
  scan.bin_width_deg = width_deg;
  int count = 0;
  double start = 0;
  if (span.width_deg >= 360.0) {
    start = -180.0 + width_deg / 2;
    count = static_cast<int>(std::ceil(360.0 / width_deg - 1e-9));
  } else {
    const double first = std::floor(span.start_deg / width_deg + 0.5);  // bin centred on first w
    start = (first - 0.5) * width_deg;
    count = std::max(1, static_cast<int>(std::ceil((span.start_deg + span.width_deg) / width_deg +
                                                   0.5 - first - 1e-9)));
  }
  scan.start_azimuth_deg = Wrap180(start);
  scan.range_m.assign(static_cast<size_t>(count), 0.0F);
  scan.support_px.assign(static_cast<size_t>(count), 0);
}

// Per bin, histograms over q = fB / horizontal range in 1/16 px (from 0 to `top`, min_range_m):
// pixel counts and the sums of their exact q. Kept per thread (frames may be scanned on several
// threads at once) and reused.
struct Histograms {
  int bins = 0;
  int top = 0;
  std::vector<int> counts;
  std::vector<float> sums;

  size_t Offset(int bin) const { return static_cast<size_t>(bin) * static_cast<size_t>(top + 1); }
  void Reset(int n, int top_q) {
    bins = n;
    top = top_q;
    counts.assign(Offset(bins), 0);
    sums.assign(Offset(bins), 0.0F);
  }
};

Histograms& HistogramBuffers() {
  thread_local Histograms buffers;
  return buffers;
}

// The bins a histogram's support is counted over: the bin and its neighbours (null at the scan's
// ends, unless it covers the whole circle).
struct BinView {
  const int* own = nullptr;
  const float* own_sum = nullptr;
  const int* left = nullptr;
  const int* right = nullptr;
};

// The nearest supported q of one bin (1/16 px) and its support (0: clear). The support is found
// from the near end: the first window of `window` entries where the bin and its two neighbours hold
// `need` pixels and the bin itself a quarter of them (an obstacle that a bin edge splits keeps its
// support; a speck is still too few). The value is the mean of the bin's own pixels over that
// window and half a window farther, then of those within half a window of that mean, three times,
// never farther than that: it settles on the nearest surface's centre (the first window alone
// would hold its near tail) and cannot drift to a surface behind it.
std::pair<double, int> NearestSupported(const BinView& h, int top, int window, int need) {
  const int own_need = std::max(1, need / 4);
  const auto combined = [&](int q) {
    return h.own[q] + (h.left != nullptr ? h.left[q] : 0) + (h.right != nullptr ? h.right[q] : 0);
  };
  int sum = 0, own = 0;
  int trigger = -1;
  for (int q = top; q >= 0; --q) {
    sum += combined(q);
    own += h.own[q];
    if (q + window <= top) {
      sum -= combined(q + window);
      own -= h.own[q + window];
    }
    if (sum >= need && own >= own_need) {
      trigger = q;
      break;
    }
  }
  if (trigger < 0) return {0.0, 0};
  const auto mean_over = [&](int lo, int hi, int* count) {
    double total = 0;
    int n = 0;
    for (int q = lo; q <= hi; ++q) {
      total += h.own_sum[q];
      n += h.own[q];
    }
    *count = n;
    return n > 0 ? total / n : 0.0;
  };
  const int farthest = std::max(0, trigger - window / 2);
  int n = 0;
  double centre = mean_over(farthest, std::min(top, trigger + window - 1), &n);
  const int half = std::max(1, window / 2);
  for (int iteration = 0; iteration < 3; ++iteration) {
    const int c = static_cast<int>(centre);
    const double next = mean_over(std::max(farthest, c - half), std::min(top, c + half), &n);
    if (n < own_need) break;
    centre = next;
  }
  return {centre, sum};
}

// What the pixel loop needs besides the map.
struct PixelGeometry {
  Eigen::Matrix3d r;  // body_from_cam rotation
  Eigen::Vector3d t;  // lever arm
  double f = 0, cx = 0, cy = 0;
  double baseline_m = 0;
  int floor16 = 0;                  // the trusted floor, fixed point
  double fb16 = 0;                  // f B kScale
  double max_range_sq = 0;          // metres^2
  double max_below = 0, min_z = 0;  // the vertical band (body z, metres)
  double start_deg = 0, width_deg = 1;
  int row_step = 1;
};

// Counts every trusted pixel that stands out from the ground into its bin's histogram.
void FillHistograms(const cv::Mat1s& fixed, const PixelGeometry& g,
                    const std::optional<GroundPlane>& ground, const GroundPlaneOptions& ground_o,
                    Histograms& h) {
  const int top = h.top, bins = h.bins;
  // Metres per unit of the ray (u - cx, v - cy, f) at each fixed-point disparity: B / d.
  const int max_fixed = std::max(g.floor16, top + kScale);
  std::vector<double> scale_of(static_cast<size_t>(max_fixed) + 1, 0.0);
  for (int d16 = 1; d16 <= max_fixed; ++d16) scale_of[d16] = g.baseline_m * kScale / d16;
  const Eigen::Vector3d du = g.r.col(0);
  for (int v = 0; v < fixed.rows; v += g.row_step) {
    // The ground's disparity along the row: row_ground + a u (none without a plane).
    const double row_ground = ground ? ground->b * v + ground->c : 0.0;
    const double ground_du = ground ? ground->a : 0.0;
    const Eigen::Vector3d row_ray = g.r * Eigen::Vector3d(-g.cx, v - g.cy, g.f);
    const int16_t* row = fixed[v];
    for (int u = 0; u < fixed.cols; ++u) {
      const int d16 = row[u];
      if (d16 < g.floor16) continue;
      if (ground) {
        // StandsOutFromPlane, in fixed point.
        const double gd = std::max(0.0, row_ground + ground_du * u);
        if (d16 <= (gd + std::max(ground_o.margin_px, ground_o.margin_fraction * gd)) * kScale) {
          continue;
        }
      }
      const double s = scale_of[std::min(d16, max_fixed)];
      const Eigen::Vector3d ray = row_ray + u * du;
      const double z = s * ray.z() + g.t.z();
      if (z > g.max_below || z < g.min_z) continue;
      const double x = s * ray.x() + g.t.x();
      const double y = s * ray.y() + g.t.y();
      const double rho_sq = x * x + y * y;
      if (rho_sq > g.max_range_sq) continue;
      const double rho = std::sqrt(rho_sq);
      const double q = rho * top > g.fb16 ? g.fb16 / rho : top;
      // In [0, 360): the azimuth and the start both lie within (-180, 180].
      double rel = Atan2Deg(y, x) - g.start_deg;
      if (rel < 0) rel += 360.0;
      int bin = static_cast<int>(rel / g.width_deg);
      // Outside the span (only through the lever arm, nearer than min_range_m): the nearer edge.
      if (bin >= bins) bin = rel - bins * g.width_deg < 360.0 - rel ? bins - 1 : 0;
      const size_t index = h.Offset(bin) + static_cast<size_t>(q);
      ++h.counts[index];
      h.sums[index] += static_cast<float>(q);
    }
  }
}

}  // namespace

std::vector<std::string> RangeScanOptions::Validate() const { return fields::Check(*this); }

double RangeScan::BinCentreDeg(int i) const {
  return Wrap180(start_azimuth_deg + (i + 0.5) * bin_width_deg);
}

int RangeScan::BinOf(double deg) const {
  if (!(bin_width_deg > 0)) return -1;
  const int i = static_cast<int>(Wrap360(deg - start_azimuth_deg) / bin_width_deg);
  return i < static_cast<int>(range_m.size()) ? i : -1;
}

RangeScan ComputeRangeScan(const stereo::DisparityMap& disparity, const geometry::StereoRig& rig,
                           const geometry::RangeOptions& range,
                           const Eigen::Isometry3d& body_from_cam,
                           const std::optional<GroundPlane>& ground,
                           const RangeScanOptions& options) {
  RangeScan scan;
  const double fb = rig.f_px() * rig.baseline_m();
  if (disparity.empty() || !(fb > 0) || !(options.bin_width_deg > 0) || options.row_step < 1) {
    return scan;
  }
  // The trusted floor and the top of the search (the map's pixels).
  double floor_px = range.min_disparity_px;
  if (range.max_range_m > 0) floor_px = std::max(floor_px, fb / range.max_range_m);
  const double top_px =
      std::max(static_cast<double>(disparity.min_disparity + disparity.num_disparities - 1),
               std::ceil(floor_px) + 1.0);
  scan.min_range_m = fb / top_px;
  scan.max_range_m = fb / floor_px;
  SetBins(ImageAzimuthSpan(rig, body_from_cam, scan.min_range_m), options.bin_width_deg, scan);
  const int bins = static_cast<int>(scan.range_m.size());

  PixelGeometry g;
  g.r = body_from_cam.linear();
  g.t = body_from_cam.translation();
  g.f = rig.f_px();
  g.cx = rig.cx();
  g.cy = rig.cy();
  g.baseline_m = rig.baseline_m();
  g.floor16 = static_cast<int>(std::ceil(floor_px * kScale - 1e-9));
  g.fb16 = fb * kScale;
  g.max_range_sq = scan.max_range_m * scan.max_range_m;
  g.max_below = options.max_below_m > 0 ? options.max_below_m : HUGE_VAL;
  g.min_z = options.max_above_m > 0 ? -options.max_above_m : -HUGE_VAL;
  g.start_deg = scan.start_azimuth_deg;
  g.width_deg = options.bin_width_deg;
  g.row_step = options.row_step;
  Histograms& h = HistogramBuffers();
  h.Reset(bins, static_cast<int>(std::lround(top_px * kScale)));
  FillHistograms(disparity.fixed, g, ground, options.ground, h);

  const int window = std::max(1, static_cast<int>(std::lround(options.support_window_px * kScale)));
  const int need = std::max(1, (options.min_support_px + options.row_step - 1) / options.row_step);
  const bool circle = static_cast<double>(bins) * options.bin_width_deg >= 360.0;
  for (int b = 0; b < bins; ++b) {
    BinView view{&h.counts[h.Offset(b)], &h.sums[h.Offset(b)]};
    if (b > 0 || circle) view.left = &h.counts[h.Offset((b + bins - 1) % bins)];
    if (b + 1 < bins || circle) view.right = &h.counts[h.Offset((b + 1) % bins)];
    const auto [q, support] = NearestSupported(view, h.top, window, need);
    if (support == 0) continue;
    scan.range_m[b] =
        static_cast<float>(std::clamp(g.fb16 / q, scan.min_range_m, scan.max_range_m));
    scan.support_px[b] = support;
  }
  return scan;
}

}  // namespace stevi::detection
