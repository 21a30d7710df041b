#include "core/tracking/tracker.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <utility>

#include "core/common/error.h"

namespace stevi::tracking {
namespace {

// Points closer than this along the optical axis (metres) cannot be projected: a prediction that
// gets there has passed the camera and only coasts to its deletion.
constexpr double kMinDepthM = 1e-3;

cv::Vec3d ToCv(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

// A detection the tracker can use: a finite centroid and a finite position in front of the camera,
// scoring at least min_score.
bool Usable(const detection::Detection& d, double min_score) {
  const cv::Vec3d& p = d.position_cam_m;
  if (!(std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]) && p[2] > kMinDepthM)) {
    return false;
  }
  if (!(std::isfinite(d.centroid_px.x) && std::isfinite(d.centroid_px.y))) return false;
  return d.score >= min_score;
}

// The detection's range, or the norm of its position when the range field is not set.
double RawRange(const detection::Detection& d) {
  if (std::isfinite(d.range_m) && d.range_m > 0) return d.range_m;
  return cv::norm(d.position_cam_m);
}

// True when max(a, b) <= max_ratio * min(a, b), or when either value is unknown (<= 0).
bool WithinRatio(double a, double b, double max_ratio) {
  if (!(a > 0) || !(b > 0)) return true;
  return std::max(a, b) <= max_ratio * std::min(a, b);
}

}  // namespace

std::string_view TrackStateName(TrackState state) {
  switch (state) {
    case TrackState::kTentative: return "tentative";
    case TrackState::kConfirmed: return "confirmed";
    case TrackState::kCoasting: return "coasting";
  }
  return "unknown";
}

std::vector<std::string> GateOptions::Validate() const { return fields::Check(*this); }

std::vector<std::string> TrackerOptions::Validate() const {
  std::vector<std::string> problems = fields::Check(*this);
  // Below 1, delete_misses is a problem of its own; the bound is then 1.
  if (tentative_delete_misses > std::max(delete_misses, 1)) {
    problems.push_back("tentative_delete_misses: must be <= delete_misses = " +
                       std::to_string(delete_misses) + Got(tentative_delete_misses));
  }
  // Below 1, confirm_hits is a problem of its own.
  if (confirm_hits >= 1 && confirm_window < confirm_hits) {
    problems.push_back("confirm_window: must be >= confirm_hits = " + std::to_string(confirm_hits) +
                       Got(confirm_window));
  }
  return problems;
}

Tracker::Tracker(TrackerOptions options) { SetOptions(std::move(options)); }

void Tracker::SetOptions(TrackerOptions options) {
  if (std::vector<std::string> problems = options.Validate(); !problems.empty()) {
    throw std::invalid_argument("TrackerOptions: " + InvalidArgument(problems).message);
  }
  options_ = std::move(options);
}

void Tracker::Reset() {
  tracks_.clear();
  last_t_ns_.reset();
  ground_velocity_ = false;
}

namespace {

// A nearer detection cuts another when it is at least this much nearer (depth ratio) and their
// boxes touch (within kTouchPx: blobs of the detectors are separated by a few pixels of
// morphology).
constexpr double kNearerRatio = 1.15;
constexpr int kTouchPx = 4;
// A detection's size agrees with the track's when it differs by at most this fraction of the
// track's size or kSizeTolerancePx, whichever is larger; otherwise it is re-anchored on an edge.
constexpr double kSizeTolerance = 0.15;
constexpr double kSizeTolerancePx = 3.0;
// Variance of a centroid whose blob changed size by s pixels: the centroid may have moved by up to
// s / 2 with the change (one side moved), so (s / 2)^2. A re-anchored centre: the edge is located
// to about a pixel, and the anchoring itself may be wrong by a fraction of the size difference.
constexpr double kAnchorVariancePx2 = 1.0;
constexpr double kAnchorSigmaPerPx = 0.1;
// A shared (merged) detection must cover this fraction of the track's predicted box, and one of its
// edges must agree with the predicted edge within max(kEdgeAgreePx, kEdgeAgreeSigmas sigma).
constexpr double kSharedCover = 0.5;
constexpr double kSharedMinFraction = 0.25;
constexpr double kEdgeAgreePx = 3.0;
constexpr double kEdgeAgreeSigmas = 2.0;
// A detection is inside a track's box (a fragment of it) when at least this fraction of its area
// lies in the track's predicted box.
constexpr double kInsideFraction = 0.5;
// Depth sigma (as a fraction of the depth) of a position-only measurement: no depth information.
constexpr double kNoDepthSigmaFraction = 1e3;

double DepthOf(const detection::Detection& d) {
  return std::isfinite(d.depth_m) && d.depth_m > 0 ? d.depth_m : d.position_cam_m[2];
}

double DepthSigmaOf(const detection::Detection& d) {
  const double range = RawRange(d);
  if (!(std::isfinite(d.range_sigma_m) && d.range_sigma_m > 0 && range > 0)) return 0;
  return d.range_sigma_m * DepthOf(d) / range;
}

double Area(const cv::Rect& r) { return static_cast<double>(r.width) * r.height; }

double IoURect(const cv::Rect& a, const cv::Rect& b) {
  const double inter = Area(a & b);
  const double uni = Area(a) + Area(b) - inter;
  return uni > 0 ? inter / uni : 0.0;
}

cv::Rect RectAround(double u, double v, double w, double h) {
  // Clamped: a prediction near the camera plane must not overflow an int.
  const auto px = [](double x) { return static_cast<int>(std::lround(std::clamp(x, -1e6, 1e6))); };
  const int x0 = px(u - 0.5 * w), y0 = px(v - 0.5 * h);
  return {x0, y0, std::max(1, px(u + 0.5 * w) - x0), std::max(1, px(v + 0.5 * h) - y0)};
}

// The largest of the four strips of a that lie outside b (a itself when they do not overlap).
cv::Rect Subtract(const cv::Rect& a, const cv::Rect& b) {
  const cv::Rect overlap = a & b;
  if (overlap.empty()) return a;
  const cv::Rect strips[] = {{a.x, a.y, overlap.x - a.x, a.height},
                             {overlap.br().x, a.y, a.br().x - overlap.br().x, a.height},
                             {a.x, a.y, a.width, overlap.y - a.y},
                             {a.x, overlap.br().y, a.width, a.br().y - overlap.br().y}};
  cv::Rect best;
  for (const cv::Rect& r : strips) {
    if (r.width > 0 && r.height > 0 && r.area() > best.area()) best = r;
  }
  return best.empty() ? a : best;
}

}  // namespace

