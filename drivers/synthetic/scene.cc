#include "drivers/synthetic/scene.h"

#include <cmath>
#include <limits>
#include <map>
#include <utility>

#include "drivers/synthetic/scene_helpers.h"
#include "drivers/synthetic/synthetic_source.h"

namespace stevi::drivers {
namespace {

constexpr double kPi = 3.14159265358979323846;

bool Finite(const cv::Vec3d& v) {
  return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
}

bool InUnit(double x) { return x >= 0.0 && x <= 1.0; }

// Adds "field: problem" when `bad`.
void Check(bool bad, const std::string& field, const std::string& problem,
           std::vector<std::string>& problems) {
  if (bad) problems.push_back(field + ": " + problem);
}

void ValidatePath(const Path& path, const std::string& prefix, std::vector<std::string>& problems) {
  Check(!Finite(path.start), prefix + "start", "must be finite", problems);
  Check(!Finite(path.velocity_mps), prefix + "velocity_mps", "must be finite", problems);
  Check(!(path.period_s >= 0.0) || !std::isfinite(path.period_s), prefix + "period_s",
        "must be >= 0 (0 = never wraps)", problems);
  Check(!(path.radius_m >= 0.0) || !std::isfinite(path.radius_m), prefix + "radius_m",
        "must be >= 0", problems);
  Check(!std::isfinite(path.angular_rate_rad_s), prefix + "angular_rate_rad_s", "must be finite",
        problems);
  Check(!std::isfinite(path.phase_rad), prefix + "phase_rad", "must be finite", problems);
}

}  // namespace

Obstacle MakeObstacle(int id, std::string name, cv::Vec3d size_m, Path path, double albedo,
                      double contrast, double cell_m) {
  Obstacle o;
  o.id = id;
  o.name = std::move(name);
  o.size_m = size_m;
  o.path = path;
  o.albedo = albedo;
  o.contrast = contrast;
  o.texture_cell_m = cell_m;
  return o;
}

Path Fixed(cv::Vec3d centre) {
  Path p;
  p.kind = Path::Kind::kStatic;
  p.start = centre;
  return p;
}

cv::Vec3d Path::PositionAt(double t_s) const {
  switch (kind) {
    case Kind::kStatic: return start;
    case Kind::kLinear: {
      const double t = period_s > 0.0 ? std::fmod(t_s, period_s) : t_s;
      return start + velocity_mps * t;
    }
    case Kind::kCircle: {
      const double angle = phase_rad + angular_rate_rad_s * t_s;
      return {start[0] + radius_m * std::cos(angle), start[1],
              start[2] + radius_m * std::sin(angle)};
    }
  }
  return start;
}

cv::Vec3d Scene::RigOffsetAt(double t_s) const {
  const double t = rig_period_s > 0.0 ? std::fmod(t_s, rig_period_s) : t_s;
  return rig_velocity_mps * t;
}

namespace {

// Scene::Validate's steps: the problems of each list of the scene, appended.
void ValidateObstacles(const std::vector<Obstacle>& obstacles, std::vector<std::string>& problems) {
  std::map<int, size_t> first_with_id;
  for (size_t i = 0; i < obstacles.size(); ++i) {
    const Obstacle& o = obstacles[i];
    const std::string prefix = "obstacles[" + std::to_string(i) + "].";
    Check(o.id <= 0, prefix + "id", "must be > 0 (0 is the ground, -1 the sky)", problems);
    const auto [it, inserted] = first_with_id.emplace(o.id, i);
    Check(!inserted, prefix + "id",
          "duplicate id " + std::to_string(o.id) + " (also obstacles[" +
              std::to_string(it->second) + "])",
          problems);
    if (o.parts.empty()) {
      Check(!(o.size_m[0] > 0.0 && o.size_m[1] > 0.0 && o.size_m[2] > 0.0) || !Finite(o.size_m),
            prefix + "size_m", "every side must be > 0", problems);
    }
    for (size_t k = 0; k < o.parts.size(); ++k) {
      const ObstaclePart& part = o.parts[k];
      const std::string part_prefix = prefix + "parts[" + std::to_string(k) + "].";
      Check(!Finite(part.offset_m), part_prefix + "offset_m", "must be finite", problems);
      Check(!(part.size_m[0] > 0.0 && part.size_m[1] > 0.0 && part.size_m[2] > 0.0) ||
                !Finite(part.size_m),
            part_prefix + "size_m", "every side must be > 0", problems);
    }
    Check(!InUnit(o.albedo), prefix + "albedo", "must be in 0..1", problems);
    Check(!InUnit(o.contrast), prefix + "contrast", "must be in 0..1", problems);
    Check(!(o.texture_cell_m > 0.0) || !std::isfinite(o.texture_cell_m), prefix + "texture_cell_m",
          "must be > 0", problems);
    ValidatePath(o.path, prefix + "path.", problems);
  }
}

void ValidateHills(const std::vector<Hill>& hills, double camera_height_m,
                   std::vector<std::string>& problems) {
  for (size_t i = 0; i < hills.size(); ++i) {
    const Hill& hill = hills[i];
    const std::string prefix = "hills[" + std::to_string(i) + "].";
    const cv::Vec3d& c = hill.centre_m;
    const cv::Vec3d& r = hill.radii_m;
    const bool centre_ok = Finite(c);
    const bool radii_ok = r[0] > 0.0 && r[1] > 0.0 && r[2] > 0.0 && Finite(r);
    Check(!centre_ok, prefix + "centre_m", "must be finite", problems);
    Check(centre_ok && std::isfinite(camera_height_m) && c[1] < camera_height_m,
          prefix + "centre_m", "must be on or below the ground (y >= camera_height_m)", problems);
    Check(!radii_ok, prefix + "radii_m", "every radius must be > 0", problems);
    if (centre_ok && radii_ok) {
      const double inside = (c[0] / r[0]) * (c[0] / r[0]) + (c[1] / r[1]) * (c[1] / r[1]) +
                            (c[2] / r[2]) * (c[2] / r[2]);
      Check(inside <= 1.0, prefix + "centre_m", "the camera (0, 0, 0) must be outside the hill",
            problems);
    }
    Check(!InUnit(hill.albedo), prefix + "albedo", "must be in 0..1", problems);
    Check(!InUnit(hill.contrast), prefix + "contrast", "must be in 0..1", problems);
    Check(!(hill.texture_cell_m > 0.0) || !std::isfinite(hill.texture_cell_m),
          prefix + "texture_cell_m", "must be > 0", problems);
  }
}

void ValidateMarks(const std::vector<GroundMark>& marks, std::vector<std::string>& problems) {
  for (size_t i = 0; i < marks.size(); ++i) {
    const GroundMark& m = marks[i];
    const std::string prefix = "marks[" + std::to_string(i) + "].";
    const cv::Rect2d& a = m.area_xz_m;
    Check(!std::isfinite(a.x) || !std::isfinite(a.y) || !(a.width > 0.0) || !(a.height > 0.0) ||
              !std::isfinite(a.width) || !std::isfinite(a.height),
          prefix + "area_xz_m", "must be finite with width and height > 0", problems);
    Check(!InUnit(m.albedo), prefix + "albedo", "must be in 0..1", problems);
    Check(!InUnit(m.contrast), prefix + "contrast", "must be in 0..1", problems);
  }
}

void ValidateDashedLines(const std::vector<DashedLine>& dashed_lines,
                         std::vector<std::string>& problems) {
  for (size_t i = 0; i < dashed_lines.size(); ++i) {
    const DashedLine& l = dashed_lines[i];
    const std::string prefix = "dashed_lines[" + std::to_string(i) + "].";
    Check(!std::isfinite(l.x_m), prefix + "x_m", "must be finite", problems);
    Check(!(l.width_m > 0.0) || !std::isfinite(l.width_m), prefix + "width_m", "must be > 0",
          problems);
    Check(!std::isfinite(l.z_start_m), prefix + "z_start_m", "must be finite", problems);
    Check(!(l.z_end_m > l.z_start_m), prefix + "z_end_m", "must be > z_start_m (may be infinite)",
          problems);
    Check(!(l.dash_m > 0.0) || !std::isfinite(l.dash_m), prefix + "dash_m", "must be > 0",
          problems);
    Check(!(l.gap_m >= 0.0) || !std::isfinite(l.gap_m), prefix + "gap_m", "must be >= 0", problems);
    Check(!InUnit(l.albedo), prefix + "albedo", "must be in 0..1", problems);
    Check(!InUnit(l.contrast), prefix + "contrast", "must be in 0..1", problems);
  }
}

}  // namespace

std::vector<std::string> Scene::Validate() const {
  std::vector<std::string> problems;
  const bool moving = rig_velocity_mps != cv::Vec3d(0.0, 0.0, 0.0);
  Check(!std::isfinite(rig_velocity_mps[0]) || !std::isfinite(rig_velocity_mps[2]) ||
            rig_velocity_mps[1] != 0.0,
        "rig_velocity_mps", "must be finite and level (y = 0)", problems);
  Check(!(rig_period_s >= 0.0) || !std::isfinite(rig_period_s), "rig_period_s", "must be >= 0",
        problems);
  Check(moving && (!hills.empty() || !marks.empty() || !dashed_lines.empty()), "rig_velocity_mps",
        "a moving rig supports no hills, marks or dashed lines", problems);
  Check(!(camera_height_m > 0.0) || !std::isfinite(camera_height_m), "camera_height_m",
        "must be > 0", problems);
  Check(!InUnit(ground_albedo), "ground_albedo", "must be in 0..1", problems);
  Check(!InUnit(ground_contrast), "ground_contrast", "must be in 0..1", problems);
  Check(!(ground_texture_cell_m > 0.0) || !std::isfinite(ground_texture_cell_m),
        "ground_texture_cell_m", "must be > 0", problems);
  Check(!InUnit(sky_top), "sky_top", "must be in 0..1", problems);
  Check(!InUnit(sky_horizon), "sky_horizon", "must be in 0..1", problems);
  Check(!(std::abs(camera_pitch_deg) <= 45.0), "camera_pitch_deg", "must be in -45..45", problems);
  Check(!InUnit(cloud_cover), "cloud_cover", "must be in 0..1", problems);
  Check(!(std::abs(cloud_grey) <= 1.0), "cloud_grey", "must be in -1..1", problems);
  Check(!(cloud_scale > 0.0) || !std::isfinite(cloud_scale), "cloud_scale", "must be > 0",
        problems);

  ValidateObstacles(obstacles, problems);
  ValidateHills(hills, camera_height_m, problems);
  ValidateMarks(marks, problems);
  ValidateDashedLines(dashed_lines, problems);
  return problems;
}

// The demo scene, for the default rig (640x480, f = 700 px, B = 0.6 m, so f B = 420 px m).
// The camera flies 40 m above flat ground, looking horizontally: the ground starts at 117 m
// depth on the bottom row and the horizon is row 240. Everything of interest is between 20 and
// 50 m, where the disparity is 8.4..21 px. The moving obstacles loop every 20 s:
//   - aircraft-1 crosses the view left to right at 30 m, high up (rows ~54..100);
//   - drone-3 flies right to left at 48 m in the same rows and passes behind aircraft-1
//     (fully hidden for ~2.5 s around t = 12 s);
//   - drone-2 (20 m, moving right) and aircraft-2 (35 m, moving left) cross in the image around
//     t = 6 s (rows ~155..185), aircraft-2 behind;
//   - drone-1 circles (radius 8 m around x = 0, z = 32 m, rows ~95..165) once every 20 s,
//     starting on the left (x = -8 m) in front of the tower; it passes behind drone-2 around
//     t = 12 s.
// Static: a 50 m tower on the left at 43 m and a 36 m tall hangar on the right at 48 m, both
// standing on the ground (their tops are in view; their bases are below the bottom row).
Scene DefaultScene() {
  Scene scene;
  scene.camera_height_m = 40.0;
  scene.ground_albedo = 0.45;
  scene.ground_contrast = 0.3;
  scene.ground_texture_cell_m = 0.4;
  scene.sky_top = 0.55;
  scene.sky_horizon = 0.9;
  const double h = scene.camera_height_m;
  const double loop_s = 20.0;

  auto add = [&scene](int id, std::string name, cv::Vec3d size_m, Path path, double albedo,
                      double contrast, double cell_m) {
    scene.obstacles.push_back(
        MakeObstacle(id, std::move(name), size_m, path, albedo, contrast, cell_m));
  };
  auto linear = [loop_s](cv::Vec3d start, cv::Vec3d velocity_mps) {
    Path p;
    p.kind = Path::Kind::kLinear;
    p.start = start;
    p.velocity_mps = velocity_mps;
    p.period_s = loop_s;
    return p;
  };

  // Tower: 4 x 50 x 4 m, front face at z = 43 m (9.8 px), columns ~60..125, rows 77..bottom.
  add(1, "tower", {4.0, 50.0, 4.0}, Fixed({-14.0, h - 25.0, 45.0}), 0.5, 0.4, 0.2);
  // Hangar: 20 x 36 x 15 m, front face at z = 48 m (8.75 px), columns ~335..626, rows 298..bottom.
  add(2, "hangar", {20.0, 36.0, 15.0}, Fixed({11.0, h - 18.0, 55.5}), 0.62, 0.35, 0.25);
  // aircraft-1: 6 x 2 x 2 m at z = 30 m (14 px), x -12 -> +12 m over 20 s (140 x 47 px).
  add(3, "aircraft-1", {6.0, 2.0, 2.0}, linear({-12.0, -7.0, 31.0}, {1.2, 0.0, 0.0}), 0.3, 0.45,
      0.15);
  // drone-1: 1.5 x 0.8 x 1.5 m circling; front face at 23..39 m (10.7..18 px), >= 27 x 14 px;
  // nearest (z = 24 m) at t = 5 s, farthest at t = 15 s.
  {
    Path p;
    p.kind = Path::Kind::kCircle;
    p.start = {0.0, -4.5, 32.0};
    p.radius_m = 8.0;
    p.angular_rate_rad_s = 2.0 * kPi / loop_s;
    p.phase_rad = kPi;
    add(4, "drone-1", {1.5, 0.8, 1.5}, p, 0.25, 0.45, 0.12);
  }
  // drone-2: 1.5 x 0.6 x 1.5 m at z = 20 m (21 px), x -5.2 -> +8.8 m (52 x 21 px).
  add(5, "drone-2", {1.5, 0.6, 1.5}, linear({-5.2, -2.0, 20.75}, {0.7, 0.0, 0.0}), 0.3, 0.45, 0.12);
  // aircraft-2: 5 x 1.5 x 2 m at z = 35 m (12 px), x +4.25 -> -15.75 m (100 x 30 px); it
  // crosses drone-2 in the image around t = 6 s, behind it.
  add(6, "aircraft-2", {5.0, 1.5, 2.0}, linear({4.25, -3.5, 36.0}, {-1.0, 0.0, 0.0}), 0.35, 0.4,
      0.15);
  // drone-3: 1.8 x 0.9 x 1.8 m at z = 48 m (8.75 px), x +15.84 -> -4.16 m (26 x 13 px); passes
  // behind aircraft-1 around t = 12 s.
  add(7, "drone-3", {1.8, 0.9, 1.8}, linear({15.84, -11.2, 48.9}, {-1.0, 0.0, 0.0}), 0.25, 0.45,
      0.12);
  return scene;
}

// Scenario building blocks (declared in scene_helpers.h). All scenarios use the default rig:
// f = 700 px, B = 0.6 m (f B = 420 px m), 640 x 480, principal point (320, 240), 10 fps. A point
// (x, y, z) shows at u = 320 + 700 x / z, v = 240 + 700 y / z, with disparity 420 / z px (8 px at
// 52.5 m).

Path Leg(cv::Vec3d start, cv::Vec3d end, double period_s) {
  Path p;
  p.kind = Path::Kind::kLinear;
  p.start = start;
  p.velocity_mps = (end - start) * (1.0 / period_s);
  p.period_s = period_s;
  return p;
}

Path Circle(cv::Vec3d centre, double radius_m, double period_s, double phase_rad) {
  Path p;
  p.kind = Path::Kind::kCircle;
  p.start = centre;
  p.radius_m = radius_m;
  p.angular_rate_rad_s = 2.0 * kPi / period_s;
  p.phase_rad = phase_rad;
  return p;
}

SyntheticOptions ScenarioOptions(uint64_t seed, Scene scene) {
  SyntheticOptions o;
  o.seed = seed;
  o.noise_sigma = 2.0;
  o.scene = std::move(scene);
  return o;
}

Scenario MakeScenario(std::string name, uint64_t seed, Scene scene, int frames,
                      std::string description) {
  Scenario s;
  s.name = std::move(name);
  s.description = std::move(description);
  s.options = ScenarioOptions(seed, std::move(scene));
  s.frames = frames;
  return s;
}

namespace {

// A grass airfield: a 30 m wide asphalt runway along z centred on x = runway_x_m, from z = 0 to
// 2 km, with continuous 0.9 m white edge lines, a dashed white centreline (30 m dashes, 20 m
// gaps, from z = 15 m), eight threshold bars (1.8 m x 30 m, at z = 60..90 m), and two crop
// fields of other greys beside it (their edges are long straight grey-level steps).
void AddAirfield(Scene& scene, double runway_x_m) {
  const double half = 15.0;
  auto mark = [&scene](double x0, double x1, double z0, double z1, double albedo, double contrast) {
    GroundMark m;
    m.area_xz_m = cv::Rect2d(x0, z0, x1 - x0, z1 - z0);
    m.albedo = albedo;
    m.contrast = contrast;
    scene.marks.push_back(m);
  };
  const double rx = runway_x_m;
  // Fields first (painted over by nothing else), then the runway and its paint.
  mark(rx - 260.0, rx - 45.0, 0.0, 700.0, 0.34, 0.28);       // dark grass field, left
  mark(rx + 50.0, rx + 320.0, 90.0, 520.0, 0.56, 0.25);      // light crop field, right
  mark(rx - half, rx + half, 0.0, 2000.0, 0.32, 0.12);       // asphalt
  mark(rx - half, rx - half + 0.9, 0.0, 2000.0, 0.9, 0.03);  // edge lines
  mark(rx + half - 0.9, rx + half, 0.0, 2000.0, 0.9, 0.03);
  for (int k = 0; k < 4; ++k) {  // threshold bars, four each side of the centreline
    const double x_in = 1.8 + 3.6 * k;
    mark(rx - x_in - 1.8, rx - x_in, 60.0, 90.0, 0.9, 0.03);
    mark(rx + x_in, rx + x_in + 1.8, 60.0, 90.0, 0.9, 0.03);
  }
  DashedLine centre;
  centre.x_m = rx;
  centre.width_m = 0.9;
  centre.z_start_m = 15.0;
  centre.z_end_m = 2000.0;
  centre.dash_m = 30.0;
  centre.gap_m = 20.0;
  centre.albedo = 0.9;
  centre.contrast = 0.03;
  scene.dashed_lines.push_back(centre);
}

// The far terrain: four broad hills 15..45 m high, their feet 200..310 m away (disparity
// 1.2..2.1 px), tops at rows ~145..205 for a camera a few metres up. Hazy: light, low contrast.
void AddFarRidge(Scene& scene) {
  const double h = scene.camera_height_m;
  auto hill = [&scene](cv::Vec3d centre, cv::Vec3d radii, double albedo, double contrast,
                       double cell) {
    Hill x;
    x.centre_m = centre;
    x.radii_m = radii;
    x.albedo = albedo;
    x.contrast = contrast;
    x.texture_cell_m = cell;
    scene.hills.push_back(x);
  };
  hill({-180.0, h + 10.0, 330.0}, {160.0, 55.0, 70.0}, 0.52, 0.2, 2.0);  // 45 m high
  hill({60.0, h + 5.0, 380.0}, {140.0, 40.0, 60.0}, 0.55, 0.2, 2.0);     // 35 m high
  hill({260.0, h + 10.0, 290.0}, {120.0, 50.0, 60.0}, 0.5, 0.2, 2.0);    // 40 m high
  hill({-40.0, h + 20.0, 250.0}, {70.0, 35.0, 40.0}, 0.48, 0.22, 1.5);   // 15 m high, in front
}

Scenario ClearSky() {
  Scene scene;
  scene.camera_height_m = 100.0;  // the ground is 290 m+ away, below the horizon row
  const double loop_s = 8.0;
  scene.obstacles.push_back(MakeObstacle(1, "aircraft-1", {6.0, 2.0, 2.0},
                                         Leg({-10.0, -9.0, 33.0}, {10.0, -9.0, 33.0}, loop_s), 0.3,
                                         0.45, 0.15));
  scene.obstacles.push_back(MakeObstacle(2, "aircraft-2", {8.0, 2.5, 3.0},
                                         Leg({12.0, -5.0, 49.5}, {-12.0, -5.0, 49.5}, loop_s), 0.35,
                                         0.4, 0.2));
  scene.obstacles.push_back(MakeObstacle(
      3, "drone-1", {1.2, 0.5, 1.2}, Circle({0.0, -3.0, 22.0}, 5.0, loop_s, kPi), 0.25, 0.45, 0.1));
  scene.obstacles.push_back(MakeObstacle(4, "drone-2", {1.5, 0.6, 1.5},
                                         Leg({4.0, -7.5, 45.75}, {3.0, -5.0, 24.75}, loop_s), 0.28,
                                         0.45, 0.12));
  return MakeScenario(
      "clear_sky", 101, std::move(scene), 80,
      "Camera 100 m above flat textured ground, so the ground (290 m and farther, < 1.5 px of "
      "disparity) stays below the horizon row and every obstacle is against the sky gradient "
      "(all of them above row 190). Four moving obstacles: aircraft-1 (6 x 2 x 2 m) crosses "
      "left to right with its front face at 32 m (13.1 px of disparity; box ~135 x 54 px with "
      "its underside, rows 22..75); aircraft-2 (8 x 2.5 x 3 m) crosses right to left at 48 m "
      "(8.75 px, 8.25 px at its back; ~120 x 40 px, rows 149..188); drone-1 (1.2 x 0.5 x "
      "1.2 m) circles (radius 5 m around x = 0, z = 22 m) with its front at 16.4..26.4 m "
      "(16..26 px, 31..55 px wide); drone-2 (1.5 x 0.6 x 1.5 m) approaches from 45 m to 24 m "
      "(9.3 -> 17.3 px) while climbing, growing from 25 x 13 to 47 x 25 px. 8 s loop, 80 "
      "frames. The easy baseline: no clutter behind any obstacle; occlusions between them.");
}

Scenario LowOverGround() {
  Scene scene;
  scene.camera_height_m = 3.0;
  const double h = scene.camera_height_m;
  AddAirfield(scene, 4.0);
  AddFarRidge(scene);
  // Near low hills: their front slopes are as near as the obstacles.
  Hill near_left;
  near_left.centre_m = {-30.0, h + 2.0, 70.0};
  near_left.radii_m = {28.0, 10.0, 30.0};  // 8 m high, front foot at 40.6 m (10.3 px)
  near_left.albedo = 0.42;
  near_left.contrast = 0.3;
  near_left.texture_cell_m = 0.5;
  scene.hills.push_back(near_left);
  Hill near_right;
  near_right.centre_m = {38.0, h + 3.0, 110.0};
  near_right.radii_m = {35.0, 15.0, 25.0};  // 12 m high, front foot at 85.5 m (4.9 px)
  near_right.albedo = 0.4;
  near_right.contrast = 0.3;
  near_right.texture_cell_m = 0.6;
  scene.hills.push_back(near_right);

  const double loop_s = 6.0;
  scene.obstacles.push_back(MakeObstacle(1, "aircraft-low", {5.0, 1.5, 2.0},
                                         Leg({-3.0, -1.5, 41.0}, {8.0, -1.5, 41.0}, loop_s), 0.3,
                                         0.4, 0.15));
  scene.obstacles.push_back(MakeObstacle(2, "drone-1", {1.5, 0.6, 1.5},
                                         Leg({6.0, -5.0, 25.75}, {-6.0, -5.0, 25.75}, loop_s), 0.28,
                                         0.45, 0.12));
  scene.obstacles.push_back(MakeObstacle(3, "aircraft-2", {5.0, 1.5, 2.0},
                                         Leg({-8.0, -11.0, 46.0}, {4.0, -11.0, 46.0}, loop_s), 0.35,
                                         0.4, 0.15));
  return MakeScenario(
      "low_over_ground", 102, std::move(scene), 60,
      "Camera 3 m over a grass airfield, level: the ground fills the lower half (8.8 m deep at "
      "the bottom row, 50 m at row 282), with a 30 m runway along z right of the camera "
      "(centre x = 4 m, asphalt 0.32, white 0.9 edge lines, dashed centreline, threshold bars "
      "at 60..90 m) and two crop fields whose edges converge to the horizon. Terrain: a far "
      "ridge of four hills (15..45 m high, feet at 200..310 m, tops at rows ~145..205) and two "
      "near low hills: left 8 m high, its front slope from 40.6 m (10.3 px, as near as the "
      "obstacles); right 12 m high from 85.5 m. Terrain is ~60 % of the image, hills ~18 %. "
      "Obstacles: aircraft-low (5 x 1.5 x 2 m) at 40 m (10.5 px), 4.5 m above the ground, just "
      "above the horizon (rows 201..227) in front of the ridge and the near hills, flying "
      "right; drone-1 (1.5 x 0.6 x 1.5 m) at 25 m (16.8 px, rows 92..115) flying left; "
      "aircraft-2 (5 x 1.5 x 2 m) at 45 m (9.3 px, rows 58..87) flying right. 6 s loop, 60 "
      "frames. Hard: edges and salient spots of the runway paint, field edges and hill "
      "silhouettes are not obstacles, and the near hill and the ground have obstacle-like "
      "disparities.");
}

Scenario SmallFar() {
  Scene scene;
  scene.camera_height_m = 40.0;
  const double loop_s = 6.0;
  scene.obstacles.push_back(MakeObstacle(1, "aircraft-small", {1.3, 0.5, 0.8},
                                         Leg({-3.0, -6.0, 46.4}, {3.0, -6.0, 46.4}, loop_s), 0.3,
                                         0.45, 0.06));
  scene.obstacles.push_back(MakeObstacle(2, "drone-near", {1.5, 0.6, 1.5},
                                         Leg({3.0, -0.5, 15.75}, {-3.0, -0.5, 15.75}, loop_s), 0.28,
                                         0.45, 0.1));
  return MakeScenario(
      "small_far", 103, std::move(scene), 60,
      "Camera 40 m over flat textured ground. aircraft-small (1.3 x 0.5 x 0.8 m) at 46 m: "
      "9.1 px of disparity (9.08 px at its back), ~20 x 9 px, rows 145..153, crossing left to "
      "right (u ~265..375) against the sky; drone-near (1.5 x 0.6 x 1.5 m) at 15 m (28 px, "
      "~71..80 x 29 px, rows 203..231, just above the horizon) crossing right to left. 6 s "
      "loop, 60 frames. Hard: the far one is a few pixels across, below typical blob-area "
      "floors, and has few pixels of disparity for the matcher.");
}

Scenario ClosePair() {
  Scene scene;
  scene.camera_height_m = 40.0;
  const double loop_s = 6.0;
  // Both drift right at ~10 px/s; the drone rises, so the vertical gap between their boxes
  // closes from ~8 px to an overlap of ~6 px (the drone then hides the aircraft's underside).
  scene.obstacles.push_back(MakeObstacle(1, "aircraft-far", {5.0, 1.5, 2.0},
                                         Leg({-3.0, -4.5, 36.0}, {0.0, -4.5, 36.0}, loop_s), 0.33,
                                         0.42, 0.15));
  scene.obstacles.push_back(MakeObstacle(2, "drone-near", {1.5, 0.6, 1.5},
                                         Leg({-1.9, -1.50, 20.75}, {-0.1, -1.95, 20.75}, loop_s),
                                         0.28, 0.45, 0.1));
  return MakeScenario(
      "close_pair", 104, std::move(scene), 60,
      "Camera 40 m over flat textured ground. aircraft-far (5 x 1.5 x 2 m) at 35 m (12 px, "
      "~101 x 35 px with its underside, rows 135..169) and drone-near (1.5 x 0.6 x 1.5 m) at "
      "20 m (21 px, ~53 x 24 px) just below it, both drifting right at ~10 px/s; the drone "
      "climbs, so the gap between the two boxes closes from 7 px (frame 0) to an 8 px overlap "
      "(frame 59, the drone hiding the aircraft's underside). 6 s loop, 60 frames. Hard: edge "
      "closing and blob merging join them into one blob, whose median range is wrong for "
      "both; the depths differ by 75 %.");
}

Scenario LowContrast() {
  Scene scene;
  scene.camera_height_m = 40.0;
  // The sky is 0.9 - 0.35 (240 - v) / 240 at row v (sky_top 0.55, sky_horizon 0.9).
  const double loop_s = 6.0;
  scene.obstacles.push_back(MakeObstacle(1, "aircraft-pale", {5.0, 1.5, 0.6},
                                         Leg({-6.0, -5.0, 32.3}, {6.0, -5.0, 32.3}, loop_s), 0.80,
                                         0.15, 0.15));
  scene.obstacles.push_back(MakeObstacle(2, "drone-grey", {1.5, 0.6, 0.4},
                                         Leg({5.0, -6.0, 26.2}, {-5.0, -6.0, 26.2}, loop_s), 0.61,
                                         0.15, 0.1));
  return MakeScenario(
      "low_contrast", 105, std::move(scene), 60,
      "Camera 40 m over flat textured ground. aircraft-pale (5 x 1.5 x 0.6 m, albedo 0.80, "
      "contrast 0.15) at 32 m (13.1 px, ~110 x 34 px, rows 115..148) against sky of grey "
      "0.72..0.77 (mean 0.74: +0.06), crossing left to right; drone-grey (1.5 x 0.6 x 0.4 m, "
      "albedo 0.61, contrast 0.15) at 26 m (16.2 px, ~41 x 18 px, rows 71..88) against sky "
      "of ~0.67 (-0.06), crossing right to left. Measured in the image: mean grey 0.05 and "
      "0.065 from the sky beside them, texture standard deviation ~0.055 and ~0.075, enough "
      "for stereo; their outlines barely show (only the darker-shaded underside and side "
      "faces, 1..4 px). 6 s loop, 60 frames. Hard for intensity and edge extractors.");
}

Scenario TowerOnGround() {
  Scene scene;
  scene.camera_height_m = 5.0;
  const double h = scene.camera_height_m;
  AddAirfield(scene, 30.0);  // the runway to the right; the tower stands on the grass
  AddFarRidge(scene);
  const double loop_s = 6.0;
  // Static, standing on the ground (bottom at y = h).
  scene.obstacles.push_back(
      MakeObstacle(1, "tower", {3.0, 15.0, 3.0}, Fixed({-6.0, h - 7.5, 39.5}), 0.5, 0.4, 0.15));
  scene.obstacles.push_back(
      MakeObstacle(2, "hut", {8.0, 4.0, 6.0}, Fixed({9.0, h - 2.0, 47.0}), 0.6, 0.35, 0.2));
  scene.obstacles.push_back(MakeObstacle(3, "drone-1", {1.5, 0.6, 1.5},
                                         Leg({6.0, -4.0, 28.75}, {-5.0, -4.0, 28.75}, loop_s), 0.28,
                                         0.45, 0.12));
  return MakeScenario(
      "tower_on_ground", 106, std::move(scene), 60,
      "Camera 5 m over a grass airfield (runway along z centred on x = 30 m with its paint, "
      "crop fields, and the far ridge of low_over_ground). tower (3 x 15 x 3 m) stands on the "
      "ground at 38 m (11 px, 10.3 px at its back; columns 182..243, rows 56..332: its foot "
      "meets the grass at the same depth); hut (8 x 4 x 6 m, albedo 0.6) stands on the ground "
      "at 44 m (9.5 px, 8.4 px at its back), right of centre, entirely below the horizon "
      "against the ground (columns 390..526, rows 254..319, its roof seen from above); "
      "drone-1 (1.5 x 0.6 x 1.5 m) at 28 m (15 px, ~40 x 20 px, rows 133..152) flies right to "
      "left and ends in front of the tower (from frame ~46). 6 s loop, 60 frames. Hard: "
      "obstacles rooted in the ground, whose disparity meets the ground's at their feet.");
}

}  // namespace

Scenario FlightScenario() {
  Scenario s;
  s.name = "flight";
  s.description =
      "The demo scene with the rig flying forward at 3 m/s (repeating every 10 s): the tower and "
      "the hangar come 30 m nearer and the moving obstacles pass by.";
  s.options.scene = DefaultScene();
  s.options.scene.rig_velocity_mps = cv::Vec3d(0.0, 0.0, 3.0);
  s.options.scene.rig_period_s = 10.0;
  s.frames = 100;
  return s;
}

std::vector<Scenario> EvaluationScenarios() {
  return {ClearSky(), LowOverGround(), SmallFar(), ClosePair(), LowContrast(), TowerOnGround()};
}

}  // namespace stevi::drivers
