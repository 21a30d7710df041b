// The tracker's life cycle (tracker.h): options, the stages of Update() in order, association,
// new tracks, merges, deletion and the published Track. tracker_measurement.cc holds how a
// detection measures a track (cuts, predictions, re-anchored centres, the Kalman corrections,
// coasting); tracker_ego_motion.cc carries the tracks through the camera's motion.
#include "core/tracking/tracker.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <utility>

#include "core/common/error.h"
#include "core/tracking/tracker_internal.h"

namespace stevi::tracking {

using internal::Area;
using internal::DepthOf;
using internal::kMinDepthM;
using internal::RawRange;
using internal::ToCv;
using internal::WithinRatio;

namespace {

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

// A detection is inside a track's box (a fragment of it) when at least this fraction of its area
// lies in the track's predicted box.
constexpr double kInsideFraction = 0.5;

double IoURect(const cv::Rect& a, const cv::Rect& b) {
  const double inter = Area(a & b);
  const double uni = Area(a) + Area(b) - inter;
  return uni > 0 ? inter / uni : 0.0;
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

bool Tracker::ConfirmedByHits(const Entry& e) const {
  const int window = options_.confirm_window;
  const std::uint64_t mask = window >= 64 ? ~std::uint64_t{0} : (std::uint64_t{1} << window) - 1;
  return std::popcount(e.hit_history & mask) >= options_.confirm_hits;
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
