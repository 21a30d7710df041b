#include "core/tracking/tracker.h"
#include "tests/testing/measured_detection.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <functional>
#include <iostream>
#include <limits>
#include <random>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace stevi::tracking {
namespace {

using ::testing::HasSubstr;
using ::testing::IsEmpty;

// The analytic rig of the tests: f = 700 px, principal point (320, 240), baseline 0.6 m.
const CameraModel kCamera{.f_px = 700, .cx = 320, .cy = 240, .baseline_m = 0.6};
constexpr double kFB = 700 * 0.6;
constexpr int64_t kFrameNs = 33'333'333;  // 30 Hz
constexpr double kDt = kFrameNs * 1e-9;
constexpr double kCentroidSigmaPx = 0.3;
constexpr double kDisparitySigmaPx = 0.25;

int64_t FrameTime(int frame) { return frame * kFrameNs; }

// An obstacle moving in a straight line in the cam frame.
struct Target {
  Eigen::Vector3d p0;
  Eigen::Vector3d v;
  double width_m = 2;
  double height_m = 1.5;
  Eigen::Vector3d At(int frame) const { return p0 + v * (frame * kDt); }
};

// What a stereo detector reports for an obstacle centred at `p`: centroid and disparity (noisy
// when `rng` is given), the back-projected position, range and range sigma, and the box, area and
// perimeter of the obstacle's size at the measured depth.
detection::Detection Detect(const Eigen::Vector3d& p, double width_m, double height_m,
                            std::mt19937* rng) {
  std::normal_distribution<double> centroid(0.0, kCentroidSigmaPx);
  std::normal_distribution<double> disparity(0.0, kDisparitySigmaPx);
  double u = kCamera.cx + kCamera.f_px * p.x() / p.z();
  double v = kCamera.cy + kCamera.f_px * p.y() / p.z();
  double d = kFB / p.z();
  if (rng != nullptr) {
    u += centroid(*rng);
    v += centroid(*rng);
    d += disparity(*rng);
  }
  detection::Detection det = testing::MeasuredDetection(kCamera, u, v, d, kDisparitySigmaPx);
  testing::SetObstacleBox(det, kCamera, width_m, height_m);
  det.score = 1.0;
  det.extractor = "synthetic";
  return det;
}

detection::Detection Detect(const Target& target, int frame, std::mt19937* rng) {
  return Detect(target.At(frame), target.width_m, target.height_m, rng);
}

Eigen::Vector3d ToEigen(const cv::Vec3d& v) { return {v[0], v[1], v[2]}; }

const Track* Find(const std::vector<Track>& tracks, std::uint64_t id) {
  for (const Track& t : tracks) {
    if (t.id == id) return &t;
  }
  return nullptr;
}

// Distance in the image between the track's filtered position and the point `truth`.
double PixelError(const Track& t, const Eigen::Vector3d& truth) {
  const Eigen::Vector2d a = Project(kCamera, ToEigen(t.position_cam_m));
  return (a - Project(kCamera, truth)).norm();
}

// The track nearest (3-D) to `p`.
const Track* Nearest(const std::vector<Track>& tracks, const Eigen::Vector3d& p) {
  const Track* best = nullptr;
  double best_distance = std::numeric_limits<double>::infinity();
  for (const Track& t : tracks) {
    const double distance = (ToEigen(t.position_cam_m) - p).norm();
    if (distance < best_distance) {
      best_distance = distance;
      best = &t;
    }
  }
  return best;
}

TEST(Tracker, CrossingTargetsAtDifferentDepthsKeepTheirIds) {
  // Near: 30 m, moving right at 5 m/s. Far: 60 m, moving left at 10 m/s, twice the size so that
  // both have the same box (47 x 35 px) on the same image row: only depth tells them apart. They
  // cross at the image centre at t = 2 s. While the near one covers the far one's centre, the far
  // one is not detected (about 6 frames).
  const Target near{.p0 = {-10, 1, 30}, .v = {5, 0, 0}, .width_m = 2, .height_m = 1.5};
  const Target far{.p0 = {20, 2, 60}, .v = {-10, 0, 0}, .width_m = 4, .height_m = 3};
  Tracker tracker;
  std::mt19937 rng(1);
  std::uint64_t near_id = 0, far_id = 0;
  int hidden_frames = 0;
  for (int k = 0; k < 120; ++k) {
    const Eigen::Vector3d pn = near.At(k), pf = far.At(k);
    const double du = kCamera.f_px * (pn.x() / pn.z() - pf.x() / pf.z());
    const double near_width_px = kCamera.f_px * near.width_m / pn.z();
    const bool far_hidden = std::abs(du) < near_width_px / 2;
    std::vector<detection::Detection> detections = {Detect(near, k, &rng)};
    if (!far_hidden) detections.push_back(Detect(far, k, &rng));
    hidden_frames += far_hidden;
    const std::vector<Track> tracks = tracker.Update(detections, FrameTime(k), kCamera);

    // Clean detections: never a spurious track.
    ASSERT_EQ(tracks.size(), 2u) << "frame " << k;
    if (k == 5) {
      near_id = Nearest(tracks, pn)->id;
      far_id = Nearest(tracks, pf)->id;
      ASSERT_NE(near_id, far_id);
    }
    if (k < 5) continue;
    const Track* tn = Find(tracks, near_id);
    const Track* tf = Find(tracks, far_id);
    ASSERT_NE(tn, nullptr) << "frame " << k;
    ASSERT_NE(tf, nullptr) << "frame " << k;
    if (k < 10) continue;  // the depth filters settle
    // Each id stays on its own obstacle: in the image within 2 px (centroid noise 0.3 px; a swap
    // is tens of pixels off except at the crossing), and in depth within a few sigma of the
    // filtered depth (raw noise 0.54 m at 30 m, 2.1 m at 60 m; a swap is 30 m off).
    EXPECT_LT(PixelError(*tn, pn), 2.0) << "frame " << k;
    EXPECT_LT(PixelError(*tf, pf), 2.0) << "frame " << k;
    EXPECT_LT(std::abs(tn->position_cam_m[2] - pn.z()), 1.0) << "frame " << k;
    EXPECT_LT(std::abs(tf->position_cam_m[2] - pf.z()), 3.0) << "frame " << k;
    EXPECT_EQ(tn->state, TrackState::kConfirmed) << "frame " << k;
    EXPECT_EQ(tf->state, far_hidden ? TrackState::kCoasting : TrackState::kConfirmed)
        << "frame " << k;
  }
  EXPECT_GE(hidden_frames, 5);
}

TEST(Tracker, OccludedTargetKeepsItsIdAndCoastsThroughTheGap) {
  // 40 m ahead, moving right at 4 m/s and closing at 3 m/s. No detection for frames 30..41.
  const Target target{.p0 = {-6, 1, 40}, .v = {4, 0, -3}};
  constexpr int kGapStart = 30, kGapEnd = 42;  // [start, end)
  Tracker tracker;
  std::mt19937 rng(2);
  std::uint64_t id = 0;
  int hits_before_gap = 0;
  cv::Size box_size;
  double depth_before_gap = 0;
  for (int k = 0; k < 75; ++k) {
    const bool occluded = k >= kGapStart && k < kGapEnd;
    std::vector<detection::Detection> detections;
    if (!occluded) detections.push_back(Detect(target, k, &rng));
    const std::vector<Track> tracks = tracker.Update(detections, FrameTime(k), kCamera);
    ASSERT_EQ(tracks.size(), 1u) << "frame " << k;
    const Track& t = tracks[0];
    if (k == 0) id = t.id;
    EXPECT_EQ(t.id, id) << "frame " << k;
    EXPECT_EQ(t.age_frames, k + 1);
    if (k == kGapStart - 1) {
      EXPECT_EQ(t.state, TrackState::kConfirmed);
      hits_before_gap = t.hits;
      box_size = t.detection.bbox.size();
      depth_before_gap = t.detection.depth_m;
    }
    if (occluded) {
      EXPECT_EQ(t.state, TrackState::kCoasting) << "frame " << k;
      EXPECT_EQ(t.misses, k - kGapStart + 1);
      EXPECT_EQ(t.hits, hits_before_gap);
      // The box follows the prediction, same size, and stays on the truth: the 3-D prediction of a
      // constant-velocity obstacle drifts only by the velocity error (a few cm/s) times the gap.
      const Eigen::Vector3d truth = target.At(k);
      const cv::Point2d truth_px(kCamera.cx + kCamera.f_px * truth.x() / truth.z(),
                                 kCamera.cy + kCamera.f_px * truth.y() / truth.z());
      EXPECT_LT(cv::norm(t.detection.centroid_px - truth_px), 1.5) << "frame " << k;
      // The full size, scaled with the predicted depth (the obstacle closes in).
      EXPECT_NEAR(t.detection.bbox.width, box_size.width * depth_before_gap / t.position_cam_m[2],
                  1.5);
      EXPECT_NEAR(t.detection.bbox.height, box_size.height * depth_before_gap / t.position_cam_m[2],
                  1.5);
      const cv::Point2d box_centre(t.detection.bbox.x + t.detection.bbox.width / 2.0,
                                   t.detection.bbox.y + t.detection.bbox.height / 2.0);
      EXPECT_LT(cv::norm(box_centre - truth_px), 2.5) << "frame " << k;
      EXPECT_LT(std::abs(t.position_cam_m[2] - truth.z()), 1.0) << "frame " << k;
    } else if (k >= kGapEnd) {
      EXPECT_EQ(t.state, TrackState::kConfirmed) << "frame " << k;
      EXPECT_EQ(t.misses, 0);
    }
  }
}

TEST(Tracker, CoastingUsesTheOccludedNoises) {
  // The same 10-frame occlusion under three settings. The thesis's defaults (q = 1e-5, R = 1e7
  // px^2) let the position sigma grow by free propagation only. A large occluded process noise
  // makes it grow faster; a tiny occluded measurement noise pins it (the pseudo-measurement is
  // trusted). None of them moves the predicted position.
  const Target target{.p0 = {-2, 0, 30}, .v = {3, 0, -2}};
  auto run = [&](double occluded_q, double occluded_r) {
    TrackerOptions options;
    options.kalman.occluded_process_noise = occluded_q;
    options.kalman.occluded_measurement_noise = occluded_r;
    Tracker tracker(options);
    std::vector<Track> tracks;
    for (int k = 0; k < 30; ++k) {
      tracks = tracker.Update({Detect(target, k, nullptr)}, FrameTime(k), kCamera);
    }
    const double sigma_before = tracks.at(0).position_sigma_m[0];
    for (int k = 30; k < 40; ++k) tracks = tracker.Update({}, FrameTime(k), kCamera);
    EXPECT_EQ(tracks.at(0).state, TrackState::kCoasting);
    EXPECT_LT((ToEigen(tracks.at(0).position_cam_m) - target.At(39)).norm(), 0.05);
    return tracks.at(0).position_sigma_m[0] / sigma_before;
  };
  const double thesis = run(1e-5, 1e7);
  const double noisy = run(10.0, 1e7);
  const double pinned = run(1e-5, 1e-6);
  std::cout << "position sigma growth over the occlusion: thesis " << thesis
            << ", q = 10: " << noisy << ", R = 1e-6 px^2: " << pinned << "\n";
  EXPECT_GT(thesis, 1.2);  // 10 frames of velocity uncertainty
  EXPECT_GT(noisy, 2 * thesis);
  EXPECT_LT(pinned, 1.0);
}

TEST(Tracker, OcclusionOfDeleteMissesFramesEndsTheTrack) {
  // delete_misses = 15: the 15th consecutive miss deletes; the obstacle comes back as a new id.
  const Target target{.p0 = {0, 0, 40}, .v = {1, 0, 0}};
  Tracker tracker;
  std::vector<Track> tracks;
  for (int k = 0; k < 10; ++k) {
    tracks = tracker.Update({Detect(target, k, nullptr)}, FrameTime(k), kCamera);
  }
  ASSERT_EQ(tracks.size(), 1u);
  const std::uint64_t id = tracks[0].id;
  for (int k = 10; k < 24; ++k) tracks = tracker.Update({}, FrameTime(k), kCamera);
  ASSERT_EQ(tracks.size(), 1u);
  EXPECT_EQ(tracks[0].misses, 14);
  EXPECT_EQ(tracks[0].state, TrackState::kCoasting);
  EXPECT_THAT(tracker.Update({}, FrameTime(24), kCamera), IsEmpty());
  tracks = tracker.Update({Detect(target, 25, nullptr)}, FrameTime(25), kCamera);
  ASSERT_EQ(tracks.size(), 1u);
  EXPECT_GT(tracks[0].id, id);
  EXPECT_EQ(tracks[0].state, TrackState::kTentative);
}

TEST(Tracker, IdsStrictlyIncreaseAndAreNeverReused) {
  // Obstacles enter and leave; single-frame clutter comes and goes; one obstacle reappears where a
  // deleted track was; then Reset(). Every new id must exceed every id seen before, and an id that
  // has gone must never come back.
  const Target a{.p0 = {-3, 0, 25}, .v = {0.5, 0, 0}};
  const Target b{.p0 = {4, -1, 45}, .v = {-1, 0, -2}};
  Tracker tracker;
  std::mt19937 rng(3);
  // Clutter well away from a (other pixels, other depths), so that a's track is left to die.
  std::uniform_real_distribution<double> clutter_x(5, 20), clutter_z(60, 80);
  std::set<std::uint64_t> seen, gone, previous;
  std::uint64_t max_seen = 0;
  std::uint64_t a_id = 0;
  bool a_deleted_on_time = false;
  for (int k = 0; k < 100; ++k) {
    if (k == 70) tracker.Reset();
    std::vector<detection::Detection> detections;
    if (k <= 20) detections.push_back(Detect(a, k, &rng));
    if (k >= 10) detections.push_back(Detect(b, k, &rng));
    // After a's track is deleted, an obstacle appears exactly where a was last seen.
    if (k >= 40 && k < 60) detections.push_back(Detect(a, 20, &rng));
    if (k % 7 == 3) detections.push_back(Detect({clutter_x(rng), 0, clutter_z(rng)}, 1, 1, &rng));
    const std::vector<Track> tracks = tracker.Update(detections, FrameTime(k), kCamera);

    std::set<std::uint64_t> current;
    for (const Track& t : tracks) {
      ASSERT_GE(t.id, 1u);
      EXPECT_FALSE(gone.count(t.id)) << "id " << t.id << " reused at frame " << k;
      if (!seen.count(t.id)) {
        EXPECT_GT(t.id, max_seen) << "frame " << k;
        seen.insert(t.id);
        max_seen = std::max(max_seen, t.id);
      }
      current.insert(t.id);
    }
    for (std::uint64_t id : previous) {
      if (!current.count(id)) gone.insert(id);
    }
    previous = current;
    if (k == 20) a_id = Nearest(tracks, a.At(20))->id;
    // a's last detection is at frame 20: 15 misses later (frame 35) the track is gone.
    if (k == 34) {
      EXPECT_NE(Find(tracks, a_id), nullptr);
    }
    if (k == 35) a_deleted_on_time = Find(tracks, a_id) == nullptr;
    if (k == 45) {
      const Track* reborn = Nearest(tracks, a.At(20));
      ASSERT_NE(reborn, nullptr);
      EXPECT_GT(reborn->id, a_id);
      EXPECT_EQ(reborn->state, TrackState::kConfirmed);
    }
  }
  EXPECT_TRUE(a_deleted_on_time);
  EXPECT_GT(gone.size(), 5u);  // a, the clutter, everything Reset() dropped
  EXPECT_EQ(tracker.next_id(), max_seen + 1);
}

// Confirms a track on a stationary obstacle at 30 m (3 frames), then offers one detection changed
// by `change`. True when it went to the existing track; false when the existing one missed (the
// detection then started a new track, or, inside the track's box at a depth it allows, was taken
// for a fragment of it and started none).
bool AssignedAfterChange(const std::function<void(detection::Detection&)>& change) {
  Tracker tracker;
  const Eigen::Vector3d p(0.5, 0.2, 30);
  std::vector<Track> tracks;
  for (int k = 0; k < 3; ++k) {
    tracks = tracker.Update({Detect(p, 2, 1.5, nullptr)}, FrameTime(k), kCamera);
  }
  EXPECT_EQ(tracks.size(), 1u);
  EXPECT_EQ(tracks[0].state, TrackState::kConfirmed);
  const std::uint64_t id = tracks[0].id;
  detection::Detection changed = Detect(p, 2, 1.5, nullptr);
  change(changed);
  tracks = tracker.Update({changed}, FrameTime(3), kCamera);
  const Track* old_track = Find(tracks, id);
  EXPECT_NE(old_track, nullptr);
  if (old_track == nullptr) return false;
  if (old_track->misses == 0) {
    EXPECT_EQ(tracks.size(), 1u);
    return true;
  }
  EXPECT_EQ(old_track->state, TrackState::kCoasting);
  EXPECT_LE(tracks.size(), 2u);
  if (tracks.size() == 2) {
    EXPECT_GT(tracks.back().id, id);
    EXPECT_EQ(tracks.back().state, TrackState::kTentative);
  }
  return false;
}

// The same obstacle seen at `depth_m` (same pixel, disparity changed).
std::function<void(detection::Detection&)> AtDepth(double depth_m) {
  return [depth_m](detection::Detection& d) {
    const double scale = depth_m / d.position_cam_m[2];
    d.position_cam_m *= scale;
    d.depth_m = depth_m;
    d.disparity_px = kFB / depth_m;
    d.range_m = cv::norm(d.position_cam_m);
  };
}

TEST(Tracker, DepthGateRejectsADetectionAtAnotherDepth) {
  // The depth gate: 3 sigmas of sqrt(sigma_d^2 + P_zz), sigma_d floored at 5 % of the depth. At
  // 30 m: sigma_d = max(0.54, 1.5) m, and the predicted depth of a three-hit track (its velocity
  // barely known) has a sigma of about 1 m: about 5.4 m. 30 -> 38.4 m (the old fixed ratio gate,
  // 1.3, let it through) is another obstacle; 30 -> 33.6 m is not. The ratio cap holds too.
  EXPECT_FALSE(AssignedAfterChange(AtDepth(30 * 1.32)));
  EXPECT_FALSE(AssignedAfterChange(AtDepth(30 / 1.32)));
  EXPECT_FALSE(AssignedAfterChange(AtDepth(30 * 1.28)));
  EXPECT_FALSE(AssignedAfterChange(AtDepth(30 / 1.28)));
  EXPECT_TRUE(AssignedAfterChange(AtDepth(30 * 1.12)));
  EXPECT_TRUE(AssignedAfterChange(AtDepth(30 / 1.12)));
  // A detection at half the range inside the track's box starts a (child) track of its own.
  EXPECT_FALSE(AssignedAfterChange(AtDepth(15)));
}

TEST(Tracker, AreaPerimeterAndDistanceGates) {
  // max_area_ratio 3, max_perimeter_ratio 2.5: a larger blob is refused beyond them; a smaller
  // one is a partial view and passes. Position: the detection's box must overlap the predicted
  // box (grown by 3 sigmas), and its centre be within max_distance_px 80.
  EXPECT_FALSE(AssignedAfterChange(
      [](detection::Detection& d) { d.area_px = static_cast<int>(d.area_px * 3.2); }));
  EXPECT_TRUE(AssignedAfterChange(
      [](detection::Detection& d) { d.area_px = static_cast<int>(d.area_px * 2.8); }));
  EXPECT_FALSE(AssignedAfterChange([](detection::Detection& d) { d.perimeter_px *= 2.6; }));
  EXPECT_TRUE(AssignedAfterChange([](detection::Detection& d) { d.perimeter_px *= 2.4; }));
  EXPECT_TRUE(AssignedAfterChange([](detection::Detection& d) { d.perimeter_px /= 2.6; }));
  EXPECT_TRUE(AssignedAfterChange([](detection::Detection& d) { d.area_px /= 4; }));
  // The box is 47 px wide: a move of 30 px still overlaps the prediction, 60 px does not.
  for (const auto& [shift_px, assigned] : {std::pair{60.0, false}, std::pair{30.0, true}}) {
    EXPECT_EQ(AssignedAfterChange([shift = shift_px](detection::Detection& d) {
                d.centroid_px.x += shift;
                d.bbox.x += static_cast<int>(shift);
                d.position_cam_m[0] += shift * d.position_cam_m[2] / kCamera.f_px;
              }),
              assigned)
        << shift_px << " px";
  }
}

// Time of closest approach t* = -p.v / |v|^2 and miss distance |p + v t*| of a relative position
// p and velocity v.
Eigen::Vector2d Collision(const Eigen::Vector3d& p, const Eigen::Vector3d& v) {
  const double t_star = -p.dot(v) / v.squaredNorm();
  return {t_star, (p + t_star * v).norm()};
}

// The state tolerance of (t*, miss distance) for a track: sum over the six state components of
// |d(t*, miss)/d component| times the track's own 1-sigma of that component (numeric derivatives).
// The sum of |J_i| sigma_i bounds the linearised sigma whatever the correlations between the
// components are.
Eigen::Vector2d CollisionTolerance(const Track& t) {
  Eigen::Matrix<double, 6, 1> state, sigma;
  state << ToEigen(t.position_cam_m), ToEigen(t.velocity_cam_mps);
  sigma << ToEigen(t.position_sigma_m), ToEigen(t.velocity_sigma_mps);
  Eigen::Vector2d tolerance = Eigen::Vector2d::Zero();
  for (int i = 0; i < 6; ++i) {
    const double h = 1e-6 * std::max(1.0, std::abs(state[i]));
    Eigen::Matrix<double, 6, 1> plus = state, minus = state;
    plus[i] += h;
    minus[i] -= h;
    const Eigen::Vector2d derivative =
        (Collision(plus.head<3>(), plus.tail<3>()) - Collision(minus.head<3>(), minus.tail<3>())) /
        (2 * h);
    tolerance += derivative.cwiseAbs() * sigma[i];
  }
  return tolerance;
}

// The tracker's collision outputs on one straight-line obstacle over many noisy runs, against the
// truth, from `first_frame` on.
struct CollisionErrors {
  Eigen::Vector2d worst_normalised = Eigen::Vector2d::Zero();  // max |error| / tolerance
  Eigen::Vector2d rms_normalised = Eigen::Vector2d::Zero();    // RMS of error / tolerance
  Eigen::Vector2d last_rms = Eigen::Vector2d::Zero();          // RMS error at the last frame
  Eigen::Vector2d last_tolerance = Eigen::Vector2d::Zero();    // mean tolerance at the last frame
  double mean_rate_error_mps = 0;        // mean of (range rate - truth) over runs and frames
  double rate_error_over_sigma_rms = 0;  // RMS of (range rate - truth) / range_rate_sigma_mps
  double smoothed_over_raw = 0;          // RMS range error, smoothed / raw
  bool always_closing = true;            // a time to collision at every checked frame
};

CollisionErrors MeasureCollision(const Target& target, int frames, int first_frame, int runs) {
  CollisionErrors e;
  Eigen::Vector2d normalised_sq = Eigen::Vector2d::Zero();
  double rate_sum = 0, raw_sq = 0, smoothed_sq = 0, rate_normalised_sq = 0;
  int n = 0;
  for (int run = 0; run < runs; ++run) {
    Tracker tracker;
    std::mt19937 rng(100 + run);
    for (int k = 0; k < frames; ++k) {
      const std::vector<Track> tracks =
          tracker.Update({Detect(target, k, &rng)}, FrameTime(k), kCamera);
      EXPECT_EQ(tracks.size(), 1u);
      if (tracks.size() != 1 || k < first_frame) continue;
      const Track& t = tracks[0];
      const Eigen::Vector3d p = target.At(k);
      if (!t.time_to_collision_s || !t.closest_approach_m) {
        e.always_closing = false;
        continue;
      }
      const Eigen::Vector2d error =
          Eigen::Vector2d(*t.time_to_collision_s, *t.closest_approach_m) - Collision(p, target.v);
      const Eigen::Vector2d tolerance = CollisionTolerance(t);
      const Eigen::Vector2d normalised = error.cwiseAbs().cwiseQuotient(tolerance);
      e.worst_normalised = e.worst_normalised.cwiseMax(normalised);
      normalised_sq += normalised.cwiseAbs2();
      if (k == frames - 1) {
        e.last_rms += error.cwiseAbs2() / runs;
        e.last_tolerance += tolerance / runs;
      }
      const double rate_error = t.range_rate_mps - p.dot(target.v) / p.norm();
      rate_sum += rate_error;
      rate_normalised_sq += std::pow(rate_error / t.range_rate_sigma_mps, 2);
      raw_sq += std::pow(t.range_m - p.norm(), 2);
      smoothed_sq += std::pow(t.smoothed_range_m - p.norm(), 2);
      ++n;
    }
  }
  e.rms_normalised = (normalised_sq / n).cwiseSqrt();
  e.last_rms = e.last_rms.cwiseSqrt();
  e.mean_rate_error_mps = rate_sum / n;
  e.rate_error_over_sigma_rms = std::sqrt(rate_normalised_sq / n);
  e.smoothed_over_raw = std::sqrt(smoothed_sq / raw_sq);
  std::cout << "error / tolerance: worst " << e.worst_normalised.transpose() << ", rms "
            << e.rms_normalised.transpose() << "; last frame: rms error " << e.last_rms.transpose()
            << ", tolerance " << e.last_tolerance.transpose() << "; mean range-rate error "
            << e.mean_rate_error_mps << " m/s, rms over its sigma " << e.rate_error_over_sigma_rms
            << "; smoothed/raw range RMS " << e.smoothed_over_raw << "\n";
  return e;
}

// What both encounters below check: a time to collision at every checked frame; the errors on t*
// and on the miss distance within 4 tolerances, their RMS within 1.2; at the last frame t* to
// 0.1 s and the miss distance to `last_miss_m` (tolerance and RMS error); and the range rate
// unbiased, its mean error within 0.5 m/s.
void ExpectCollisionWithin(const CollisionErrors& e, double last_miss_m) {
  EXPECT_TRUE(e.always_closing);
  EXPECT_LT(e.worst_normalised[0], 4.0);
  EXPECT_LT(e.worst_normalised[1], 4.0);
  EXPECT_LT(e.rms_normalised[0], 1.2);
  EXPECT_LT(e.rms_normalised[1], 1.2);
  EXPECT_LT(e.last_tolerance[0], 0.1);
  EXPECT_LT(e.last_tolerance[1], last_miss_m);
  EXPECT_LT(e.last_rms[0], 0.1);
  EXPECT_LT(e.last_rms[1], last_miss_m);
  EXPECT_LT(std::abs(e.mean_rate_error_mps), 0.5);
}

TEST(Tracker, HeadOnApproachGivesTimeToCollisionAndMissDistance) {
  // From 80 m, closing at 15 m/s, passing 2.24 m off the camera (2 m right, 1 m up): t* = z / 15,
  // miss distance |(2, -1)| = 2.236 m. 30 runs of 3 s (80 m -> 35 m), checked from 1 s on (the
  // time to collision is given once the closing speed is 2 sigma clear of zero).
  // The state tolerance (CollisionTolerance, from the track's own sigmas, which kalman_test shows
  // to be consistent) is about one sigma: every error is within 4 of it, their RMS within 1.2
  // (measured: worst 2.8 and 1.6, RMS 0.91 and 0.50). At the end (t* = 2.3 s, 35 m) the
  // tolerances are 0.06 s on t* and 0.18 m on the miss distance.
  const Target target{.p0 = {2, -1, 80}, .v = {0, 0, -15}};
  const CollisionErrors e = MeasureCollision(target, 90, 30, 30);
  // The fading filter's range rate is noisy frame to frame (0.105 sigma / dt: 5 m/s at 50 m), but
  // unbiased: its mean over the 2250 frames is within 0.5 m/s of the truth (-15 m/s).
  ExpectCollisionWithin(e, 0.3);
  // The smoothed range beats the raw one by the fading filter's factor (0.62 at beta 0.7).
  EXPECT_LT(e.smoothed_over_raw, 0.7);
}

TEST(Tracker, PassingObstacleGivesItsClosestApproach) {
  // From (-10, 0, 60) at (5, 0, -10) m/s: t* = 650 / 125 = 5.2 s from the start, passing
  // |(16, 0, 8)| = 17.9 m away. 30 runs of 3.6 s (depth 60 m -> 24 m), checked from 1 s
  // on (before, the closing speed is not yet 2 sigma clear of zero: no time to collision).
  // Here the miss distance depends on the closing speed too (an error dv moves the closest point
  // by about t* dv). Measured: worst 2.3 and 1.9 tolerances, RMS 0.63 and 0.60; at the end
  // (t* = 1.6 s) t* to 0.03 s and the miss distance to 0.24 m.
  const Target target{.p0 = {-10, 0, 60}, .v = {5, 0, -10}};
  const CollisionErrors e = MeasureCollision(target, 110, 30, 30);
  ExpectCollisionWithin(e, 0.5);
  // The range-rate sigma on the wire is honest: the error over it has an RMS near 1.
  EXPECT_GT(e.rate_error_over_sigma_rms, 0.5);
  EXPECT_LT(e.rate_error_over_sigma_rms, 1.5);
}

TEST(Tracker, RecedingObstacleHasNoTimeToCollision) {
  const Target target{.p0 = {1, 0, 30}, .v = {0, 0, 6}};
  Tracker tracker;
  std::vector<Track> tracks;
  for (int k = 0; k < 30; ++k) {
    tracks = tracker.Update({Detect(target, k, nullptr)}, FrameTime(k), kCamera);
  }
  ASSERT_EQ(tracks.size(), 1u);
  EXPECT_FALSE(tracks[0].time_to_collision_s.has_value());
  EXPECT_FALSE(tracks[0].closest_approach_m.has_value());
  const Eigen::Vector3d p = target.At(29);
  EXPECT_NEAR(tracks[0].range_rate_mps, p.dot(target.v) / p.norm(), 0.05);
  EXPECT_NEAR(tracks[0].velocity_cam_mps[2], 6, 0.05);
}

TEST(Tracker, TentativeTracksConfirmOrDie) {
  const Eigen::Vector3d p(0, 0, 30);
  Tracker tracker;  // confirm_hits 3, tentative_delete_misses 2
  std::vector<Track> tracks = tracker.Update({Detect(p, 2, 1.5, nullptr)}, FrameTime(0), kCamera);
  ASSERT_EQ(tracks.size(), 1u);
  EXPECT_EQ(tracks[0].state, TrackState::kTentative);
  EXPECT_EQ(tracks[0].hits, 1);
  tracks = tracker.Update({}, FrameTime(1), kCamera);  // one dropped detection is survived
  ASSERT_EQ(tracks.size(), 1u);
  EXPECT_EQ(tracks[0].state, TrackState::kTentative);
  EXPECT_EQ(tracks[0].misses, 1);
  tracks = tracker.Update({Detect(p, 2, 1.5, nullptr)}, FrameTime(2), kCamera);
  ASSERT_EQ(tracks.size(), 1u);
  EXPECT_EQ(tracks[0].state, TrackState::kTentative);
  EXPECT_EQ(tracks[0].hits, 2);
  tracks = tracker.Update({Detect(p, 2, 1.5, nullptr)}, FrameTime(3), kCamera);
  ASSERT_EQ(tracks.size(), 1u);
  EXPECT_EQ(tracks[0].state, TrackState::kConfirmed);  // third hit
  EXPECT_EQ(tracks[0].age_frames, 4);

  // Clutter: seen once, missed twice, gone.
  Tracker other;
  other.Update({Detect(p, 2, 1.5, nullptr)}, FrameTime(0), kCamera);
  EXPECT_EQ(other.Update({}, FrameTime(1), kCamera).size(), 1u);
  EXPECT_THAT(other.Update({}, FrameTime(2), kCamera), IsEmpty());

  TrackerOptions immediate;
  immediate.confirm_hits = 1;
  Tracker at_once(immediate);
  tracks = at_once.Update({Detect(p, 2, 1.5, nullptr)}, FrameTime(0), kCamera);
  ASSERT_EQ(tracks.size(), 1u);
  EXPECT_EQ(tracks[0].state, TrackState::kConfirmed);
}

// The M-of-N rule with the defaults (M = 3 hits within N = 5 updates, tentative_delete_misses 2)
// is exactly the former "3 hits in all": every hit/miss sequence of up to 10 updates that starts
// with a hit gives the same life cycle under both (the former computed here, independently).
TEST(Tracker, DefaultMOfNIsThreeHitsInAllForEverySequence) {
  const Eigen::Vector3d p(0, 0, 30);
  constexpr int kLength = 10;
  for (int pattern = 0; pattern < (1 << (kLength - 1)); ++pattern) {
    Tracker tracker;
    int hits = 0, run_of_misses = 0;
    bool alive = true, confirmed = false;
    std::string sequence;
    for (int k = 0; k < kLength && alive; ++k) {
      const bool hit = k == 0 || ((pattern >> (k - 1)) & 1) != 0;
      sequence += hit ? 'H' : 'm';
      std::vector<detection::Detection> detections;
      if (hit) detections.push_back(Detect(p, 2, 1.5, nullptr));
      const std::vector<Track> tracks = tracker.Update(detections, FrameTime(k), kCamera);
      // The former rule: confirmed at 3 hits; tentative and deleted at 2 misses in a row.
      run_of_misses = hit ? 0 : run_of_misses + 1;
      hits += hit ? 1 : 0;
      if (!confirmed && run_of_misses >= 2) alive = false;
      if (alive && hits >= 3) confirmed = true;
      if (!alive) {
        EXPECT_THAT(tracks, IsEmpty()) << sequence;
        continue;
      }
      ASSERT_EQ(tracks.size(), 1u) << sequence;
      const TrackState want = !confirmed ? TrackState::kTentative
                              : hit      ? TrackState::kConfirmed
                                         : TrackState::kCoasting;
      EXPECT_EQ(tracks[0].state, want) << sequence;
    }
  }
}

// M hits within the last N updates, exactly: the states of a static obstacle under hit/miss
// sequences ('H' a detection, 'm' none), for several M and N.
TEST(Tracker, MOfNConfirmsAtMHitsWithinTheLastNUpdates) {
  const Eigen::Vector3d p(0, 0, 30);
  // The state after each update: 't' tentative, 'C' confirmed, 'c' coasting, '-' deleted.
  const auto states = [&](int m, int n, int tentative_delete_misses, const std::string& sequence) {
    TrackerOptions options;
    options.confirm_hits = m;
    options.confirm_window = n;
    options.tentative_delete_misses = tentative_delete_misses;
    Tracker tracker(options);
    std::string out;
    for (size_t k = 0; k < sequence.size(); ++k) {
      std::vector<detection::Detection> detections;
      if (sequence[k] == 'H') detections.push_back(Detect(p, 2, 1.5, nullptr));
      const std::vector<Track> tracks =
          tracker.Update(detections, FrameTime(static_cast<int>(k)), kCamera);
      if (tracks.empty()) {
        out += '-';
        continue;
      }
      switch (tracks[0].state) {
        case TrackState::kTentative: out += 't'; break;
        case TrackState::kConfirmed: out += 'C'; break;
        case TrackState::kCoasting: out += 'c'; break;
      }
    }
    return out;
  };
  // 3 of 5: every other frame confirms at the fifth update.
  EXPECT_EQ(states(3, 5, 2, "HmHmHmH"), "ttttCcC");
  // 3 of 4: every other frame never confirms (at most 2 hits in any 4 updates); it lives on as
  // tentative, since it never misses twice in a row.
  EXPECT_EQ(states(3, 4, 2, "HmHmHmHm"), "tttttttt");
  EXPECT_EQ(states(3, 4, 2, "HmHHm"), "tttCc");
  EXPECT_EQ(states(3, 4, 2, "HHmH"), "tttC");
  // 3 of 3: consecutive hits only; an old hit drops out of the window.
  EXPECT_EQ(states(3, 3, 2, "HmHHmHHH"), "tttttttC");
  EXPECT_EQ(states(3, 3, 2, "HHH"), "ttC");
  // 2 of 5 with 3 misses to delete a tentative track: two hits three updates apart confirm.
  EXPECT_EQ(states(2, 5, 3, "HmmH"), "tttC");
  EXPECT_EQ(states(2, 5, 3, "Hmmm"), "ttt-");
  // 1 of N: confirmed at once.
  EXPECT_EQ(states(1, 1, 2, "Hm"), "Cc");
}

TEST(TrackerOptions, ConfirmWindowMustHoldConfirmHits) {
  TrackerOptions options;
  options.confirm_hits = 4;
  options.confirm_window = 3;
  std::vector<std::string> problems = options.Validate();
  ASSERT_EQ(problems.size(), 1u) << ::testing::PrintToString(problems);
  EXPECT_EQ(problems[0], "confirm_window: must be >= confirm_hits = 4 (got 3)");
  options.confirm_window = 65;
  problems = options.Validate();
  ASSERT_EQ(problems.size(), 1u) << ::testing::PrintToString(problems);
  EXPECT_THAT(problems[0], HasSubstr("confirm_window: must be in [1, 64]"));
  options.confirm_window = 64;
  EXPECT_THAT(options.Validate(), IsEmpty());
  EXPECT_EQ(TrackerOptions{}.confirm_window, 5);
}

TEST(Tracker, IgnoresLowScoreAndUnrangedDetections) {
  TrackerOptions options;
  options.min_score = 0.5;
  Tracker tracker(options);
  detection::Detection weak = Detect(Eigen::Vector3d(0, 0, 30), 2, 1.5, nullptr);
  weak.score = 0.4;
  detection::Detection unranged = Detect(Eigen::Vector3d(5, 0, 30), 2, 1.5, nullptr);
  unranged.position_cam_m = cv::Vec3d(0, 0, std::numeric_limits<double>::infinity());
  detection::Detection behind = Detect(Eigen::Vector3d(-5, 0, 30), 2, 1.5, nullptr);
  behind.position_cam_m[2] = -30;
  detection::Detection good = Detect(Eigen::Vector3d(8, 0, 30), 2, 1.5, nullptr);
  good.score = 0.5;
  const std::vector<Track> tracks =
      tracker.Update({weak, unranged, behind, good}, FrameTime(0), kCamera);
  ASSERT_EQ(tracks.size(), 1u);
  EXPECT_NEAR(tracks[0].position_cam_m[0], 8, 1e-9);
}

TEST(Tracker, RealTimeStepRepeatedTimestampsAndLongGaps) {
  // Frames every 50 ms (not the nominal 33): the velocity comes out in m/s all the same.
  const Target target{.p0 = {-4, 0, 40}, .v = {6, 0, 0}};
  Tracker tracker;
  std::vector<Track> tracks;
  int64_t t_ns = 0;
  for (int k = 0; k < 40; ++k) {
    t_ns = k * 50'000'000LL;
    const Eigen::Vector3d p = target.p0 + target.v * (t_ns * 1e-9);
    tracks = tracker.Update({Detect(p, 2, 1.5, nullptr)}, t_ns, kCamera);
  }
  ASSERT_EQ(tracks.size(), 1u);
  EXPECT_NEAR(tracks[0].velocity_cam_mps[0], 6, 0.05);
  const cv::Vec3d before = tracks[0].position_cam_m;

  // The same timestamp again (dt = 0): no motion, still matched.
  const Eigen::Vector3d last = target.p0 + target.v * (t_ns * 1e-9);
  tracks = tracker.Update({Detect(last, 2, 1.5, nullptr)}, t_ns, kCamera);
  ASSERT_EQ(tracks.size(), 1u);
  EXPECT_EQ(tracks[0].misses, 0);
  EXPECT_LT(cv::norm(tracks[0].position_cam_m - before), 0.01);

  // An hour's gap (a stalled source): predicted for max_dt_s = 1 s only, never an hour.
  tracks = tracker.Update({}, t_ns + 3600LL * 1'000'000'000LL, kCamera);
  ASSERT_EQ(tracks.size(), 1u);
  EXPECT_EQ(tracks[0].state, TrackState::kCoasting);
  EXPECT_NEAR(tracks[0].position_cam_m[0], before[0] + 6 * 1.0, 0.1);
  EXPECT_TRUE(std::isfinite(tracks[0].smoothed_range_m));

  // A timestamp that goes backwards is a step of 0.
  const cv::Vec3d coasted = tracks[0].position_cam_m;
  tracks = tracker.Update({}, 0, kCamera);
  ASSERT_EQ(tracks.size(), 1u);
  EXPECT_LT(cv::norm(tracks[0].position_cam_m - coasted), 1e-9);
}

TEST(Tracker, HundredTargetsKeepTheirIds) {
  // 100 obstacles on a 10 x 10 grid of directions at depths 20..65 m, each drifting slowly; 40
  // frames. Reports the update time of 100 tracks x 100 detections.
  std::vector<Target> targets;
  for (int i = 0; i < 10; ++i) {
    for (int j = 0; j < 10; ++j) {
      const double z = 20 + 5 * ((i + 3 * j) % 10);
      const double u = 40 + 60 * i, v = 30 + 45 * j;
      targets.push_back({.p0 = {(u - 320) * z / 700, (v - 240) * z / 700, z},
                         .v = {0.05 * (j - 5), 0.03 * (i - 5), -1.0},
                         .width_m = 0.02 * z,
                         .height_m = 0.02 * z});
    }
  }
  Tracker tracker;
  std::mt19937 rng(9);
  std::vector<std::uint64_t> ids(targets.size(), 0);
  std::vector<double> update_us;
  for (int k = 0; k < 40; ++k) {
    std::vector<detection::Detection> detections;
    for (const Target& t : targets) detections.push_back(Detect(t, k, &rng));
    const auto start = std::chrono::steady_clock::now();
    const std::vector<Track> tracks = tracker.Update(detections, FrameTime(k), kCamera);
    const auto stop = std::chrono::steady_clock::now();
    if (k >= 5) {
      update_us.push_back(std::chrono::duration<double, std::micro>(stop - start).count());
    }
    ASSERT_EQ(tracks.size(), targets.size()) << "frame " << k;
    for (size_t i = 0; i < targets.size(); ++i) {
      const Track* nearest = Nearest(tracks, targets[i].At(k));
      ASSERT_NE(nearest, nullptr);
      if (k == 0) ids[i] = nearest->id;
      EXPECT_EQ(nearest->id, ids[i]) << "target " << i << " frame " << k;
    }
  }
  std::sort(update_us.begin(), update_us.end());
  std::cout << "100 tracks x 100 detections: median update " << update_us[update_us.size() / 2]
            << " us, max " << update_us.back() << " us\n";
}

TEST(TrackerOptions, ValidateNamesBadFields) {
  EXPECT_THAT(TrackerOptions{}.Validate(), IsEmpty());
  TrackerOptions options;
  options.kalman.process_noise = -1;
  options.gates.max_depth_ratio = 0.9;
  options.gates.max_distance_px = 0;
  options.confirm_hits = 0;
  options.delete_misses = 4;
  options.tentative_delete_misses = 5;
  options.fading_beta = 1.2;
  options.min_score = 1.5;
  options.max_dt_s = 0;
  const std::vector<std::string> problems = options.Validate();
  const std::string all = ::testing::PrintToString(problems);
  EXPECT_EQ(problems.size(), 8u) << all;
  EXPECT_THAT(all, HasSubstr("kalman.process_noise: must be >= 0"));
  EXPECT_THAT(all, HasSubstr("gates.max_depth_ratio: must be >= 1 (got 0.9)"));
  EXPECT_THAT(all, HasSubstr("gates.max_distance_px: must be > 0"));
  EXPECT_THAT(all, HasSubstr("confirm_hits: must be >= 1 (got 0)"));
  EXPECT_THAT(all, HasSubstr("tentative_delete_misses: must be <= delete_misses = 4 (got 5)"));
  EXPECT_THAT(all, HasSubstr("fading_beta: must be in (0, 1] (got 1.2)"));
  EXPECT_THAT(all, HasSubstr("min_score: must be in [0, 1] (got 1.5)"));
  EXPECT_THAT(all, HasSubstr("max_dt_s: must be > 0"));
  EXPECT_THROW(Tracker{options}, std::invalid_argument);
}

TEST(Tracker, RejectsAnInvalidCamera) {
  Tracker tracker;
  EXPECT_THROW(tracker.Update({}, 0, CameraModel{}), std::invalid_argument);
}

TEST(TrackStateName, NamesEveryState) {
  EXPECT_EQ(TrackStateName(TrackState::kTentative), "tentative");
  EXPECT_EQ(TrackStateName(TrackState::kConfirmed), "confirmed");
  EXPECT_EQ(TrackStateName(TrackState::kCoasting), "coasting");
}

// A far obstacle moving left slides behind a nearer one moving right: its visible blob is eaten
// from its left, so the blob's centroid drifts right while the obstacle moves left. The tracker
// re-centres a cut blob on its uncut edge with the obstacle's full width, so the far track keeps
// moving left, coasts in the right place while hidden, and takes its detections again when the
// obstacle comes out on the other side.
TEST(Tracker, ABlobCutByANearerOneIsCentredOnItsUncutEdge) {
  const Target near_target{.p0 = {-9, 0, 30}, .v = {12, 0, 0}, .width_m = 5, .height_m = 2};
  const Target far_target{.p0 = {6, 0, 48}, .v = {-12, 0, 0}, .width_m = 6, .height_m = 2};
  Tracker tracker;
  std::optional<std::uint64_t> far_id;
  int cut_frames = 0, wrong_direction = 0;
  for (int k = 0; k < 60; ++k) {
    std::vector<detection::Detection> detections{Detect(near_target, k, nullptr)};
    detection::Detection far = Detect(far_target, k, nullptr);
    const cv::Rect occluder = detections[0].bbox;
    // The far blob is what the near one leaves visible.
    const int left = std::max(far.bbox.x, occluder.x + occluder.width);
    const int right = far.bbox.x + far.bbox.width;
    const bool overlapping = (far.bbox & occluder).area() > 0;
    if (overlapping && right - left >= 4 && left > far.bbox.x) {
      far.bbox = cv::Rect(left, far.bbox.y, right - left, far.bbox.height);
      far.centroid_px.x = left + 0.5 * (right - left);
      far.area_px = far.bbox.area();
      far.perimeter_px = 2 * (far.bbox.width + far.bbox.height);
      ++cut_frames;
      detections.push_back(far);
    } else if (!overlapping || far.bbox.x >= occluder.x + occluder.width) {
      detections.push_back(far);
    }  // else: wholly hidden
    const std::vector<Track> tracks = tracker.Update(detections, FrameTime(k), kCamera);
    if (k == 5) {
      const Track* t = Nearest(tracks, far_target.At(k));
      ASSERT_NE(t, nullptr);
      far_id = t->id;
    }
    if (far_id) {
      const Track* t = Find(tracks, *far_id);
      ASSERT_NE(t, nullptr) << "frame " << k << ": the far track was lost";
      if (k > 8 && t->velocity_cam_mps[0] > 0) ++wrong_direction;
    }
  }
  EXPECT_GT(cut_frames, 5) << "the scenario must cut the far blob";
  EXPECT_EQ(wrong_direction, 0) << "the far track's velocity turned towards the cut";
  // Two obstacles, two tracks, all along.
  EXPECT_EQ(tracker.next_id(), 3u);
}

}  // namespace
}  // namespace stevi::tracking
