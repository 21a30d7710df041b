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

Eigen::Vector3d ToEigen(const cv::Vec3d& v) { return {v[0], v[1], v[2]}; }
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

Tracker::Entry Tracker::NewEntry(const detection::Detection& d, const CameraModel& camera) {
  Entry e{.id = next_id_++,
          .state = options_.confirm_hits <= 1 ? TrackState::kConfirmed : TrackState::kTentative,
          .age_frames = 1,
          .hits = 1,
          .misses = 0,
          .last = d,
          .kalman = {},
          .range_filter = FadingMemoryFilter(options_.fading_beta),
          .since_measured_s = 0};
  const Eigen::Vector3d position = ToEigen(d.position_cam_m);
  e.kalman.Initialize(
      position,
      DetectionCovariance(camera, position, options_.kalman.measurement_noise, d.range_sigma_m),
      options_.kalman.initial_velocity_sigma_mps);
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

  // Cost: pixel distance between the detection's centroid and the track's predicted centre. Only
  // the pairs inside every gate are listed; all others are forbidden and never assigned.
  const GateOptions& gates = options_.gates;
  const double max_distance2 = gates.max_distance_px * gates.max_distance_px;
  allowed_.clear();
  for (int t = 0; t < num_tracks; ++t) {
    const Entry& e = tracks_[t];
    const Eigen::Vector3d p = e.kalman.PredictedPosition(dt);
    if (!(p.z() > kMinDepthM)) continue;
    const Eigen::Vector2d centre = Project(camera, p);
    for (int k = 0; k < num_detections; ++k) {
      const detection::Detection& d = detections[usable_[k]];
      const double dx = d.centroid_px.x - centre.x(), dy = d.centroid_px.y - centre.y();
      const double distance2 = dx * dx + dy * dy;
      if (!(distance2 <= max_distance2)) continue;
      if (!WithinRatio(d.position_cam_m[2], p.z(), gates.max_depth_ratio)) continue;
      if (!WithinRatio(d.area_px, e.last.area_px, gates.max_area_ratio)) continue;
      if (!WithinRatio(d.perimeter_px, e.last.perimeter_px, gates.max_perimeter_ratio)) continue;
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
      const Eigen::Vector3d measured = ToEigen(d.position_cam_m);
      e.kalman.Predict(dt, kalman.process_noise);
      e.kalman.Update(measured, DetectionCovariance(camera, measured, kalman.measurement_noise,
                                                    d.range_sigma_m));
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
      e.kalman.Predict(dt, kalman.occluded_process_noise);
      const Eigen::Vector3d p = e.kalman.position();
      if (p.z() > kMinDepthM) {
        e.kalman.Update(p, PixelNoiseCovariance(camera, p, kalman.occluded_measurement_noise));
      }
      ++e.misses;
      if (e.state == TrackState::kConfirmed) e.state = TrackState::kCoasting;
    }
  }

  std::erase_if(tracks_, [this](const Entry& e) {
    return e.misses >= (e.state == TrackState::kTentative ? options_.tentative_delete_misses
                                                          : options_.delete_misses);
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
  const Eigen::Vector3d p = e.kalman.position();
  const Eigen::Vector3d v = e.kalman.velocity();
  if (e.misses > 0 && p.z() > kMinDepthM) {
    // Not measured this frame: the box follows the prediction, keeping its size.
    const Eigen::Vector2d centre = Project(camera, p);
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
  const ConstantVelocityKalman::State variance = e.kalman.covariance().diagonal();
  track.position_sigma_m = ToCv(variance.head<3>().cwiseMax(0.0).cwiseSqrt());
  track.velocity_sigma_mps = ToCv(variance.tail<3>().cwiseMax(0.0).cwiseSqrt());
  track.range_m = RawRange(e.last);
  track.smoothed_range_m = e.range_filter.Predict(e.since_measured_s);
  // The range rate of the filtered 3-D state: as smooth as the time to collision computed from the
  // same state, so the two never disagree in sign (the fading filter's own rate is noisier).
  track.range_rate_mps = p.norm() > 0 ? p.dot(v) / p.norm() : 0.0;
  const double speed2 = v.squaredNorm();
  if (speed2 > 1e-12) {
    const double t_closest = -p.dot(v) / speed2;
    if (t_closest > 0) {
      track.time_to_collision_s = t_closest;
      track.closest_approach_m = (p + t_closest * v).norm();
    }
  }
  return track;
}

}  // namespace stevi::tracking
