// The scenarios for evaluating the tracker (TrackingScenarios() in synthetic_source.h). All use the
// default rig (640x480, f = 700 px, B = 0.6 m, principal point (320, 240), 10 fps): a point
// (x, y, z) shows at u = 320 + 700 x / z, v = 240 + 700 y / z, with disparity 420 / z px. The
// camera is 100 m above the ground, as in clear_sky, so that every obstacle is against the sky and
// detection stays clean: these scenes test the tracker, not the detectors. Every obstacle's front
// face is at 52 m or nearer (>= 8 px of disparity) while it is in view. Paths never wrap within
// the scenario (each Leg's period is the scenario's length or longer).
#include <string>
#include <utility>

#include "drivers/synthetic/scene_helpers.h"
#include "drivers/synthetic/synthetic_source.h"

namespace stevi::drivers {
namespace {

// A path from `start` (box centre, metres) at `velocity_mps` that does not wrap within the
// scenarios (they last at most 10 s).
Path Straight(cv::Vec3d start, cv::Vec3d velocity_mps) {
  Path p;
  p.kind = Path::Kind::kLinear;
  p.start = start;
  p.velocity_mps = velocity_mps;
  p.period_s = 0.0;  // never wraps
  return p;
}

// Camera 100 m above the ground (290 m and farther, < 1.5 px of disparity, below the horizon).
Scene SkyScene() {
  Scene scene;
  scene.camera_height_m = 100.0;
  return scene;
}

Scenario CrossingOcclusion() {
  Scene scene = SkyScene();
  const double length_s = 9.0;
  // aircraft-a: front face at 30 m (14 px), rows 61..104 (with its underside), left to right.
  scene.obstacles.push_back(MakeObstacle(1, "aircraft-a", {5.0, 1.5, 2.0},
                                         Leg({-9.0, -6.95, 31.0}, {9.0, -6.95, 31.0}, length_s),
                                         0.3, 0.45, 0.15));
  // aircraft-b: front face at 48 m (8.75 px; 8.4 px at its back), rows 68..102, right to left.
  scene.obstacles.push_back(MakeObstacle(2, "aircraft-b", {6.0, 2.0, 2.0},
                                         Leg({6.0, -10.83, 49.0}, {-12.0, -10.83, 49.0}, length_s),
                                         0.35, 0.4, 0.2));
  // cargo-drone: hovering, front face at 25 m (16.8 px), columns 276..364, rows 143..227.
  scene.obstacles.push_back(
      MakeObstacle(3, "cargo-drone", {3.2, 3.0, 2.0}, Fixed({0.0, -2.0, 26.0}), 0.4, 0.4, 0.15));
  // drone-c: front face at 45 m (9.3 px), rows 179..193, left to right at 3.9 m/s behind the
  // cargo drone: fully hidden for 10 frames (42..51).
  scene.obstacles.push_back(MakeObstacle(4, "drone-c", {2.0, 0.8, 2.0},
                                         Straight({-18.0, -3.54, 46.0}, {3.9, 0.0, 0.0}), 0.25,
                                         0.45, 0.12));
  return MakeScenario(
      "crossing_occlusion", 201, std::move(scene), 90,
      "Camera 100 m above flat ground, every obstacle against the sky. A crossing: aircraft-a "
      "(5 x 1.5 x 2 m, front face at 30 m, 14 px of disparity, ~120 x 44 px, rows 61..104) flies "
      "left to right at 2 m/s (u 52..584) and aircraft-b (6 x 2 x 2 m, front at 48 m, 8.75 px, "
      "~90 x 35 px, rows 68..102) right to left at 2 m/s (u 452..105); aircraft-a starts to cover "
      "aircraft-b at frame 26, hides it completely at frames 38..41, and uncovers it by frame 53 "
      "(depth ratio 1.6). An occlusion: cargo-drone (3.2 x 3 x 2 m) hovers at 25 m (16.8 px, "
      "columns 276..364, rows 143..227) and drone-c (2 x 0.8 x 2 m, front at 45 m, 9.3 px, ~34 x "
      "15 px, rows 179..193) flies left to right at 3.9 m/s (6.1 px per frame, u 25..596) behind "
      "it: partly hidden at frames 37..41, fully hidden at 42..51 (10 frames), partly hidden at "
      "52..56, then in the clear again. 9 s, 90 frames. Hard: tracks must coast through both "
      "occlusions and keep their ids, and the crossing obstacles must not swap ids; the partly "
      "hidden frames move the visible centroid differently from the obstacle.");
}

Scenario EntriesExits() {
  Scene scene = SkyScene();
  // Each row band holds one obstacle, so that their boxes never overlap.
  // aircraft-1: front at 32 m (13.1 px), rows 49..91, enters from the left at frame 4 and leaves
  // on the right at frames 65..75.
  scene.obstacles.push_back(MakeObstacle(1, "aircraft-1", {5.0, 1.5, 2.0},
                                         Straight({-20.0, -8.0, 33.0}, {5.0, 0.0, 0.0}), 0.3, 0.45,
                                         0.15));
  // drone-1: front at 22 m (19 px), rows 110..136, in view at the start, leaves on the left at
  // frames 21..28.
  scene.obstacles.push_back(MakeObstacle(2, "drone-1", {1.5, 0.6, 1.5},
                                         Straight({-3.0, -3.8, 22.75}, {-3.0, 0.0, 0.0}), 0.28,
                                         0.45, 0.12));
  // aircraft-2: front at 44 m (9.5 px), rows 145..179, enters from the right at frame 9 and
  // leaves on the left at frames 68..77.
  scene.obstacles.push_back(MakeObstacle(3, "aircraft-2", {6.0, 2.0, 2.0},
                                         Straight({30.0, -5.0, 45.0}, {-7.0, 0.0, 0.0}), 0.35, 0.4,
                                         0.2));
  // drone-2: front at 28 m (15 px), rows 198..214, enters from the left at frame 43.
  scene.obstacles.push_back(MakeObstacle(4, "drone-2", {1.5, 0.6, 1.5},
                                         Straight({-27.0, -1.4, 28.75}, {3.0, 0.0, 0.0}), 0.28,
                                         0.45, 0.12));
  // drone-3: front at 38 m (11 px), rows 104..125, enters from the right at frame 56.
  scene.obstacles.push_back(MakeObstacle(5, "drone-3", {2.0, 0.8, 2.0},
                                         Straight({38.7, -7.0, 39.0}, {-3.5, 0.0, 0.0}), 0.25, 0.45,
                                         0.12));
  return MakeScenario(
      "entries_exits", 202, std::move(scene), 90,
      "Camera 100 m above flat ground, every obstacle against the sky, each in its own band of "
      "rows (no two boxes ever overlap). Four entries and three exits at the image sides: "
      "aircraft-1 (5 x 1.5 x 2 m, front at 32 m, 13.1 px, ~115 x 42 px) flies left to right at "
      "5 m/s (11 px per frame), entering at frame 4 and leaving at 65..75; drone-1 (1.5 x 0.6 x "
      "1.5 m, 22 m, 19 px, ~60 x 26 px) is in view at the start and leaves on the left at "
      "21..28; aircraft-2 (6 x 2 x 2 m, 44 m, 9.5 px, ~100 x 35 px) flies right to left at "
      "7 m/s, entering at 9 and leaving at 68..77; drone-2 (1.5 x 0.6 x 1.5 m, 28 m, 15 px, ~48 x "
      "16 px) enters from the left at 43 and drone-3 (2 x 0.8 x 2 m, 38 m, 11 px, ~48 x 21 px) "
      "from the right at 56, both in view at the end. 9 s, 90 frames. Hard: obstacles cut by "
      "the image border (their centroids lag), and tracks that must end with their obstacle and "
      "never come back under an old id.");
}

// The sky scene of head_on and departing: one drone (2 x 1 x 2 m) flying in 6 s between its far
// point (front face at 50 m, 8.4 px) and its near point (12.6 m, 33 px), at 6.33 m/s, with a
// lateral drift of 0.17 m/s and 0.13 m/s; the straight line misses the camera by 2.4 m.
Scene HeadOnScene(std::string name, bool approaching) {
  const cv::Vec3d far(3.5, -2.0, 51.0);
  const cv::Vec3d near(2.5, -1.2, 13.0);
  const double length_s = 6.0;
  Scene scene = SkyScene();
  scene.obstacles.push_back(MakeObstacle(
      1, std::move(name), {2.0, 1.0, 2.0},
      approaching ? Leg(far, near, length_s) : Leg(near, far, length_s), 0.25, 0.45, 0.12));
  return scene;
}

Scenario HeadOn() {
  // Closing: left and down.
  Scene scene = HeadOnScene("drone-head-on", true);
  return MakeScenario(
      "head_on", 203, std::move(scene), 60,
      "Camera 100 m above flat ground, the obstacle against the sky. drone-head-on (2 x 1 x 2 m) "
      "flies nearly straight at the camera: its front face from 50 m (8.4 px of disparity, "
      "30 x 15 px at u 354..383, v 205..219) to 12.6 m at frame 59 (33 px, 122 x 60 px), "
      "closing at 6.33 m/s with a lateral drift of (-0.17, +0.13) m/s: the straight line passes "
      "the camera at 2.4 m (the closest approach, 7.9 s after frame 0). 6 s, 60 frames. Hard: "
      "range noise that grows with the range squared (0.1 px of disparity is 0.6 m at 50 m), a "
      "box that grows 4 times, and time to collision from a depth velocity.");
}

Scenario Departing() {
  // head_on played backwards: from 12.6 m out to 50 m.
  Scene scene = HeadOnScene("drone-departing", false);
  return MakeScenario(
      "departing", 204, std::move(scene), 60,
      "head_on backwards: drone-departing (2 x 1 x 2 m) flies straight away from the camera, its "
      "front face from 12.6 m (33 px of disparity) to 50 m (8.4 px) in 6 s, receding at 6.33 m/s: "
      "a diverging obstacle, for the autopilot consumer to stay CLEAR on. 60 frames.");
}

// Camera 12 m above the ground, as on the user's airfield: the ground fills the image below the
// horizon (row 240); the obstacles fly above it, against the sky.
Scene AirfieldScene() {
  Scene scene;
  scene.camera_height_m = 12.0;
  return scene;
}

Scenario Crossing() {
  Scene scene = AirfieldScene();
  const double length_s = 8.0;
  // aircraft-near: 10 x 2 x 3 m, front face at 40 m (10.5 px of disparity), ~175 x 35 px, rows
  // 170..205, its front-face centre from u 100 to 540 (3.14 m/s, 5.5 px per frame).
  scene.obstacles.push_back(MakeObstacle(1, "aircraft-near", {10.0, 2.0, 3.0},
                                         Straight({-12.571, -3.0, 41.5}, {3.1429, 0.0, 0.0}), 0.3,
                                         0.45, 0.2));
  // aircraft-far: 10 x 2 x 3 m, front face at 50 m (8.4 px; the scoring floor is 8 px, 52.5 m),
  // ~140 x 28 px, rows 176..204, from u 540 to 100 (3.93 m/s).
  scene.obstacles.push_back(MakeObstacle(2, "aircraft-far", {10.0, 2.0, 3.0},
                                         Straight({15.714, -3.6, 51.5}, {-3.9286, 0.0, 0.0}), 0.6,
                                         0.4, 0.25));
  return MakeScenario(
      "crossing", 205, std::move(scene), static_cast<int>(length_s * 10),
      "Camera 12 m above the ground (ground below the horizon). Two aircraft-like boxes (10 x 2 x "
      "3 m) cross in the image on nearly the same rows: aircraft-near (front face at 40 m, "
      "10.5 px of disparity, ~175 x 35 px) flies left to right (u 100 -> 540) and aircraft-far "
      "(50 m, 8.4 px, ~140 x 28 px) right to left (u 540 -> 100); they cross at frame 40, their "
      "boxes overlap for ~28 frames (the far one cut by the near one) and the far one is wholly "
      "covered for ~3. Depth ratio 1.25: inside the old fixed depth gate (1.3), so only the "
      "depths' own uncertainties tell the two apart. 8 s, 80 frames. Hard: the far blob falls "
      "into pieces while cut, some pieces take the near one's disparity, and the two must keep "
      "their ids.");
}

Scenario Occlusion() {
  Scene scene = AirfieldScene();
  // billboard: 5 x 4 x 0.5 m, floating, front face at 25 m (16.8 px), columns 250..390, rows
  // 142..254 (its bottom below the horizon, against distant ground).
  scene.obstacles.push_back(
      MakeObstacle(1, "billboard", {5.0, 4.0, 0.5}, Fixed({0.0, -1.5, 25.25}), 0.55, 0.45, 0.3));
  // aircraft-c: 6 x 1.2 x 2 m, front face at 45 m (9.3 px), ~93 x 19 px, rows 200..218, left to
  // right at 7.71 m/s (12 px per frame) from u 60: behind the billboard's columns from frame 12
  // (its right edge) to frame 36 (its left edge); wholly hidden at frames 20..23.
  scene.obstacles.push_back(MakeObstacle(2, "aircraft-c", {6.0, 1.2, 2.0},
                                         Straight({-16.714, -1.8, 46.0}, {7.7143, 0.0, 0.0}), 0.3,
                                         0.45, 0.15));
  return MakeScenario(
      "occlusion", 206, std::move(scene), 45,
      "Camera 12 m above the ground. A billboard (5 x 4 x 0.5 m, front face at 25 m, 16.8 px, "
      "columns 250..390, rows 142..254) floats in front of the horizon; aircraft-c (6 x 1.2 x 2 m, "
      "front at 45 m, 9.3 px, ~93 x 19 px, rows 200..218) flies left to right behind it at "
      "12 px per frame: partly hidden at frames 12..19 (its box shrinks from the right), wholly "
      "hidden at 20..23, partly hidden at 24..35 (growing from the left), then in the clear. "
      "4.5 s, 45 frames. Hard: the track must coast through the occlusion and take the "
      "re-emerging aircraft back under its old id while its box is a sliver of the full size.");
}

}  // namespace

std::vector<Scenario> TrackingScenarios() {
  return {CrossingOcclusion(), EntriesExits(), HeadOn(), Departing(), Crossing(), Occlusion()};
}

}  // namespace stevi::drivers
