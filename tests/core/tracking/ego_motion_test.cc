// Ego-motion in the tracker: a rig driving down a street of parked cars at 10 m/s (10 fps), turning
// right by 90 degrees at a crossing (6 degrees a frame, a 9.5 m radius) and driving on. The
// detections are the cars' 3-D boxes projected through the known camera path (centroid and
// disparity with noise, seeded). Truth is the analytic geometry: the cars' centres in the world
// and the camera's pose at each frame.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <map>
#include <numbers>
#include <optional>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "core/tracking/tracker.h"
#include "tests/testing/measured_detection.h"

namespace stevi::tracking {
namespace {

// f = 700 px, 640 x 480, baseline 0.6 m.
const CameraModel kCamera{
    .f_px = 700, .cx = 320, .cy = 240, .baseline_m = 0.6, .width = 640, .height = 480};
constexpr double kFB = 700 * 0.6;
constexpr int64_t kFrameNs = 100'000'000;  // 10 fps
constexpr double kDt = 0.1;
constexpr double kCentroidSigmaPx = 0.3;
constexpr double kDisparitySigmaPx = 0.25;
constexpr double kDeg = std::numbers::pi / 180;

// The street: the world frame is the cam frame of frame 0 (x east, y down, z north). The rig
// drives north 1 m a frame for kStraight frames, turns right by 90 degrees in kTurn frames on an
// arc of radius 1 m / 6 degrees, then drives east.
constexpr int kStraight = 25;
constexpr int kTurn = 15;
constexpr int kFrames = 75;
constexpr double kTurnRate = 90.0 / kTurn * kDeg;  // radians a frame
constexpr double kRadius = 1.0 / kTurnRate;

// world_from_cam at frame k.
Eigen::Isometry3d WorldFromCam(int k) {
  double heading = 0;
  Eigen::Vector3d position;
  if (k <= kStraight) {
    position = {0, 0, static_cast<double>(k)};
  } else if (k <= kStraight + kTurn) {
    heading = (k - kStraight) * kTurnRate;
    position = {kRadius * (1 - std::cos(heading)), 0, kStraight + kRadius * std::sin(heading)};
  } else {
    heading = 90 * kDeg;
    position = {kRadius + (k - kStraight - kTurn), 0, kStraight + kRadius};
  }
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  // A right turn about the down axis: forward (z) turns towards east (x).
  pose.linear() = Eigen::AngleAxisd(heading, Eigen::Vector3d::UnitY()).toRotationMatrix();
  pose.translation() = position;
  return pose;
}

EgoMotion EgoMotionAt(int k) {
  return {.cam_now_from_cam_prev = WorldFromCam(k).inverse() * WorldFromCam(k - 1)};
}

// A parked car: an axis-aligned box in the world.
struct Car {
  int id;
  Eigen::Vector3d centre;
  Eigen::Vector3d size;  // along world x, y, z
};

// Cars parked 4 m either side of the first street (along z) and of the second (along x, at
// z = kStraight + kRadius), 1.5 m tall, 4.5 m long, their centres 0.75 m below the camera, and one
// beyond the crossing that the turn sweeps out of view.
std::vector<Car> Street() {
  const double y = 0.75;
  const Eigen::Vector3d along_z(1.8, 1.5, 4.5), along_x(4.5, 1.5, 1.8);
  const double second = kStraight + kRadius;
  return {
      {1, {-4, y, 16}, along_z},         {2, {4, y, 20}, along_z},
      {3, {-4, y, 36}, along_z},         {4, {-2, y, 58}, along_z},
      {5, {20, y, second + 4}, along_x}, {6, {30, y, second - 4}, along_x},
      {7, {40, y, second + 4}, along_x}, {8, {50, y, second - 4}, along_x},
  };
}

struct View {
  Eigen::Vector3d centre_cam;  // the car's centre in the cam frame
  cv::Rect box;                // its projected box (may extend beyond the image)
  bool in_front = false;       // every corner at least 1 m in front of the camera
};

View See(const Car& car, int k) {
  const Eigen::Isometry3d cam_from_world = WorldFromCam(k).inverse();
  View view;
  view.centre_cam = cam_from_world * car.centre;
  double u0 = 1e9, v0 = 1e9, u1 = -1e9, v1 = -1e9;
  view.in_front = true;
  for (int corner = 0; corner < 8; ++corner) {
    const Eigen::Vector3d offset(corner & 1 ? 0.5 : -0.5, corner & 2 ? 0.5 : -0.5,
                                 corner & 4 ? 0.5 : -0.5);
    const Eigen::Vector3d p = cam_from_world * (car.centre + offset.cwiseProduct(car.size));
    if (p.z() < 1) {
      view.in_front = false;
      return view;
    }
    const Eigen::Vector2d uv = Project(kCamera, p);
    u0 = std::min(u0, uv.x()), v0 = std::min(v0, uv.y());
    u1 = std::max(u1, uv.x()), v1 = std::max(v1, uv.y());
  }
  view.box =
      cv::Rect(cv::Point(static_cast<int>(std::lround(u0)), static_cast<int>(std::lround(v0))),
               cv::Point(static_cast<int>(std::lround(u1)), static_cast<int>(std::lround(v1))));
  return view;
}

const cv::Rect kImage(0, 0, 640, 480);

// Detected: the whole box in the image, within 60 m.
bool Detectable(const View& view) {
  return view.in_front && (view.box & kImage) == view.box && view.centre_cam.z() <= 60;
}

// What a stereo detector reports for the car: its box, the centroid at the projected centre and
// the disparity of the centre's depth, both with noise.
detection::Detection Detect(const View& view, std::mt19937& rng) {
  std::normal_distribution<double> centroid(0.0, kCentroidSigmaPx);
  std::normal_distribution<double> disparity(0.0, kDisparitySigmaPx);
  const Eigen::Vector2d uv = Project(kCamera, view.centre_cam);
  const double u = uv.x() + centroid(rng), v = uv.y() + centroid(rng);
  const double d = kFB / view.centre_cam.z() + disparity(rng);
  detection::Detection det = testing::MeasuredDetection(kCamera, u, v, d, kDisparitySigmaPx);
  det.bbox = view.box;
  det.area_px = view.box.area();
  det.valid_disparities = det.area_px;
  det.perimeter_px = 2.0 * (view.box.width + view.box.height);
  det.score = 1.0;
  det.extractor = "synthetic";
  return det;
}

double IoU(const cv::Rect& a, const cv::Rect& b) {
  const double inter = (a & b).area();
  const double uni = a.area() + b.area() - inter;
  return uni > 0 ? inter / uni : 0;
}

struct DriveResult {
  int id_switches = 0;  // a car matched to another track id than the last time
  int matched = 0;      // (car, frame) pairs matched to a confirmed or coasting track
  int position_checks = 0;
  int position_failures = 0;
  double worst_error_over_bound = 0;  // the largest world-position error over its bound
  double rms_world_error_m = 0;
  std::map<int, std::vector<std::uint64_t>> ids;  // per car, the track ids in order
  std::vector<int> confirmed;                     // per frame, confirmed or coasting tracks
  std::vector<std::string> failures;
};

// Drives the street. `ego` says at which frames the tracker gets the camera's motion.
DriveResult Drive(const std::function<bool(int)>& ego) {
  const std::vector<Car> cars = Street();
  std::mt19937 rng(20261128);
  Tracker tracker;
  DriveResult out;
  std::map<int, std::uint64_t> last_id;
  double sum_error2 = 0;
  for (int k = 0; k < kFrames; ++k) {
    std::vector<detection::Detection> detections;
    std::vector<View> views;
    for (const Car& car : cars) {
      views.push_back(See(car, k));
      if (Detectable(views.back())) detections.push_back(Detect(views.back(), rng));
    }
    std::optional<EgoMotion> motion;
    if (k > 0 && ego(k)) motion = EgoMotionAt(k);
    const std::vector<Track> tracks = tracker.Update(detections, k * kFrameNs, kCamera, motion);
    out.confirmed.push_back(
        static_cast<int>(std::count_if(tracks.begin(), tracks.end(), [](const Track& t) {
          return t.state != TrackState::kTentative;
        })));
    // Match the confirmed and coasting tracks to the cars in the image, IoU >= 0.3, best first.
    std::vector<std::tuple<double, int, int>> pairs;
    for (size_t c = 0; c < cars.size(); ++c) {
      if (!views[c].in_front || (views[c].box & kImage).area() == 0) continue;
      for (size_t t = 0; t < tracks.size(); ++t) {
        if (tracks[t].state == TrackState::kTentative) continue;
        const double iou = IoU(tracks[t].detection.bbox, views[c].box & kImage);
        if (iou >= 0.3) pairs.emplace_back(iou, static_cast<int>(c), static_cast<int>(t));
      }
    }
    std::sort(pairs.rbegin(), pairs.rend());
    std::vector<char> car_used(cars.size(), 0), track_used(tracks.size(), 0);
    for (const auto& [iou, c, t] : pairs) {
      if (car_used[c] || track_used[t]) continue;
      car_used[c] = track_used[t] = 1;
      const Track& track = tracks[t];
      const Car& car = cars[c];
      ++out.matched;
      if (last_id.count(car.id) && last_id[car.id] != track.id) ++out.id_switches;
      if (!last_id.count(car.id) || last_id[car.id] != track.id)
        out.ids[car.id].push_back(track.id);
      last_id[car.id] = track.id;
      // The track's world position against the car's centre.
      const Eigen::Vector3d p(track.position_cam_m[0], track.position_cam_m[1],
                              track.position_cam_m[2]);
      const double error = (WorldFromCam(k) * p - car.centre).norm();
      const double range = views[c].centre_cam.norm();
      const double bound = std::max(0.05 * range, 3 * cv::norm(track.position_sigma_m));
      ++out.position_checks;
      sum_error2 += error * error;
      out.worst_error_over_bound = std::max(out.worst_error_over_bound, error / bound);
      if (error > bound) {
        ++out.position_failures;
        char line[160];
        std::snprintf(line, sizeof line, "frame %d car %d track %llu (%s): %.2f m off at %.1f m", k,
                      car.id, static_cast<unsigned long long>(track.id),
                      std::string(TrackStateName(track.state)).c_str(), error, range);
        out.failures.push_back(line);
      }
    }
  }
  out.rms_world_error_m = out.position_checks ? std::sqrt(sum_error2 / out.position_checks) : 0;
  return out;
}

std::string Summary(const DriveResult& r) {
  char line[200];
  std::snprintf(line, sizeof line,
                "%d ID switches, %d matched, world position %d of %d beyond bound (worst %.2f of "
                "the bound), RMS %.3f m",
                r.id_switches, r.matched, r.position_failures, r.position_checks,
                r.worst_error_over_bound, r.rms_world_error_m);
  std::string s = line;
  for (const auto& [car, ids] : r.ids) {
    s += "\n  car " + std::to_string(car) + ":";
    for (std::uint64_t id : ids) s += " " + std::to_string(id);
  }
  for (size_t i = 0; i < r.failures.size() && i < 10; ++i) s += "\n  " + r.failures[i];
  return s;
}

TEST(EgoMotion, TheStreetIsTheOneTheTestMeans) {
  // The path: 1 m a frame everywhere, and a right turn of 90 degrees.
  for (int k = 1; k < kFrames; ++k) {
    EXPECT_NEAR((WorldFromCam(k).translation() - WorldFromCam(k - 1).translation()).norm(), 1.0,
                0.01)
        << k;
  }
  EXPECT_NEAR((WorldFromCam(kFrames - 1).linear() * Eigen::Vector3d::UnitZ()).x(), 1.0, 1e-12);
  // Every car is detected for at least 5 frames, and none is hidden behind another.
  for (const Car& car : Street()) {
    int seen = 0;
    for (int k = 0; k < kFrames; ++k) seen += Detectable(See(car, k)) ? 1 : 0;
    EXPECT_GE(seen, 4) << "car " << car.id;
  }
  for (int k = 0; k < kFrames; ++k) {
    std::vector<cv::Rect> boxes;
    for (const Car& car : Street()) {
      const View view = See(car, k);
      if (Detectable(view)) boxes.push_back(view.box);
    }
    for (size_t i = 0; i < boxes.size(); ++i) {
      for (size_t j = i + 1; j < boxes.size(); ++j) {
        EXPECT_TRUE((boxes[i] & boxes[j]).empty()) << "frame " << k;
      }
    }
  }
}

// The done-when: with the camera's motion every car keeps one id through the drive and the turn,
// and every confirmed or coasting track's world position (pose x position_cam_m) stays within
// max(5 % of the range, 3 sigma) of the car's centre. Without it the turn costs ids (measured: see
// the printed summary), so the compensation is what keeps them.
TEST(EgoMotion, ParkedCarsKeepTheirIdsAndWorldPositionsThroughATurn) {
  const DriveResult with = Drive([](int) { return true; });
  std::printf("with ego-motion: %s\n", Summary(with).c_str());
  EXPECT_EQ(with.id_switches, 0) << Summary(with);
  EXPECT_EQ(with.position_failures, 0) << Summary(with);
  for (const Car& car : Street()) {
    ASSERT_TRUE(with.ids.count(car.id)) << "car " << car.id << " never tracked";
    EXPECT_EQ(with.ids.at(car.id).size(), 1u) << "car " << car.id << ": " << Summary(with);
  }

  const DriveResult without = Drive([](int) { return false; });
  std::printf("without ego-motion: %s\n", Summary(without).c_str());
  // The turn breaks the constant-velocity prediction: ids switch or tracks are lost and started
  // again, and the world positions drift.
  int without_ids = 0, with_ids = 0;
  for (const auto& [car, ids] : without.ids) without_ids += static_cast<int>(ids.size());
  for (const auto& [car, ids] : with.ids) with_ids += static_cast<int>(ids.size());
  EXPECT_GT(without_ids, with_ids) << Summary(without);
  EXPECT_GT(without.position_failures, 0) << Summary(without);
}

// A pose dropout: two frames on the first street and two late in the turn without the camera's
// motion. The tracker converts the velocities back to relative for them with the camera's last
// motion (on the straight they then predict as well as with ego-motion; in the turn a constant
// relative velocity is a straight line where a static point moves on an arc) and forward again at
// the next ego-motion.
TEST(EgoMotion, APoseDropoutKeepsEveryId) {
  const std::vector<int> dropped = {10, 11, kStraight + 11, kStraight + 12};
  const DriveResult r =
      Drive([&](int k) { return std::count(dropped.begin(), dropped.end(), k) == 0; });
  std::printf("dropout at frames 10, 11, %d, %d: %s\n", dropped[2], dropped[3], Summary(r).c_str());
  for (int k : dropped) EXPECT_GT(r.confirmed[k], 0) << "frame " << k << " has no track to carry";
  EXPECT_EQ(r.id_switches, 0) << Summary(r);
  // Held through the turn, the relative velocity is that of the last motion, but constant: the
  // filters pick up a velocity error there, which a track that coasts afterwards carries (measured:
  // 3 coasting frames of one car beyond the bound, at most 2.2 times it; none without the dropout).
  EXPECT_LE(r.worst_error_over_bound, 3.0) << Summary(r);
  for (const auto& [car, ids] : r.ids) EXPECT_EQ(ids.size(), 1u) << "car " << car;
}

// The published velocity stays relative to the camera: a parked car on the straight approaches at
// the rig's 10 m/s, and the range rate and time to collision follow.
TEST(EgoMotion, PublishedVelocityIsRelativeToTheCamera) {
  const std::vector<Car> cars = Street();
  const Car& ahead = cars[3];  // 58 m ahead, 2 m to the left
  std::mt19937 rng(7);
  Tracker tracker;
  std::vector<Track> tracks;
  for (int k = 0; k < 20; ++k) {
    std::optional<EgoMotion> motion;
    if (k > 0) motion = EgoMotionAt(k);
    const View view = See(ahead, k);
    ASSERT_TRUE(Detectable(view)) << k;
    tracks = tracker.Update({Detect(view, rng)}, k * kFrameNs, kCamera, motion);
  }
  ASSERT_EQ(tracks.size(), 1u);
  const Track& t = tracks[0];
  const cv::Vec3d truth(0, 0, -10);  // the car seen from the rig driving north at 10 m/s
  for (int axis = 0; axis < 3; ++axis) {
    EXPECT_NEAR(t.velocity_cam_mps[axis], truth[axis], 3 * t.velocity_sigma_mps[axis] + 0.05)
        << "axis " << axis;
  }
  const Eigen::Vector3d p = See(ahead, 19).centre_cam;
  EXPECT_NEAR(t.range_rate_mps, -10 * p.z() / p.norm(), 3 * t.range_rate_sigma_mps + 0.05);
  ASSERT_TRUE(t.time_to_collision_s.has_value());
  // Straight line: closest approach when the rig passes the car, z / 10 s from now, 2.0 m to its
  // centre line (x -2, y 0.75).
  EXPECT_NEAR(*t.time_to_collision_s, p.z() / 10, 0.1 * p.z() / 10);
  EXPECT_NEAR(*t.closest_approach_m, std::hypot(2.0, 0.75), 0.5);
}

// MapAngleDepth moves the mean exactly and leaves an identity alone.
TEST(EgoMotion, MapAngleDepthMovesTheStateThroughARigidMotion) {
  ConstantVelocityKalman kalman;
  const Eigen::Vector3d p(3, -1, 20);
  kalman.Initialize(Eigen::Vector3d(p.x() / p.z(), p.y() / p.z(), p.z()),
                    Eigen::Vector3d(1e-6, 1e-6, 0.04).asDiagonal(), 2.0);
  const ConstantVelocityKalman before = kalman;
  kalman.MapAngleDepth(Eigen::Matrix<double, 6, 6>::Identity(),
                       Eigen::Matrix<double, 6, 1>::Zero());
  EXPECT_LT((kalman.state() - before.state()).norm(), 1e-12);
  EXPECT_LT((kalman.covariance() - before.covariance()).norm(), 1e-9);

  const Eigen::Isometry3d motion = EgoMotionAt(kStraight + 3).cam_now_from_cam_prev;
  Eigen::Matrix<double, 6, 6> linear = Eigen::Matrix<double, 6, 6>::Zero();
  linear.topLeftCorner<3, 3>() = motion.linear();
  linear.bottomRightCorner<3, 3>() = motion.linear();
  Eigen::Matrix<double, 6, 1> offset = Eigen::Matrix<double, 6, 1>::Zero();
  offset.head<3>() = motion.translation();
  kalman.MapAngleDepth(linear, offset);
  const Eigen::Vector3d moved = motion * p;
  EXPECT_LT((PointFromAngleDepth(kalman.position()) - moved).norm(), 1e-9);
  // The point's covariance in the cam frame is the rotated one: R C R^T.
  const auto point_covariance = [](const ConstantVelocityKalman& k) {
    const Eigen::Vector3d s = k.position();
    Eigen::Matrix3d J;
    J << s.z(), 0, s.x(), 0, s.z(), s.y(), 0, 0, 1;
    return Eigen::Matrix3d(J * k.covariance().topLeftCorner<3, 3>() * J.transpose());
  };
  const Eigen::Matrix3d expected =
      motion.linear() * point_covariance(before) * motion.linear().transpose();
  EXPECT_LT((point_covariance(kalman) - expected).norm(), 1e-5 * expected.norm());
}

}  // namespace
}  // namespace stevi::tracking