void Tracker::FindCuts(const std::vector<detection::Detection>& detections,
                       const CameraModel& camera) {
  cuts_.assign(usable_.size(), Cut{});
  for (size_t k = 0; k < usable_.size(); ++k) {
    const detection::Detection& d = detections[usable_[k]];
    Cut& cut = cuts_[k];
    if (camera.width > 0) {
      cut.left = d.bbox.x <= 0;
      cut.right = d.bbox.x + d.bbox.width >= camera.width;
    }
    if (camera.height > 0) {
      cut.top = d.bbox.y <= 0;
      cut.bottom = d.bbox.y + d.bbox.height >= camera.height;
    }
    const cv::Rect grown(d.bbox.x - kTouchPx, d.bbox.y - kTouchPx, d.bbox.width + 2 * kTouchPx,
                         d.bbox.height + 2 * kTouchPx);
    const cv::Point2d centre(d.bbox.x + 0.5 * d.bbox.width, d.bbox.y + 0.5 * d.bbox.height);
    for (size_t j = 0; j < usable_.size(); ++j) {
      const detection::Detection& o = detections[usable_[j]];
      if (j == k || !(DepthOf(o) * kNearerRatio < DepthOf(d))) continue;
      const cv::Rect overlap = grown & o.bbox;
      if (overlap.empty()) continue;
      // The side the nearer blob is on: the axis along which the overlap is thinner relative to
      // the blob's size.
      const cv::Point2d other(o.bbox.x + 0.5 * o.bbox.width, o.bbox.y + 0.5 * o.bbox.height);
      if (overlap.width * d.bbox.height <= overlap.height * d.bbox.width) {
        (other.x < centre.x ? cut.left : cut.right) = true;
      } else {
        (other.y < centre.y ? cut.top : cut.bottom) = true;
      }
    }
  }
}

Tracker::Prediction Tracker::Predict(const Entry& e, double dt, const CameraModel& camera) const {
  Prediction p;
  p.kalman = e.kalman;
  p.kalman.PredictAngleDepth(dt, options_.kalman.process_noise);
  const ConstantVelocityKalman::State& x = p.kalman.state();
  const ConstantVelocityKalman::Covariance& P = p.kalman.covariance();
  p.z = x(2);
  p.valid = p.z > kMinDepthM;
  if (!p.valid) return p;
  p.u = camera.cx + camera.f_px * x(0);
  p.v = camera.cy + camera.f_px * x(1);
  p.sigma_u = camera.f_px * std::sqrt(std::max(P(0, 0), 0.0));
  p.sigma_v = camera.f_px * std::sqrt(std::max(P(1, 1), 0.0));
  p.var_z = std::max(P(2, 2), 0.0);
  const double scale = e.full_depth_m > 0 ? e.full_depth_m / p.z : 1.0;
  p.size = cv::Size2d(e.full_size.width * scale, e.full_size.height * scale);
  return p;
}

cv::Rect Tracker::PredictedBox(const Prediction& p, double grow_u, double grow_v) {
  return RectAround(p.u, p.v, p.size.width + 2 * grow_u, p.size.height + 2 * grow_v);
}

