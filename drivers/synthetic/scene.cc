#include "drivers/synthetic/scene.h"

#include <cmath>
#include <map>

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

cv::Vec3d Path::PositionAt(double t_s) const {
  switch (kind) {
    case Kind::kStatic:
      return start;
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

std::vector<std::string> Scene::Validate() const {
  std::vector<std::string> problems;
  Check(!(camera_height_m > 0.0) || !std::isfinite(camera_height_m), "camera_height_m",
        "must be > 0", problems);
  Check(!InUnit(ground_albedo), "ground_albedo", "must be in 0..1", problems);
  Check(!InUnit(ground_contrast), "ground_contrast", "must be in 0..1", problems);
  Check(!(ground_texture_cell_m > 0.0) || !std::isfinite(ground_texture_cell_m),
        "ground_texture_cell_m", "must be > 0", problems);
  Check(!InUnit(sky_top), "sky_top", "must be in 0..1", problems);
  Check(!InUnit(sky_horizon), "sky_horizon", "must be in 0..1", problems);

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
    Check(!(o.size_m[0] > 0.0 && o.size_m[1] > 0.0 && o.size_m[2] > 0.0) || !Finite(o.size_m),
          prefix + "size_m", "every side must be > 0", problems);
    Check(!InUnit(o.albedo), prefix + "albedo", "must be in 0..1", problems);
    Check(!InUnit(o.contrast), prefix + "contrast", "must be in 0..1", problems);
    Check(!(o.texture_cell_m > 0.0) || !std::isfinite(o.texture_cell_m), prefix + "texture_cell_m",
          "must be > 0", problems);
    ValidatePath(o.path, prefix + "path.", problems);
  }
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
    Obstacle o;
    o.id = id;
    o.name = std::move(name);
    o.size_m = size_m;
    o.path = path;
    o.albedo = albedo;
    o.contrast = contrast;
    o.texture_cell_m = cell_m;
    scene.obstacles.push_back(std::move(o));
  };
  auto fixed = [](cv::Vec3d centre) {
    Path p;
    p.kind = Path::Kind::kStatic;
    p.start = centre;
    return p;
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
  add(1, "tower", {4.0, 50.0, 4.0}, fixed({-14.0, h - 25.0, 45.0}), 0.5, 0.4, 0.2);
  // Hangar: 20 x 36 x 15 m, front face at z = 48 m (8.75 px), columns ~335..626, rows 298..bottom.
  add(2, "hangar", {20.0, 36.0, 15.0}, fixed({11.0, h - 18.0, 55.5}), 0.62, 0.35, 0.25);
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
  add(5, "drone-2", {1.5, 0.6, 1.5}, linear({-5.2, -2.0, 20.75}, {0.7, 0.0, 0.0}), 0.3, 0.45,
      0.12);
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

}  // namespace stevi::drivers
