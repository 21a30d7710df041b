// How a detection measures a track (tracker.h, Tracker's private stages): the sides a nearer
// detection or the border cuts, the prediction and its gate box, the centre of a blob whose size
// differs (re-anchored on the edge that agrees), the Kalman corrections of a measured, a new and a
// position-only track, and free prediction while coasting.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include "core/tracking/tracker.h"
#include "core/tracking/tracker_internal.h"

namespace stevi::tracking {

using internal::Area;
using internal::DepthOf;
using internal::DepthSigmaOf;
using internal::kMinDepthM;
using internal::RawRange;
using internal::RectAround;
using internal::WithinRatio;

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
// Depth sigma (as a fraction of the depth) of a position-only measurement: no depth information.
constexpr double kNoDepthSigmaFraction = 1e3;

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

}  // namespace stevi::tracking