Tracker::Measured Tracker::Measure(const Entry& e, const Prediction& p,
                                   const detection::Detection& d, const Cut& cut,
                                   bool merged) const {
  Measured m;
  m.centre = d.centroid_px;
  const double base = options_.kalman.measurement_noise;
  // One axis: the detection's extent [lo, lo + size), the track's expected size and predicted
  // centre, which sides are cut, and the centroid's offset from the box centre.
  const auto axis = [&](double lo, double size, double expected, double predicted, bool cut_lo,
                        bool cut_hi, double offset, double& centre, double& variance) {
    const double difference = std::abs(size - expected);
    // A larger blob is re-anchored only when it is a merge of several tracks' obstacles; otherwise
    // the obstacle grew (entering the image, coming out from behind another, closing in).
    if (!(expected > 0) || difference <= std::max(kSizeTolerancePx, kSizeTolerance * expected) ||
        (size > expected && !merged)) {
      variance = base + 0.25 * difference * difference;
      return false;
    }
    const double hi = lo + size;
    bool anchor_lo;
    if (cut_lo != cut_hi) {
      anchor_lo = cut_hi;  // the uncut edge
    } else {
      anchor_lo = std::abs(lo - (predicted - 0.5 * expected)) <=
                  std::abs(hi - (predicted + 0.5 * expected));
    }
    centre = (anchor_lo ? lo + 0.5 * expected : hi - 0.5 * expected) + offset;
    variance = base + kAnchorVariancePx2 + std::pow(kAnchorSigmaPerPx * difference, 2);
    return true;
  };
  if (!p.valid) {
    m.var_u = m.var_v = base;
    return m;
  }
  const bool ax = axis(d.bbox.x, d.bbox.width, p.size.width, p.u, cut.left, cut.right,
                       e.centroid_offset.x, m.centre.x, m.var_u);
  const bool ay = axis(d.bbox.y, d.bbox.height, p.size.height, p.v, cut.top, cut.bottom,
                       e.centroid_offset.y, m.centre.y, m.var_v);
  m.anchored = ax || ay;
  return m;
}

bool Tracker::DepthConsistent(const Prediction& p, const detection::Detection& d) const {
  const GateOptions& gates = options_.gates;
  const double z = DepthOf(d);
  if (!WithinRatio(z, p.z, gates.max_depth_ratio)) return false;
  const double sigma = std::max(DepthSigmaOf(d), gates.min_depth_sigma_fraction * z);
  const double difference = z - p.z;
  return difference * difference <=
         gates.depth_sigmas * gates.depth_sigmas * (sigma * sigma + p.var_z);
}

void Tracker::Correct(Entry& e, const Prediction& p, const detection::Detection& d, const Cut& cut,
                      bool merged, const CameraModel& camera) {
  const Measured measured = Measure(e, p, d, cut, merged);
  e.kalman = p.kalman;
  const AngleDepth m = MeasureAngleDepth(camera, measured.centre.x, measured.centre.y, DepthOf(d),
                                         DepthSigmaOf(d), options_.kalman.measurement_noise);
  Eigen::Matrix3d covariance = m.covariance;
  const double f2 = camera.f_px * camera.f_px;
  covariance(0, 0) = measured.var_u / f2;
  covariance(1, 1) = measured.var_v / f2;
  e.kalman.Update(m.s, covariance);
  // The full size follows a detection that nothing cut and whose size agrees with the track's (or
  // any uncut one while the track is young: its first boxes may have been partial).
  if (!cut.any() && (!measured.anchored || e.hits < options_.confirm_hits)) {
    e.full_size = cv::Size2d(d.bbox.width, d.bbox.height);
    e.full_depth_m = DepthOf(d);
    e.centroid_offset = cv::Point2d(d.centroid_px.x - (d.bbox.x + 0.5 * d.bbox.width),
                                    d.centroid_px.y - (d.bbox.y + 0.5 * d.bbox.height));
  } else if (cut.any() && e.full_depth_m > 0) {
    // A cut blob larger than the full size says the obstacle is at least that large (it is entering
    // the image, or was first seen partly hidden).
    const double scale = DepthOf(d) / e.full_depth_m;
    if (!cut.left && !cut.right)
      e.full_size.width = std::max(e.full_size.width, d.bbox.width * scale);
    if (!cut.top && !cut.bottom) {
      e.full_size.height = std::max(e.full_size.height, d.bbox.height * scale);
    }
  }
  e.last_cut = cut.any() || measured.anchored;
  e.position_only = false;
  e.box = d.bbox;
  if (measured.anchored && !cut.any() &&
      (d.bbox.width > p.size.width || d.bbox.height > p.size.height)) {
    // A larger blob than the obstacle (merged with another): the track's box is its full box at
    // the new centre, within the blob.
    const cv::Rect full = PredictedBox(Predict(e, 0, camera), 0, 0) & d.bbox;
    if (!full.empty()) e.box = full;
  }
}

Tracker::Entry Tracker::NewEntry(const detection::Detection& d, const CameraModel& camera) {
  Entry e{.id = next_id_++,
          .state = options_.confirm_hits <= 1 ? TrackState::kConfirmed : TrackState::kTentative,
          .age_frames = 1,
          .hits = 1,
          .misses = 0,
          .last = d,
          .kalman = {},
          .range_filter = FadingMemoryFilter(options_.fading_beta),
          .since_measured_s = 0,
          .full_size = cv::Size2d(d.bbox.width, d.bbox.height),
          .full_depth_m = DepthOf(d),
          .centroid_offset = cv::Point2d(d.centroid_px.x - (d.bbox.x + 0.5 * d.bbox.width),
                                         d.centroid_px.y - (d.bbox.y + 0.5 * d.bbox.height)),
          .last_cut = false,
          .child = false,
          .box = d.bbox};
  const double z = DepthOf(d);
  const AngleDepth m = MeasureAngleDepth(camera, d.centroid_px.x, d.centroid_px.y, z,
                                         DepthSigmaOf(d), options_.kalman.measurement_noise);
  const double v = options_.kalman.initial_velocity_sigma_mps;
  e.kalman.Initialize(m.s, m.covariance, Eigen::Vector3d(v / z, v / z, v));
  e.range_filter.Update(RawRange(d), 0);
  return e;
}

