// Pipeline::Finish with a pose source: the vehicle's poses give the tracker the camera's motion
// between frames. A car drives north at 10 m/s past parked cars, turns right by 90 degrees and
// drives east (10 fps). The detections are the parked cars' boxes projected through the known path
// (written out here with explicit rotation matrices, independently of core/geo); the poses are
// the path in WGS84. Each car keeps one id, and its georeferenced position stays at the car.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <map>
#include <memory>
#include <numbers>
#include <optional>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include <GeographicLib/LocalCartesian.hpp>
#include <gtest/gtest.h>

#include "core/pipeline/pipeline.h"

namespace stevi::pipeline {
namespace {

constexpr double kF = 700, kCx = 320, kCy = 240, kBaseline = 0.6;
constexpr int64_t kFrameNs = 100'000'000;                    // 10 fps
constexpr int64_t kUnixStartNs = 1'790'000'000'000'000'000;  // some Unix time in 2026
constexpr double kPi = std::numbers::pi;
constexpr int kStraight = 25, kTurn = 15, kFrames = 75;
constexpr double kTurnRate = kPi / 2 / kTurn;  // radians a frame: 1 m of arc a frame
constexpr double kRadius = 1.0 / kTurnRate;
// The origin of the local NED frame: Pisa, 50 m above the ellipsoid.
constexpr double kLat = 43.7167, kLon = 10.3833, kAlt = 50;

// The vehicle at frame k: NED position of its reference point (the camera, no lever arm) and its
// heading (radians, clockwise from north).
struct Pose {
  Eigen::Vector3d ned;
  double heading = 0;
};

Pose PoseAt(int k) {
  if (k <= kStraight) return {{static_cast<double>(k), 0, 0}, 0};
  if (k <= kStraight + kTurn) {
    const double h = (k - kStraight) * kTurnRate;
    return {{kStraight + kRadius * std::sin(h), kRadius * (1 - std::cos(h)), 0}, h};
  }
  return {{kStraight + kRadius, kRadius + (k - kStraight - kTurn), 0}, kPi / 2};
}

// ned_from_cam of a level vehicle with heading h and the camera looking forward: the columns are
// the cam axes in NED (x right, y down, z forward).
Eigen::Matrix3d NedFromCam(double h) {
  Eigen::Matrix3d m;
  m.col(0) = Eigen::Vector3d(-std::sin(h), std::cos(h), 0);
  m.col(1) = Eigen::Vector3d(0, 0, 1);
  m.col(2) = Eigen::Vector3d(std::cos(h), std::sin(h), 0);
  return m;
}

Eigen::Vector3d CamOf(const Eigen::Vector3d& ned, int k) {
  const Pose pose = PoseAt(k);
  return NedFromCam(pose.heading).transpose() * (ned - pose.ned);
}

struct Car {
  int id;
  Eigen::Vector3d ned;   // centre
  Eigen::Vector3d size;  // along north, east, down
};

std::vector<Car> Cars() {
  const double d = 0.75;  // centres 0.75 m below the camera
  const Eigen::Vector3d along_n(4.5, 1.8, 1.5), along_e(1.8, 4.5, 1.5);
  const double second = kStraight + kRadius;
  return {{1, {16, -4, d}, along_n},         {2, {20, 4, d}, along_n},
          {3, {36, -4, d}, along_n},         {4, {58, -2, d}, along_n},
          {5, {second + 4, 20, d}, along_e}, {6, {second - 4, 30, d}, along_e},
          {7, {second + 4, 40, d}, along_e}, {8, {second - 4, 50, d}, along_e}};
}

// The car's projected box at frame k, when all of it is in the image within 60 m.
std::optional<cv::Rect> BoxOf(const Car& car, int k) {
  double u0 = 1e9, v0 = 1e9, u1 = -1e9, v1 = -1e9;
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3d offset(c & 1 ? 0.5 : -0.5, c & 2 ? 0.5 : -0.5, c & 4 ? 0.5 : -0.5);
    const Eigen::Vector3d p = CamOf(car.ned + offset.cwiseProduct(car.size), k);
    if (p.z() < 1) return std::nullopt;
    u0 = std::min(u0, kCx + kF * p.x() / p.z()), u1 = std::max(u1, kCx + kF * p.x() / p.z());
    v0 = std::min(v0, kCy + kF * p.y() / p.z()), v1 = std::max(v1, kCy + kF * p.y() / p.z());
  }
  const cv::Rect box(
      cv::Point(static_cast<int>(std::lround(u0)), static_cast<int>(std::lround(v0))),
      cv::Point(static_cast<int>(std::lround(u1)), static_cast<int>(std::lround(v1))));
  if ((box & cv::Rect(0, 0, 640, 480)) != box || CamOf(car.ned, k).z() > 60) return std::nullopt;
  return box;
}

detection::Detection Detect(const Car& car, const cv::Rect& box, int k, std::mt19937& rng) {
  std::normal_distribution<double> centroid(0.0, 0.3), disparity(0.0, 0.25);
  const Eigen::Vector3d p = CamOf(car.ned, k);
  const double u = kCx + kF * p.x() / p.z() + centroid(rng);
  const double v = kCy + kF * p.y() / p.z() + centroid(rng);
  const double d = kF * kBaseline / p.z() + disparity(rng);
  const double z = kF * kBaseline / d;
  detection::Detection det;
  det.centroid_px = cv::Point2d(u, v);
  det.disparity_px = d;
  det.depth_m = z;
  det.position_cam_m = cv::Vec3d((u - kCx) * z / kF, (v - kCy) * z / kF, z);
  det.range_m = cv::norm(det.position_cam_m);
  det.range_sigma_m = z * z / (kF * kBaseline) * 0.25 * det.range_m / z;
  det.bbox = box;
  det.area_px = box.area();
  det.valid_disparities = det.area_px;
  det.perimeter_px = 2.0 * (box.width + box.height);
  det.score = 1;
  det.extractor = "synthetic";
  return det;
}

struct DriveRun {
  int id_switches = 0;
  int ids = 0;                    // distinct track ids matched to the cars
  std::map<int, int> ids_of_car;  // how many track ids each car was matched to
  int geo_checks = 0;
  int geo_failures = 0;
  double worst_over_bound = 0;
};

// Finish() over the drive; `pose_ok(k)` says whether the pose source finds frame k's pose (no
// pose source at all when it is empty).
DriveRun Drive(const std::function<bool(int)>& pose_ok) {
  const auto rig = std::make_shared<const geometry::StereoRig>(
      geometry::StereoRig::Ideal(cv::Size(640, 480), kF, kBaseline, kCx, kCy));
  Snapshot snapshot{.config = std::make_shared<const PipelineConfig>(), .rig = rig};
  const GeographicLib::LocalCartesian enu(kLat, kLon, kAlt);
  if (pose_ok) {
    snapshot.pose_at = [&enu, pose_ok](int64_t t_ns, int64_t unix_ns) {
      const int k = static_cast<int>(t_ns / kFrameNs);
      EXPECT_EQ(unix_ns, kUnixStartNs + t_ns);
      geo::PoseLookup lookup;
      if (!pose_ok(k)) return lookup;  // kNoPose
      const Pose pose = PoseAt(k);
      geo::VehiclePose vehicle;
      vehicle.state.t_ns = unix_ns;
      enu.Reverse(pose.ned.y(), pose.ned.x(), -pose.ned.z(), vehicle.state.lat_deg,
                  vehicle.state.lon_deg, vehicle.state.alt_m);
      vehicle.state.yaw_deg = pose.heading * 180 / kPi;
      lookup.status = geo::GeoStatus::kOk;
      lookup.message = "ok";
      lookup.pose = vehicle;
      return lookup;
    };
  }
  Pipeline pipeline;
  std::mt19937 rng(1128);
  DriveRun run;
  std::map<int, std::uint64_t> last;
  std::map<std::uint64_t, int> seen_ids;
  const std::vector<Car> cars = Cars();
  for (int k = 0; k < kFrames; ++k) {
    PreparedFrame prepared;
    prepared.result.capture_time_ns = k * kFrameNs;
    prepared.result.capture_unix_time_ns = kUnixStartNs + k * kFrameNs;
    prepared.result.rig = rig;
    std::vector<std::optional<cv::Rect>> boxes;
    for (const Car& car : cars) {
      boxes.push_back(BoxOf(car, k));
      if (boxes.back()) prepared.result.detections.push_back(Detect(car, *boxes.back(), k, rng));
    }
    Result<FrameResult> result = pipeline.Finish(std::move(prepared), snapshot);
    EXPECT_TRUE(result.ok()) << result.error().message;
    if (!result.ok()) return run;
    const FrameResult& r = *result;
    // Each detected car's track: the confirmed or coasting track on its box (IoU >= 0.3).
    for (size_t c = 0; c < cars.size(); ++c) {
      if (!boxes[c]) continue;
      for (size_t t = 0; t < r.tracks.size(); ++t) {
        const tracking::Track& track = r.tracks[t];
        const double inter = (track.detection.bbox & *boxes[c]).area();
        const double iou = inter / (track.detection.bbox.area() + boxes[c]->area() - inter);
        if (track.state == tracking::TrackState::kTentative || iou < 0.3) continue;
        const int id = cars[c].id;
        if (last.count(id) && last[id] != track.id) ++run.id_switches;
        last[id] = track.id;
        seen_ids[track.id] = id;
        if (!pose_ok || !r.track_geo[t]) break;
        // The georeferenced position against the car's centre, in the local NED frame.
        double east = 0, north = 0, up = 0;
        enu.Forward(r.track_geo[t]->lat_deg, r.track_geo[t]->lon_deg, r.track_geo[t]->alt_m, east,
                    north, up);
        const double error = (Eigen::Vector3d(north, east, -up) - cars[c].ned).norm();
        const double range = CamOf(cars[c].ned, k).norm();
        const double sigma = std::sqrt(r.track_geo[t]->sigma.covariance_ned_m2.trace());
        const double bound = std::max(0.05 * range, 3 * sigma);
        ++run.geo_checks;
        run.geo_failures += error > bound ? 1 : 0;
        run.worst_over_bound = std::max(run.worst_over_bound, error / bound);
        break;
      }
    }
  }
  run.ids = static_cast<int>(seen_ids.size());
  for (const auto& [id, car] : seen_ids) ++run.ids_of_car[car];
  return run;
}

std::string Describe(const DriveRun& r) {
  char line[160];
  std::snprintf(line, sizeof line,
                "%d ID switches, %d track ids for 8 cars, georeferenced %d of %d beyond the bound "
                "(worst %.2f of it)",
                r.id_switches, r.ids, r.geo_failures, r.geo_checks, r.worst_over_bound);
  std::string s = line;
  for (const auto& [car, n] : r.ids_of_car)
    s += "; car " + std::to_string(car) + ": " + std::to_string(n);
  return s;
}

TEST(PipelineEgoMotion, ParkedCarsKeepTheirIdsAndGeoPositionsThroughATurn) {
  const DriveRun with = Drive([](int) { return true; });
  std::printf("with poses: %s\n", Describe(with).c_str());
  EXPECT_EQ(with.id_switches, 0) << Describe(with);
  EXPECT_EQ(with.ids, 8) << Describe(with);
  EXPECT_GT(with.geo_checks, 100) << Describe(with);
  EXPECT_EQ(with.geo_failures, 0) << Describe(with);

  // Without a pose source the tracker sees no ego-motion: the turn costs ids.
  const DriveRun without = Drive({});
  std::printf("without poses: %s\n", Describe(without).c_str());
  EXPECT_GT(without.ids, with.ids) << Describe(without);
}

// A pose missing for two frames on the straight: the tracker gets no ego-motion for them and the
// next (no previous pose), and keeps every id.
TEST(PipelineEgoMotion, APoseGapKeepsEveryId) {
  const DriveRun run = Drive([](int k) { return k != 8 && k != 9; });
  std::printf("pose gap at frames 8, 9: %s\n", Describe(run).c_str());
  EXPECT_EQ(run.id_switches, 0) << Describe(run);
  EXPECT_EQ(run.ids, 8) << Describe(run);
}

}  // namespace
}  // namespace stevi::pipeline
