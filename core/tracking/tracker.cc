#include "core/tracking/tracker.h"

#include <algorithm>
#include <cmath>
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

std::vector<std::string> GateOptions::Validate() const {
  std::vector<std::string> problems;
  if (!(max_depth_ratio >= 1)) {
    problems.push_back("max_depth_ratio: must be >= 1" + Got(max_depth_ratio));
  }
  if (!(max_area_ratio >= 1)) {
    problems.push_back("max_area_ratio: must be >= 1" + Got(max_area_ratio));
  }
  if (!(max_perimeter_ratio >= 1)) {
    problems.push_back("max_perimeter_ratio: must be >= 1" + Got(max_perimeter_ratio));
  }
  if (!(max_distance_px > 0)) {
    problems.push_back("max_distance_px: must be > 0 pixels" + Got(max_distance_px));
  }
  return problems;
}

std::vector<std::string> TrackerOptions::Validate() const {
  std::vector<std::string> problems;
  AppendPrefixed(problems, "kalman.", kalman.Validate());
  AppendPrefixed(problems, "gates.", gates.Validate());
  if (confirm_hits < 1) problems.push_back("confirm_hits: must be >= 1" + Got(confirm_hits));
  if (delete_misses < 1) problems.push_back("delete_misses: must be >= 1" + Got(delete_misses));
  if (tentative_delete_misses < 1 || tentative_delete_misses > std::max(delete_misses, 1)) {
    problems.push_back("tentative_delete_misses: must be in 1..delete_misses" +
                       Got(tentative_delete_misses));
  }
  if (!(fading_beta > 0 && fading_beta <= 1)) {
    problems.push_back("fading_beta: must be in (0, 1]" + Got(fading_beta));
  }
  if (!(min_score >= 0 && min_score <= 1)) {
    problems.push_back("min_score: must be in [0, 1]" + Got(min_score));
  }
  if (!(std::isfinite(max_dt_s) && max_dt_s > 0)) {
    problems.push_back("max_dt_s: must be > 0 seconds and finite" + Got(max_dt_s));
  }
  return problems;
}

Tracker::Tracker(TrackerOptions options) { SetOptions(std::move(options)); }

void Tracker::SetOptions(TrackerOptions options) {
  if (std::vector<std::string> problems = options.Validate(); !problems.empty()) {
    throw std::invalid_argument("TrackerOptions: " + Error::Invalid(problems).message);
  }
  options_ = std::move(options);
}

void Tracker::Reset() {
  tracks_.clear();
  last_t_ns_.reset();
}