double Tracker::TimeStep(int64_t t_ns) {
  double dt = 0;
  if (last_t_ns_) {
    dt = static_cast<double>(t_ns - *last_t_ns_) * 1e-9;
    dt = std::clamp(dt, 0.0, options_.max_dt_s);
  }
  last_t_ns_ = t_ns;
  return dt;
}

void Tracker::SelectUsable(const std::vector<detection::Detection>& detections) {
  usable_.clear();
  for (int i = 0; i < static_cast<int>(detections.size()); ++i) {
    if (Usable(detections[i], options_.min_score)) usable_.push_back(i);
  }
}

void Tracker::PredictTracks(double dt, const CameraModel& camera) {
  const int num_tracks = static_cast<int>(tracks_.size());
  predictions_.resize(num_tracks);
  for (int t = 0; t < num_tracks; ++t) predictions_[t] = Predict(tracks_[t], dt, camera);
}

void Tracker::CountMerges(const std::vector<detection::Detection>& detections) {
  const int num_tracks = static_cast<int>(tracks_.size());
  const int num_detections = static_cast<int>(usable_.size());
  merged_.assign(num_detections, 0);
  for (int t = 0; t < num_tracks; ++t) {
    const Prediction& p = predictions_[t];
    if (!p.valid || tracks_[t].state == TrackState::kTentative) continue;
    const cv::Rect box = PredictedBox(p, 0, 0);
    for (int k = 0; k < num_detections; ++k) {
      if (Area(box & detections[usable_[k]].bbox) >= kSharedCover * Area(box)) ++merged_[k];
    }
  }
}

std::optional<double> Tracker::PairCost(const Entry& e, const Prediction& p,
                                        const detection::Detection& d, int k) const {
  const GateOptions& gates = options_.gates;
  const double max_distance2 = gates.max_distance_px * gates.max_distance_px;
  if (!DepthConsistent(p, d)) return std::nullopt;
  const Measured m = Measure(e, p, d, cuts_[k], merged_[k] > 1);
  const double dx = m.centre.x - p.u, dy = m.centre.y - p.v;
  const double distance2 = dx * dx + dy * dy;
  if (!(distance2 <= max_distance2)) return std::nullopt;
  // A larger blob than the last on a track measured last frame, neither cut: another obstacle
  // (or several) when it is much larger. A smaller one is a partial view and passes.
  if (e.misses == 0 && !cuts_[k].any() && !e.last_cut) {
    if (d.area_px > e.last.area_px &&
        !WithinRatio(d.area_px, e.last.area_px, gates.max_area_ratio)) {
      return std::nullopt;
    }
    if (d.perimeter_px > e.last.perimeter_px &&
        !WithinRatio(d.perimeter_px, e.last.perimeter_px, gates.max_perimeter_ratio)) {
      return std::nullopt;
    }
  }
  // Cost: the distance, plus half the size difference of a re-anchored blob: of two blobs
  // that both fit, the one of the obstacle's own size (not a sliver or a merge) wins.
  double cost = std::sqrt(distance2);
  if (m.anchored) {
    cost += 0.5 * (std::abs(d.bbox.width - p.size.width) + std::abs(d.bbox.height - p.size.height));
  }
  return cost;
}

void Tracker::Associate(const std::vector<detection::Detection>& detections) {
  const int num_tracks = static_cast<int>(tracks_.size());
  const int num_detections = static_cast<int>(usable_.size());
  const GateOptions& gates = options_.gates;
  allowed_.clear();
  for (int t = 0; t < num_tracks; ++t) {
    const Entry& e = tracks_[t];
    const Prediction& p = predictions_[t];
    if (!p.valid) continue;
    const cv::Rect gate_box =
        PredictedBox(p, gates.position_sigmas * p.sigma_u, gates.position_sigmas * p.sigma_v);
    for (int k = 0; k < num_detections; ++k) {
      const detection::Detection& d = detections[usable_[k]];
      if ((gate_box & d.bbox).empty()) continue;
      if (const std::optional<double> cost = PairCost(e, p, d, k)) {
        allowed_.push_back({.row = t, .col = k, .cost = *cost});
      }
    }
  }
  solver_.SolveSparse(num_tracks, num_detections, allowed_, track_to_detection_);
  detection_used_.assign(num_detections, 0);
  for (int t = 0; t < num_tracks; ++t) {
    if (track_to_detection_[t] >= 0) detection_used_[track_to_detection_[t]] = 1;
  }
}

void Tracker::UpdateMeasured(Entry& e, const Prediction& p, const detection::Detection& d, int k,
                             const CameraModel& camera) {
  Correct(e, p, d, cuts_[k], merged_[k] > 1, camera);
  e.range_filter.Update(RawRange(d), e.since_measured_s);
  e.since_measured_s = 0;
  e.last = d;
  ++e.hits;
  e.hit_history = (e.hit_history << 1) | 1;
  e.misses = 0;
  if (e.state != TrackState::kTentative || ConfirmedByHits(e)) e.state = TrackState::kConfirmed;
}

bool Tracker::ConfirmedByHits(const Entry& e) const {
  const int window = options_.confirm_window;
  const std::uint64_t mask = window >= 64 ? ~std::uint64_t{0} : (std::uint64_t{1} << window) - 1;
  return std::popcount(e.hit_history & mask) >= options_.confirm_hits;
}

int Tracker::FindSharedBlob(const Prediction& p,
                            const std::vector<detection::Detection>& detections) const {
  int found = -1;
  const cv::Rect predicted = PredictedBox(p, 0, 0);
  double best_error = std::numeric_limits<double>::infinity();
  for (int j = 0; j < static_cast<int>(usable_.size()); ++j) {
    const detection::Detection& d = detections[usable_[j]];
    if (Area(predicted & d.bbox) < kSharedCover * Area(predicted)) continue;
    const double tol_u = std::max(kEdgeAgreePx, kEdgeAgreeSigmas * p.sigma_u);
    const double lo_error = std::abs(d.bbox.x - predicted.x);
    const double hi_error = std::abs(d.bbox.br().x - predicted.br().x);
    const bool wider =
        d.bbox.width > p.size.width + std::max(kSizeTolerancePx, kSizeTolerance * p.size.width);
    const double error = std::min(lo_error, hi_error);
    if (!wider || error > tol_u || error >= best_error) continue;
    // Each obstacle of a merged blob is a substantial part of it; a sliver along its edge (a
    // side face seen at another depth, a speck) is not measured by it.
    if (p.size.width < kSharedMinFraction * d.bbox.width) continue;
    best_error = error;
    found = j;
  }
  return found;
}

void Tracker::UpdatePositionOnly(int t, int k, const std::vector<detection::Detection>& detections,
                                 const CameraModel& camera) {
  Entry& e = tracks_[t];
  const Prediction& p = predictions_[t];
  const detection::Detection& d = detections[usable_[k]];
  Measured m = Measure(e, p, d, cuts_[k], true);
  e.kalman = p.kalman;
  const AngleDepth pseudo =
      MeasureAngleDepth(camera, m.centre.x, m.centre.y, p.z, kNoDepthSigmaFraction * p.z,
                        options_.kalman.measurement_noise);
  Eigen::Matrix3d covariance = pseudo.covariance;
  const double f2 = camera.f_px * camera.f_px;
  covariance(0, 0) = m.var_u / f2;
  covariance(1, 1) = m.var_v / f2;
  e.kalman.Update(pseudo.s, covariance);
  // Its box: the full box at the new centre within the blob, less what the track that took the
  // blob covers (the nearer obstacle hides that part).
  e.position_only = true;
  e.box = PredictedBox(Predict(e, 0, camera), 0, 0) & d.bbox;
  const int num_tracks = static_cast<int>(track_to_detection_.size());
  for (int o = 0; o < num_tracks; ++o) {
    if (o != t && track_to_detection_[o] == k && predictions_[o].valid) {
      e.box = Subtract(e.box, PredictedBox(predictions_[o], 0, 0));
    }
  }
  ++e.hits;
  e.hit_history = (e.hit_history << 1) | 1;
  e.misses = 0;
  e.state = TrackState::kConfirmed;
}

void Tracker::Coast(Entry& e, double dt, const CameraModel& camera) {
  const KalmanOptions& kalman = options_.kalman;
  e.kalman.PredictAngleDepth(dt, kalman.occluded_process_noise);
  const Eigen::Vector3d s = e.kalman.position();
  if (s.z() > kMinDepthM) {
    const AngleDepth pseudo =
        MeasureAngleDepth(camera, camera.cx + camera.f_px * s.x(), camera.cy + camera.f_px * s.y(),
                          s.z(), 0, kalman.occluded_measurement_noise);
    e.kalman.Update(pseudo.s, pseudo.covariance);
    if (e.full_size.width > 0) {
      const double scale = e.full_depth_m > 0 ? e.full_depth_m / s.z() : 1.0;
      e.box = RectAround(camera.cx + camera.f_px * s.x(), camera.cy + camera.f_px * s.y(),
                         e.full_size.width * scale, e.full_size.height * scale);
    }
  }
  ++e.misses;
  e.hit_history <<= 1;
  if (e.state == TrackState::kConfirmed) e.state = TrackState::kCoasting;
}