namespace {

// A nearer detection cuts another when it is at least this much nearer (depth ratio) and their
// boxes touch (within kTouchPx).
constexpr double kNearerRatio = 1.15;
constexpr int kTouchPx = 2;
// A cut blob narrower (shorter) than this fraction of the track's full size is re-centred.
constexpr double kCutFraction = 0.9;

double DepthOf(const detection::Detection& d) {
  return std::isfinite(d.depth_m) && d.depth_m > 0 ? d.depth_m : d.position_cam_m[2];
}

double DepthSigmaOf(const detection::Detection& d) {
  const double range = RawRange(d);
  if (!(std::isfinite(d.range_sigma_m) && d.range_sigma_m > 0 && range > 0)) return 0;
  return d.range_sigma_m * DepthOf(d) / range;
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

cv::Point2d Tracker::MeasuredCentre(const Entry& e, const detection::Detection& d,
                                    const Cut& cut) const {
  cv::Point2d c = d.centroid_px;
  if (!cut.any() || !(e.full_size.width > 0)) return c;
  const double w = e.full_size.width, h = e.full_size.height;
  if (d.bbox.width < kCutFraction * w && cut.left != cut.right) {
    c.x = (cut.left ? d.bbox.x + d.bbox.width - 0.5 * w : d.bbox.x + 0.5 * w) + e.centroid_offset.x;
  }
  if (d.bbox.height < kCutFraction * h && cut.top != cut.bottom) {
    c.y = (cut.top ? d.bbox.y + d.bbox.height - 0.5 * h : d.bbox.y + 0.5 * h) + e.centroid_offset.y;
  }
  return c;
}

void Tracker::Correct(Entry& e, const detection::Detection& d, const Cut& cut,
                      const CameraModel& camera) {
  if (!cut.any() || !(e.full_size.width > 0)) {
    e.full_size = cv::Size2d(d.bbox.width, d.bbox.height);
    e.centroid_offset = cv::Point2d(d.centroid_px.x - (d.bbox.x + 0.5 * d.bbox.width),
                                    d.centroid_px.y - (d.bbox.y + 0.5 * d.bbox.height));
  }
  e.last_cut = cut.any();
  const cv::Point2d centre = MeasuredCentre(e, d, cut);
  const AngleDepth m = MeasureAngleDepth(camera, centre.x, centre.y, DepthOf(d), DepthSigmaOf(d),
                                         options_.kalman.measurement_noise);
  e.kalman.Update(m.s, m.covariance);
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
          .centroid_offset = cv::Point2d(d.centroid_px.x - (d.bbox.x + 0.5 * d.bbox.width),
                                         d.centroid_px.y - (d.bbox.y + 0.5 * d.bbox.height))};
  const double z = DepthOf(d);
  const AngleDepth m = MeasureAngleDepth(camera, d.centroid_px.x, d.centroid_px.y, z,
                                         DepthSigmaOf(d), options_.kalman.measurement_noise);
  const double v = options_.kalman.initial_velocity_sigma_mps;
  e.kalman.Initialize(m.s, m.covariance, Eigen::Vector3d(v / z, v / z, v));
  e.range_filter.Update(RawRange(d), 0);
  return e;
}

std::vector<Track> Tracker::Update(const std::vector<detection::Detection>& detections,
                                   int64_t t_ns, const CameraModel& camera) {
  if (std::vector<std::string> problems = camera.Validate(); !problems.empty()) {
    throw std::invalid_argument("Tracker::Update: camera: " + Error::Invalid(problems).message);
  }
  double dt = 0;
  if (last_t_ns_) {
    dt = static_cast<double>(t_ns - *last_t_ns_) * 1e-9;
    dt = std::clamp(dt, 0.0, options_.max_dt_s);
  }
  last_t_ns_ = t_ns;

  usable_.clear();
  for (int i = 0; i < static_cast<int>(detections.size()); ++i) {
    if (Usable(detections[i], options_.min_score)) usable_.push_back(i);
  }
  const int num_tracks = static_cast<int>(tracks_.size());
  const int num_detections = static_cast<int>(usable_.size());
  FindCuts(detections, camera);

  // Cost: pixel distance between the detection's centre (re-centred when cut) and the track's
  // predicted centre. Only the pairs inside every gate are listed; all others are forbidden and
  // never assigned.
  const GateOptions& gates = options_.gates;
  const double max_distance2 = gates.max_distance_px * gates.max_distance_px;
  allowed_.clear();
  for (int t = 0; t < num_tracks; ++t) {
    const Entry& e = tracks_[t];
    const Eigen::Vector3d s = e.kalman.PredictedAngleDepth(dt);
    if (!(s.z() > kMinDepthM)) continue;
    const double u = camera.cx + camera.f_px * s.x(), v = camera.cy + camera.f_px * s.y();
    for (int k = 0; k < num_detections; ++k) {
      const detection::Detection& d = detections[usable_[k]];
      const cv::Point2d c = MeasuredCentre(e, d, cuts_[k]);
      const double dx = c.x - u, dy = c.y - v;
      const double distance2 = dx * dx + dy * dy;
      if (!(distance2 <= max_distance2)) continue;
      if (!WithinRatio(DepthOf(d), s.z(), gates.max_depth_ratio)) continue;
      // A cut blob's area and perimeter are partial: the shape gates compare uncut blobs only.
      if (!cuts_[k].any() && !e.last_cut) {
        if (!WithinRatio(d.area_px, e.last.area_px, gates.max_area_ratio)) continue;
        if (!WithinRatio(d.perimeter_px, e.last.perimeter_px, gates.max_perimeter_ratio)) continue;
      }
      allowed_.push_back({.row = t, .col = k, .cost = std::sqrt(distance2)});
    }
  }
  solver_.SolveSparse(num_tracks, num_detections, allowed_, track_to_detection_);

  const KalmanOptions& kalman = options_.kalman;
  detection_used_.assign(num_detections, 0);
  for (int t = 0; t < num_tracks; ++t) {
    Entry& e = tracks_[t];
    const int k = track_to_detection_[t];
    ++e.age_frames;
    e.since_measured_s += dt;
    if (k >= 0) {
      const detection::Detection& d = detections[usable_[k]];
      detection_used_[k] = 1;
      e.kalman.PredictAngleDepth(dt, kalman.process_noise);
      Correct(e, d, cuts_[k], camera);
      e.range_filter.Update(RawRange(d), e.since_measured_s);
      e.since_measured_s = 0;
      e.last = d;
      ++e.hits;
      e.misses = 0;
      if (e.state != TrackState::kTentative || e.hits >= options_.confirm_hits) {
        e.state = TrackState::kConfirmed;
      }
    } else {
      // Occluded (or missed): free prediction with the occlusion noises. The pseudo-measurement is
      // the prediction itself, so it leaves the state and only (barely) shrinks the covariance.
      e.kalman.PredictAngleDepth(dt, kalman.occluded_process_noise);
      const Eigen::Vector3d s = e.kalman.position();
      if (s.z() > kMinDepthM) {
        const AngleDepth pseudo = MeasureAngleDepth(
            camera, camera.cx + camera.f_px * s.x(), camera.cy + camera.f_px * s.y(), s.z(), 0,
            kalman.occluded_measurement_noise);
        e.kalman.Update(pseudo.s, pseudo.covariance);
      }
      ++e.misses;
      if (e.state == TrackState::kConfirmed) e.state = TrackState::kCoasting;
    }
  }

  // Deleted: after too many misses, or predicted wholly out of the image (nothing can be seen
  // there; an obstacle that left the view is gone).
  std::erase_if(tracks_, [&](const Entry& e) {
    if (e.misses >= (e.state == TrackState::kTentative ? options_.tentative_delete_misses
                                                       : options_.delete_misses)) {
      return true;
    }
    if (e.misses == 0 || camera.width <= 0 || camera.height <= 0) return false;
    const Eigen::Vector3d s = e.kalman.position();
    const double u = camera.cx + camera.f_px * s.x(), v = camera.cy + camera.f_px * s.y();
    return s.z() <= kMinDepthM || u + 0.5 * e.full_size.width < 0 ||
           u - 0.5 * e.full_size.width > camera.width || v + 0.5 * e.full_size.height < 0 ||
           v - 0.5 * e.full_size.height > camera.height;
  });
  for (int k = 0; k < num_detections; ++k) {
    if (!detection_used_[k]) tracks_.push_back(NewEntry(detections[usable_[k]], camera));
  }

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
  const Eigen::Vector3d v(da * z + a * dz, db * z + b * dz, dz);
  Eigen::Matrix<double, 6, 6> J = Eigen::Matrix<double, 6, 6>::Zero();
  J(0, 0) = z, J(0, 2) = a;
  J(1, 1) = z, J(1, 2) = b;
  J(2, 2) = 1;
  J(3, 0) = dz, J(3, 2) = da, J(3, 3) = z, J(3, 5) = a;
  J(4, 1) = dz, J(4, 2) = db, J(4, 4) = z, J(4, 5) = b;
  J(5, 5) = 1;
  const Eigen::Matrix<double, 6, 1> variance =
      (J * e.kalman.covariance() * J.transpose()).diagonal();
  if (e.misses > 0 && z > kMinDepthM) {
    // Not measured this frame: the box follows the prediction, keeping its size.
    const Eigen::Vector2d centre(camera.cx + camera.f_px * a, camera.cy + camera.f_px * b);
    const cv::Point2d shift(centre.x() - e.last.centroid_px.x, centre.y() - e.last.centroid_px.y);
    track.detection.centroid_px = cv::Point2d(centre.x(), centre.y());
    // Clamped so that a prediction that nears the camera plane cannot overflow an int.
    constexpr double kMaxPx = 1e6;
    track.detection.bbox.x =
        static_cast<int>(std::lround(std::clamp(e.last.bbox.x + shift.x, -kMaxPx, kMaxPx)));
    track.detection.bbox.y =
        static_cast<int>(std::lround(std::clamp(e.last.bbox.y + shift.y, -kMaxPx, kMaxPx)));
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
  const Eigen::Vector3d line_of_sight = p.norm() > 0 ? Eigen::Vector3d(p / p.norm()) : Eigen::Vector3d::Zero();
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