void Tracker::UpdateTracks(const std::vector<detection::Detection>& detections, double dt,
                           const CameraModel& camera) {
  const int num_tracks = static_cast<int>(tracks_.size());
  for (int t = 0; t < num_tracks; ++t) {
    Entry& e = tracks_[t];
    const Prediction& p = predictions_[t];
    int k = track_to_detection_[t];
    ++e.age_frames;
    e.since_measured_s += dt;
    if (k >= 0) {
      UpdateMeasured(e, p, detections[usable_[k]], k, camera);
      continue;
    }
    // No detection of its own. A confirmed track whose predicted box lies in a larger blob that
    // shares one of its edges (two obstacles merged into one blob, whose depth is the other's) is
    // measured there in position only: the blob says where its edge is, not how far it is.
    if (e.state != TrackState::kTentative && p.valid && p.size.width > 0) {
      k = FindSharedBlob(p, detections);
    }
    if (k >= 0) {
      UpdatePositionOnly(t, k, detections, camera);
      continue;
    }
    // Occluded (or missed): free prediction with the occlusion noises. The pseudo-measurement is
    // the prediction itself, so it leaves the state and only (barely) shrinks the covariance.
    Coast(e, dt, camera);
  }
}

void Tracker::StartTracks(const std::vector<detection::Detection>& detections, int num_tracks,
                          const CameraModel& camera) {
  const int num_detections = static_cast<int>(usable_.size());
  for (int k = 0; k < num_detections; ++k) {
    if (detection_used_[k]) continue;
    const detection::Detection& d = detections[usable_[k]];
    bool fragment = false, inside = false;
    for (int t = 0; t < num_tracks && !fragment; ++t) {
      const Prediction& p = predictions_[t];
      if (!p.valid) continue;
      const cv::Rect region = PredictedBox(p, 0, 0) | tracks_[t].box;
      if (Area(region & d.bbox) < kInsideFraction * Area(d.bbox)) continue;
      if (DepthConsistent(p, d)) {
        fragment = true;
        if (tracks_[t].misses == 0) tracks_[t].box |= d.bbox;
      } else {
        inside = true;
      }
    }
    if (fragment) continue;
    tracks_.push_back(NewEntry(d, camera));
    tracks_.back().child = inside;
  }
}

bool Tracker::SameObstacle(const Entry& a, const Entry& b) const {
  const GateOptions& gates = options_.gates;
  // One obstacle: the boxes overlap at merge_iou, or one lies mostly inside the other (a
  // fragment that started a track of its own, e.g. in the first frame).
  const double inter = Area(a.box & b.box);
  if (IoURect(a.box, b.box) < options_.merge_iou &&
      inter < kInsideFraction * std::min(Area(a.box), Area(b.box))) {
    return false;
  }
  const double za = a.kalman.position().z(), zb = b.kalman.position().z();
  if (!WithinRatio(za, zb, gates.max_depth_ratio)) return false;  // the hard cap, as for a pair
  const double floor = gates.min_depth_sigma_fraction * std::max(za, zb);
  const double var = a.kalman.covariance()(2, 2) + b.kalman.covariance()(2, 2) + floor * floor;
  return !((za - zb) * (za - zb) > gates.depth_sigmas * gates.depth_sigmas * var);
}

void Tracker::MergeTracks() {
  for (size_t i = 0; i < tracks_.size(); ++i) {
    for (size_t j = i + 1; j < tracks_.size(); ++j) {
      Entry& a = tracks_[i];
      Entry& b = tracks_[j];
      if (a.id == 0 || b.id == 0) continue;
      if (!SameObstacle(a, b)) continue;
      Entry& older = a.id < b.id ? a : b;
      Entry& younger = a.id < b.id ? b : a;
      if (older.misses > 0 && younger.misses == 0 && older.state != TrackState::kTentative) {
        older.kalman = younger.kalman;
        older.last = younger.last;
        older.box = younger.box;
        older.range_filter.Update(RawRange(younger.last), older.since_measured_s);
        older.since_measured_s = 0;
        older.misses = 0;
        ++older.hits;
        older.hit_history |= 1;
        older.state = TrackState::kConfirmed;
      }
      younger.id = 0;  // merged: removed below
    }
  }
}

bool Tracker::Expired(const Entry& e, const CameraModel& camera) const {
  if (e.id == 0) return true;
  const int limit = e.state == TrackState::kTentative
                        ? (e.child ? 1 : options_.tentative_delete_misses)
                        : options_.delete_misses;
  if (e.misses >= limit) return true;
  if (e.misses == 0 || camera.width <= 0 || camera.height <= 0) return false;
  const Eigen::Vector3d s = e.kalman.position();
  const double u = camera.cx + camera.f_px * s.x(), v = camera.cy + camera.f_px * s.y();
  return s.z() <= kMinDepthM || u + 0.5 * e.full_size.width < 0 ||
         u - 0.5 * e.full_size.width > camera.width || v + 0.5 * e.full_size.height < 0 ||
         v - 0.5 * e.full_size.height > camera.height;
}

namespace {

// The cross-product matrix [w]x.
Eigen::Matrix3d Skew(const Eigen::Vector3d& w) {
  Eigen::Matrix3d m;
  m << 0, -w.z(), w.y(), w.z(), 0, -w.x(), -w.y(), w.x(), 0;
  return m;
}

}  // namespace

Tracker::ApparentMotion Tracker::ApparentMotionOf(const Eigen::Isometry3d& cam_now_from_cam_prev,
                                                  double dt) {
  // The logarithm of the rigid motion: rotation vector phi (angle theta) and the translation's
  // generator V^-1 t, V^-1 = I - W / 2 + (1 - theta sin(theta) / (2 (1 - cos(theta)))) W^2 /
  // theta^2 with W = [phi]x (I - W / 2 + W^2 / 12 for a small angle).
  const Eigen::AngleAxisd angle_axis(cam_now_from_cam_prev.linear());
  const double theta = angle_axis.angle();
  const Eigen::Vector3d phi = theta * angle_axis.axis();
  const Eigen::Matrix3d W = Skew(phi);
  double k = 1.0 / 12;
  if (theta > 1e-4)
    k = (1 - theta * std::sin(theta) / (2 * (1 - std::cos(theta)))) / (theta * theta);
  const Eigen::Matrix3d V_inv = Eigen::Matrix3d::Identity() - 0.5 * W + k * W * W;
  return {.linear = W / dt, .offset = V_inv * cam_now_from_cam_prev.translation() / dt};
}

void Tracker::ApplyEgoMotion(const EgoMotion& ego, double dt) {
  using Matrix6 = Eigen::Matrix<double, 6, 6>;
  using Vector6 = Eigen::Matrix<double, 6, 1>;
  const Eigen::Matrix3d R = ego.cam_now_from_cam_prev.linear();
  const Eigen::Vector3d t = ego.cam_now_from_cam_prev.translation();
  if (dt > 0) {
    const ApparentMotion apparent = ApparentMotionOf(ego.cam_now_from_cam_prev, dt);
    apparent_linear_ = apparent.linear;
    apparent_offset_ = apparent.offset;
  }
  // Relative velocities (the last update had no ego-motion) lose the apparent velocity of a static
  // point, A p + c, and are over the ground; then position and velocity turn with the camera. A
  // track started at the last update has no velocity of its own yet (the prior, at rest): it starts
  // at rest over the ground instead.
  const bool to_ground = !ground_velocity_ && dt > 0;
  Matrix6 rigid = Matrix6::Zero();
  rigid.topLeftCorner<3, 3>() = R;
  rigid.bottomRightCorner<3, 3>() = R;
  Vector6 moved = Vector6::Zero();
  moved.head<3>() = t;
  Matrix6 convert = Matrix6::Identity();
  Vector6 convert_offset = Vector6::Zero();
  if (to_ground) {
    convert.bottomLeftCorner<3, 3>() = -apparent_linear_;
    convert_offset.tail<3>() = -apparent_offset_;
  }
  const Matrix6 linear = rigid * convert;
  const Vector6 offset = rigid * convert_offset + moved;
  for (Entry& e : tracks_) {
    if (to_ground && e.age_frames > 1) {
      e.kalman.MapAngleDepth(linear, offset);
    } else {
      e.kalman.MapAngleDepth(rigid, moved);
    }
  }
  if (dt > 0) ground_velocity_ = true;
}

void Tracker::ToRelativeVelocity() {
  Eigen::Matrix<double, 6, 6> linear = Eigen::Matrix<double, 6, 6>::Identity();
  linear.bottomLeftCorner<3, 3>() = apparent_linear_;
  Eigen::Matrix<double, 6, 1> offset = Eigen::Matrix<double, 6, 1>::Zero();
  offset.tail<3>() = apparent_offset_;
  for (Entry& e : tracks_) e.kalman.MapAngleDepth(linear, offset);
  ground_velocity_ = false;
}

std::vector<Track> Tracker::Update(const std::vector<detection::Detection>& detections,
                                   int64_t t_ns, const CameraModel& camera,
                                   const std::optional<EgoMotion>& ego) {
  if (std::vector<std::string> problems = camera.Validate(); !problems.empty()) {
    throw std::invalid_argument("Tracker::Update: camera: " + InvalidArgument(problems).message);
  }
  const double dt = TimeStep(t_ns);
  // The tracks in this frame's cam frame: carried through the camera's motion when it is known.
  if (ego) {
    ApplyEgoMotion(*ego, dt);
  } else if (ground_velocity_) {
    ToRelativeVelocity();
  }
  SelectUsable(detections);
  const int num_tracks = static_cast<int>(tracks_.size());
  FindCuts(detections, camera);

  // Every track predicted once, with its covariance: the gates use it, and a track that gets a
  // detection is updated from it.
  PredictTracks(dt, camera);
  // How many tracks' predicted boxes each detection covers (a blob covering two is a merge).
  CountMerges(detections);
  // Cost: pixel distance between the detection's centre (re-anchored when its size differs) and
  // the track's predicted centre. Only the pairs inside every gate are listed; all others are
  // forbidden and never assigned.
  Associate(detections);
  // Each track measured by its detection, in position only by a blob it shares, or coasting.
  UpdateTracks(detections, dt, camera);
  // A detection no track took: inside a track's predicted box at a depth that track allows, it is
  // a fragment of that obstacle (its box joins the track's); at a depth the track rules out, it
  // starts a child track, deleted at its first miss while tentative; elsewhere a new track.
  StartTracks(detections, num_tracks, camera);
  // Two tracks on one obstacle (their boxes overlap at merge_iou, depths consistent): the younger
  // is merged into the older, which takes its measurement when it had none of its own.
  MergeTracks();
  // Deleted: merged, after too many misses, or predicted wholly out of the image (nothing can be
  // seen there; an obstacle that left the view is gone).
  std::erase_if(tracks_, [&](const Entry& e) { return Expired(e, camera); });

  std::vector<Track> out;
  out.reserve(tracks_.size());
  for (const Entry& e : tracks_) out.push_back(Output(e, camera));
  return out;
}

Track Tracker::Output(const Entry& e, const CameraModel& camera) const {
  Track track;
  track.id = e.id;
  track.state = e.state;
  track.age_frames = e.age_frames;
  track.hits = e.hits;
  track.misses = e.misses;
  track.detection = e.last;
  // From s = (a, b, z) and its rates to the cam frame: p = (a z, b z, z),
  // v = (a' z + a z', b' z + b z', z'); the covariance through the Jacobian.
  const ConstantVelocityKalman::State& x = e.kalman.state();
  const double a = x(0), b = x(1), z = x(2), da = x(3), db = x(4), dz = x(5);
  const Eigen::Vector3d p(a * z, b * z, z);
  const Eigen::Vector3d v_filter(da * z + a * dz, db * z + b * dz, dz);
  Eigen::Matrix<double, 6, 6> J = Eigen::Matrix<double, 6, 6>::Zero();
  J(0, 0) = z, J(0, 2) = a;
  J(1, 1) = z, J(1, 2) = b;
  J(2, 2) = 1;
  J(3, 0) = dz, J(3, 2) = da, J(3, 3) = z, J(3, 5) = a;
  J(4, 1) = dz, J(4, 2) = db, J(4, 4) = z, J(4, 5) = b;
  J(5, 5) = 1;
  Eigen::Vector3d v = v_filter;
  if (ground_velocity_) {
    // Published relative to the camera: the ground velocity plus the apparent velocity the
    // camera's own motion gives the point, v + A p + c.
    v += apparent_linear_ * p + apparent_offset_;
    Eigen::Matrix<double, 6, 6> relative = Eigen::Matrix<double, 6, 6>::Identity();
    relative.bottomLeftCorner<3, 3>() = apparent_linear_;
    J = (relative * J).eval();
  }
  const Eigen::Matrix<double, 6, 1> variance =
      (J * e.kalman.covariance() * J.transpose()).diagonal();
  if (e.misses > 0 && z > kMinDepthM) {
    // Not measured this frame: the centre is the prediction's.
    track.detection.centroid_px =
        cv::Point2d(camera.cx + camera.f_px * a, camera.cy + camera.f_px * b);
  }
  if (e.misses == 0 && e.position_only && z > kMinDepthM) {
    // Measured in position only: the depth is the filter's, not the shared blob's.
    track.detection.depth_m = z;
    track.detection.range_m = p.norm();
    track.detection.disparity_px = camera.f_px * camera.baseline_m / z;
    track.detection.position_cam_m = ToCv(p);
  }
  // Measured: the detection's box with the fragments that joined it; measured in a shared blob:
  // the full box at the new centre within the blob; coasting: the full box at the prediction.
  if (!e.box.empty()) track.detection.bbox = e.box;
  // What is reported lies in the image (a full box predicted across the border does not).
  if (camera.width > 0 && camera.height > 0) {
    const cv::Rect clipped = track.detection.bbox & cv::Rect(0, 0, camera.width, camera.height);
    if (!clipped.empty()) track.detection.bbox = clipped;
  }
  track.position_cam_m = ToCv(p);
  track.velocity_cam_mps = ToCv(v);
  track.position_sigma_m = ToCv(variance.head<3>().cwiseMax(0.0).cwiseSqrt());
  track.velocity_sigma_mps = ToCv(variance.tail<3>().cwiseMax(0.0).cwiseSqrt());
  track.range_m = RawRange(e.last);
  track.smoothed_range_m = e.range_filter.Predict(e.since_measured_s);
  // The range rate of the filtered 3-D state: as smooth as the time to collision computed from the
  // same state, so the two never disagree in sign (the fading filter's own rate is noisier).
  track.range_rate_mps = p.norm() > 0 ? p.dot(v) / p.norm() : 0.0;
  // Closing only when the range rate is significantly negative (beyond 2 sigma of its own
  // uncertainty): a hovering or standing obstacle's velocity noise must not read as an approach.
  const Eigen::Vector3d line_of_sight =
      p.norm() > 0 ? Eigen::Vector3d(p / p.norm()) : Eigen::Vector3d::Zero();
  const Eigen::Vector3d velocity_sigma = variance.tail<3>().cwiseMax(0.0).cwiseSqrt();
  const double range_rate_sigma = line_of_sight.cwiseProduct(velocity_sigma).norm();
  track.range_rate_sigma_mps = range_rate_sigma;
  const bool closing = track.range_rate_mps < -2.0 * range_rate_sigma;
  const double speed2 = v.squaredNorm();
  if (closing && speed2 > 1e-12) {
    const double t_closest = -p.dot(v) / speed2;
    if (t_closest > 0) {
      track.time_to_collision_s = t_closest;
      track.closest_approach_m = (p + t_closest * v).norm();
    }
  }
  return track;
}

}  // namespace stevi::tracking
