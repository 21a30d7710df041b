#include "drivers/synthetic/random_scenes.h"

#include "drivers/synthetic/scene_helpers.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>
#include <utility>

namespace stevi::drivers {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kFps = 10.0;

uint64_t HashString(const std::string& s) {
  uint64_t h = 0xCBF29CE484222325ull;
  for (const char c : s) {
    h ^= static_cast<uint8_t>(c);
    h *= 0x100000001B3ull;
  }
  return h;
}

// The scene's own generator. Draws are made with the engine's raw output only (no standard
// distributions, whose algorithms differ between standard libraries), so scenes are the same
// everywhere.
class Rng {
 public:
  explicit Rng(uint64_t seed) : engine_(seed) {}
  double Uniform(double a, double b) {
    return a + (b - a) * (static_cast<double>(engine_() >> 11) * 0x1.0p-53);
  }
  double LogUniform(double a, double b) { return std::exp(Uniform(std::log(a), std::log(b))); }
  int Int(int a, int b) {  // a..b inclusive
    return a + static_cast<int>(engine_() % static_cast<uint64_t>(b - a + 1));
  }
  bool Chance(double p) { return Uniform(0.0, 1.0) < p; }
  uint64_t Bits() { return engine_(); }

 private:
  std::mt19937_64 engine_;
};

// The pitched pinhole camera of the renderer (world: y down, the ground at y = height).
struct Camera {
  int w = 640, h = 480;
  double f = 700.0, baseline = 0.6, height = 10.0, pitch_deg = 0.0;
  double cx = 320.0, cy = 240.0, cp = 1.0, sp = 0.0;

  void Finish() {
    cx = w / 2.0;
    cy = h / 2.0;
    cp = std::cos(pitch_deg * kPi / 180.0);
    sp = std::sin(pitch_deg * kPi / 180.0);
  }
  double fb() const { return f * baseline; }
  double HorizonRow() const { return cy + f * sp / cp; }
  cv::Vec3d ToCam(const cv::Vec3d& p) const {
    return {p[0], p[1] * cp + p[2] * sp, p[2] * cp - p[1] * sp};
  }
  cv::Vec3d ToWorld(const cv::Vec3d& c) const {
    return {c[0], c[1] * cp - c[2] * sp, c[1] * sp + c[2] * cp};
  }
  // The world point at camera depth z through pixel (u, v).
  cv::Vec3d BackProject(double u, double v, double z) const {
    return ToWorld({(u - cx) * z / f, (v - cy) * z / f, z});
  }
  cv::Point2d Project(const cv::Vec3d& p) const {
    const cv::Vec3d c = ToCam(p);
    return {cx + f * c[0] / c[2], cy + f * c[1] / c[2]};
  }
  // The image rectangle of a world box (its eight corners); empty when a corner is behind.
  cv::Rect2d ProjectBox(const cv::Vec3d& lo, const cv::Vec3d& hi) const {
    double u0 = 1e18, u1 = -1e18, v0 = 1e18, v1 = -1e18;
    for (int k = 0; k < 8; ++k) {
      const cv::Vec3d p((k & 1) ? hi[0] : lo[0], (k & 2) ? hi[1] : lo[1], (k & 4) ? hi[2] : lo[2]);
      const cv::Vec3d c = ToCam(p);
      if (c[2] <= 0.5) return {};
      const double u = cx + f * c[0] / c[2], v = cy + f * c[1] / c[2];
      u0 = std::min(u0, u);
      u1 = std::max(u1, u);
      v0 = std::min(v0, v);
      v1 = std::max(v1, v);
    }
    return {u0, v0, u1 - u0, v1 - v0};
  }
  double InFrameFraction(const cv::Rect2d& r) const {
    if (r.width <= 0 || r.height <= 0) return 0.0;
    const cv::Rect2d in = r & cv::Rect2d(0, 0, w, h);
    return in.area() / r.area();
  }
};

// An obstacle's solids around its position, and their bounds.
struct Shape {
  std::string kind;
  std::vector<ObstaclePart> parts;
  cv::Vec3d lo{0, 0, 0}, hi{0, 0, 0};
  bool standing = false;
  int heading_axis = 0;  // aircraft: 0 = crossing (along x), 2 = approaching (along z)
  int heading_sign = 1;
  double extent_m = 0;
};

void AddPart(Shape& s, ObstaclePart::Shape shape, cv::Vec3d offset, cv::Vec3d size) {
  ObstaclePart p;
  p.shape = shape;
  p.offset_m = offset;
  p.size_m = size;
  s.parts.push_back(p);
}

// Sets the shape's bounds (lo, hi, extent_m) from its parts.
void FinishShape(Shape& s) {
  s.lo = cv::Vec3d::all(1e18);
  s.hi = cv::Vec3d::all(-1e18);
  for (const ObstaclePart& p : s.parts) {
    for (int k = 0; k < 3; ++k) {
      s.lo[k] = std::min(s.lo[k], p.offset_m[k] - 0.5 * p.size_m[k]);
      s.hi[k] = std::max(s.hi[k], p.offset_m[k] + 0.5 * p.size_m[k]);
    }
  }
  s.extent_m = std::max({s.hi[0] - s.lo[0], s.hi[1] - s.lo[1], s.hi[2] - s.lo[2]});
}

// An empty shape of `kind` (parts to be added).
Shape NewShape(std::string kind, bool standing) {
  Shape s;
  s.kind = std::move(kind);
  s.standing = standing;
  return s;
}

constexpr auto kBox = ObstaclePart::Shape::kBox;
constexpr auto kEllipsoid = ObstaclePart::Shape::kEllipsoid;

// A fixed-wing aircraft: fuselage (box or ellipsoid), wings, tailplane and fin; length in metres.
Shape Aircraft(Rng& rng, double length, bool standing) {
  Shape s = NewShape("aircraft", standing);
  s.heading_axis = rng.Chance(0.5) ? 0 : 2;
  s.heading_sign = rng.Chance(0.5) ? 1 : -1;
  const double L = length;
  const double D = L * rng.Uniform(0.08, 0.12);
  const double span = L * rng.Uniform(0.9, 1.3);
  const double chord = L * rng.Uniform(0.1, 0.16);
  const double thick = std::max(0.08, D * 0.15);
  const double fin_h = D * rng.Uniform(1.0, 1.6);
  const double wing_y = D * rng.Uniform(-0.3, 0.3);
  // Along the heading axis: +1 = the nose side.
  auto along = [&](double a, double y, double across, cv::Vec3d size_along_across) {
    // size: (along, vertical, across)
    if (s.heading_axis == 0) {
      return std::make_pair(
          cv::Vec3d(a * s.heading_sign, y, across),
          cv::Vec3d(size_along_across[0], size_along_across[1], size_along_across[2]));
    }
    return std::make_pair(
        cv::Vec3d(across, y, a * s.heading_sign),
        cv::Vec3d(size_along_across[2], size_along_across[1], size_along_across[0]));
  };
  auto add = [&](ObstaclePart::Shape shape, double a, double y, double across, cv::Vec3d size) {
    const auto [offset, sz] = along(a, y, across, size);
    AddPart(s, shape, offset, sz);
  };
  add(rng.Chance(0.5) ? kEllipsoid : kBox, 0.0, 0.0, 0.0, {L, D, D});
  add(kBox, L * 0.05, wing_y, 0.0, {chord, thick, span});
  add(kBox, -L * 0.42, -D * 0.2, 0.0, {chord * 0.7, thick, span * 0.35});
  add(kBox, -L * 0.42, -D * 0.5 - fin_h * 0.5, 0.0, {chord * 0.9, fin_h, thick});
  return s;
}

// A multirotor: body, two crossed arms and four rotor discs; span in metres.
Shape Drone(Rng& rng, double span) {
  Shape s = NewShape("drone", false);
  const double W = span;
  AddPart(s, rng.Chance(0.5) ? kEllipsoid : kBox, {0, 0, 0}, {W * 0.3, W * 0.16, W * 0.3});
  AddPart(s, kBox, {0, -W * 0.03, 0}, {W, W * 0.04, W * 0.05});
  AddPart(s, kBox, {0, -W * 0.03, 0}, {W * 0.05, W * 0.04, W});
  for (const auto& [x, z] : std::array<std::pair<double, double>, 4>{
           {{W * 0.5, 0.0}, {-W * 0.5, 0.0}, {0.0, W * 0.5}, {0.0, -W * 0.5}}}) {
    AddPart(s, kEllipsoid, {x, -W * 0.07, z}, {W * 0.32, W * 0.03, W * 0.32});
  }
  if (rng.Chance(0.5)) AddPart(s, kBox, {0, W * 0.12, 0}, {W * 0.2, W * 0.1, W * 0.12});  // camera
  return s;
}

// A balloon: an ellipsoid envelope, and a basket under the large ones; diameter in metres.
Shape Balloon(Rng& rng, double diameter) {
  Shape s = NewShape("balloon", false);
  const double Dm = diameter;
  AddPart(s, kEllipsoid, {0, 0, 0}, {Dm, Dm * rng.Uniform(1.0, 1.25), Dm});
  if (Dm > 5.0) AddPart(s, kBox, {0, Dm * 0.78, 0}, {Dm * 0.12, Dm * 0.1, Dm * 0.12});
  return s;
}

// A tower standing on the ground: three tapering sections and a mast; height in metres.
Shape Tower(Rng& rng, double height) {
  Shape s = NewShape("tower", true);
  const double H = height;
  const double wb = H * rng.Uniform(0.05, 0.12);
  const double h1 = H * 0.45, h2 = H * 0.3, h3 = H * 0.12, mast = H * 0.13;
  double y = 0.0;  // offsets upwards from the base (negative y)
  AddPart(s, kBox, {0, y - h1 / 2, 0}, {wb, h1, wb});
  y -= h1;
  AddPart(s, kBox, {0, y - h2 / 2, 0}, {wb * 0.7, h2, wb * 0.7});
  y -= h2;
  AddPart(s, kBox, {0, y - h3 / 2, 0}, {wb * 0.45, h3, wb * 0.45});
  y -= h3;
  AddPart(s, kBox, {0, y - mast / 2, 0}, {wb * 0.08, mast, wb * 0.08});
  return s;
}

// A pole standing on the ground, with a cross-arm half the time; height in metres.
Shape Pole(Rng& rng, double height) {
  Shape s = NewShape("pole", true);
  const double w = rng.Uniform(0.2, 0.5);
  AddPart(s, kBox, {0, -height / 2, 0}, {w, height, w});
  if (rng.Chance(0.5)) AddPart(s, kBox, {0, -height * 0.92, 0}, {w * 8, w * 0.5, w * 0.6});
  return s;
}

// A building standing on the ground, sometimes with a smaller box on its roof; width in metres.
Shape Building(Rng& rng, double width) {
  Shape s = NewShape("building", true);
  const double W = width, H = width * rng.Uniform(0.3, 0.9), D = width * rng.Uniform(0.5, 1.0);
  AddPart(s, kBox, {0, -H / 2, 0}, {W, H, D});
  if (rng.Chance(0.5)) {
    const double rh = H * rng.Uniform(0.15, 0.35);
    AddPart(s, kBox, {W * rng.Uniform(-0.2, 0.2), -H - rh / 2, 0}, {W * 0.35, rh, D * 0.5});
  }
  return s;
}

// A family: its rig, environment and what it places.
struct FamilySpec {
  std::vector<std::pair<std::string, double>> kinds;  // kind and weight
  double z_lo = 5, z_hi = 1500;                       // camera depth range, metres
  double contrast_lo = 0.1, contrast_hi = 1.0;
  bool prefer_sky = false;  // airborne obstacles above the horizon
  double parked = 0.0;      // the chance that an aircraft stands on the ground
  double scale = 1.0;       // size factor (close: smaller things)
};

const std::vector<cv::Size>& AllSizes() {
  static const std::vector<cv::Size> sizes = {{640, 480},   {752, 480},  {800, 600},
                                              {1024, 768},  {1280, 720}, {1280, 1024},
                                              {1920, 1080}, {1920, 1200}};
  return sizes;
}

cv::Size PickSize(Rng& rng, size_t first, size_t last) {
  return AllSizes()[first + static_cast<size_t>(rng.Int(0, static_cast<int>(last - first)))];
}

std::string PickKind(Rng& rng, const FamilySpec& spec) {
  double total = 0;
  for (const auto& [k, w] : spec.kinds) total += w;
  double x = rng.Uniform(0.0, total);
  for (const auto& [k, w] : spec.kinds) {
    if (x < w) return k;
    x -= w;
  }
  return spec.kinds.back().first;
}

// The parts of a random obstacle of `kind` (its bounds not yet set).
Shape ShapeParts(Rng& rng, const std::string& kind, const FamilySpec& spec) {
  const double k = spec.scale;
  if (kind == "aircraft") {
    return Aircraft(rng, rng.LogUniform(6.0, 40.0) * k, rng.Chance(spec.parked));
  }
  if (kind == "drone") return Drone(rng, rng.LogUniform(0.4, 2.0));
  if (kind == "balloon") {
    return Balloon(rng, k < 1.0 ? rng.LogUniform(0.5, 2.5) : rng.LogUniform(1.0, 18.0));
  }
  if (kind == "tower") return Tower(rng, rng.LogUniform(15.0, 80.0) * k);
  if (kind == "pole") return Pole(rng, rng.LogUniform(k < 1.0 ? 3.0 : 6.0, k < 1.0 ? 12.0 : 25.0));
  return Building(rng, rng.LogUniform(8.0, 40.0) * k);
}

// A random obstacle of `kind`, with its bounds.
Shape MakeShape(Rng& rng, const std::string& kind, const FamilySpec& spec) {
  Shape s = ShapeParts(rng, kind, spec);
  FinishShape(s);
  return s;
}

// The sky and ground every family starts from (some families change them).
void DrawSkyAndGround(Rng& rng, Scene& scene) {
  scene.sky_horizon = rng.Uniform(0.6, 0.95);
  scene.sky_top = std::max(0.05, scene.sky_horizon - rng.Uniform(0.0, 0.4));
  scene.ground_albedo = rng.Uniform(0.25, 0.6);
  scene.ground_contrast = rng.Uniform(0.05, 0.45);
  scene.ground_texture_cell_m = rng.LogUniform(0.05, 1.5);
  if (rng.Chance(0.6)) {
    scene.cloud_cover = rng.Uniform(0.1, 0.8);
    scene.cloud_grey = rng.Uniform(-0.25, 0.25);
    scene.cloud_scale = rng.LogUniform(0.15, 0.6);
  }
}

// A family's range of rigs: image sizes AllSizes()[first_size..last_size], focal lengths
// (log-uniform) and baselines.
struct RigRange {
  size_t first_size, last_size;
  double f_lo, f_hi;                // pixels
  double baseline_lo, baseline_hi;  // metres
};

// Draws the rig's image size, focal length and baseline from `range`.
void DrawRig(Rng& rng, const RigRange& range, Camera& cam) {
  const cv::Size size = PickSize(rng, range.first_size, range.last_size);
  cam.w = size.width;
  cam.h = size.height;
  cam.f = rng.LogUniform(range.f_lo, range.f_hi);
  cam.baseline = rng.Uniform(range.baseline_lo, range.baseline_hi);
}

// "sky": the camera high up, or low and pitched up; aircraft, drones and balloons against the sky.
FamilySpec SetUpSky(Rng& rng, Camera& cam) {
  DrawRig(rng, {0, AllSizes().size() - 1, 500.0, 2500.0, 0.2, 1.0}, cam);
  if (rng.Chance(0.6)) {
    cam.height = rng.LogUniform(60.0, 400.0);
    cam.pitch_deg = rng.Uniform(0.0, 12.0);
  } else {
    cam.height = rng.Uniform(2.0, 30.0);
    cam.pitch_deg = rng.Uniform(10.0, 25.0);
  }
  return FamilySpec{.kinds = {{"aircraft", 0.4}, {"drone", 0.35}, {"balloon", 0.25}},
                    .z_lo = 10.0,
                    .z_hi = 800.0,
                    .prefer_sky = true};
}

// A runway along z: asphalt, edge lines and a dashed centreline.
void AddRunway(Rng& rng, Scene& scene) {
  const double x = rng.Uniform(-60.0, 60.0), half = rng.Uniform(12.0, 22.0);
  const double asphalt = rng.Uniform(0.2, 0.38);
  GroundMark m;
  m.area_xz_m = cv::Rect2d(x - half, 0.0, 2 * half, 3000.0);
  m.albedo = asphalt;
  m.contrast = 0.1;
  scene.marks.push_back(m);
  for (const double edge : {x - half, x + half - 0.9}) {
    m.area_xz_m = cv::Rect2d(edge, 0.0, 0.9, 3000.0);
    m.albedo = 0.85;
    m.contrast = 0.03;
    scene.marks.push_back(m);
  }
  DashedLine centre;
  centre.x_m = x;
  centre.z_start_m = rng.Uniform(0.0, 40.0);
  centre.z_end_m = 3000.0;
  scene.dashed_lines.push_back(centre);
}

// A far ridge: one to three hills 400..900 m away, the camera `height` up.
void AddRidge(Rng& rng, double height, Scene& scene) {
  const int n = rng.Int(1, 3);
  for (int k = 0; k < n; ++k) {
    Hill hill;
    const double z = rng.Uniform(400.0, 900.0);
    hill.radii_m = {rng.Uniform(80.0, 250.0), rng.Uniform(20.0, 60.0), rng.Uniform(40.0, 90.0)};
    hill.centre_m = {rng.Uniform(-400.0, 400.0), height + rng.Uniform(0.0, 10.0), z};
    hill.albedo = rng.Uniform(0.4, 0.55);
    hill.contrast = rng.Uniform(0.1, 0.25);
    hill.texture_cell_m = rng.Uniform(1.0, 3.0);
    scene.hills.push_back(hill);
  }
}

// "airfield": the camera low over textured ground, sometimes a runway and a far ridge; things
// standing on the ground, aircraft parked or flying, drones.
FamilySpec SetUpAirfield(Rng& rng, Camera& cam, Scene& scene) {
  DrawRig(rng, {0, AllSizes().size() - 1, 400.0, 1600.0, 0.2, 0.8}, cam);
  cam.height = rng.LogUniform(2.0, 30.0);
  cam.pitch_deg = rng.Uniform(-10.0, 5.0);
  if (rng.Chance(0.5)) AddRunway(rng, scene);
  if (rng.Chance(0.3)) AddRidge(rng, cam.height, scene);
  return FamilySpec{.kinds = {{"tower", 0.2},
                              {"pole", 0.2},
                              {"building", 0.2},
                              {"aircraft", 0.25},
                              {"drone", 0.15}},
                    .z_lo = 15.0,
                    .z_hi = 400.0,
                    .parked = 0.3};
}

// "long_range": a telephoto rig near the ground, in haze; far aircraft, towers and buildings.
FamilySpec SetUpLongRange(Rng& rng, Camera& cam, Scene& scene) {
  DrawRig(rng, {4, AllSizes().size() - 1, 2000.0, 6000.0, 0.3, 1.0}, cam);
  cam.height = rng.Uniform(2.0, 20.0);
  cam.pitch_deg = rng.Uniform(0.0, 5.0);
  // Haze: a pale, flat sky, faint ground texture, faint clouds.
  scene.sky_horizon = rng.Uniform(0.75, 0.95);
  scene.sky_top = scene.sky_horizon - rng.Uniform(0.0, 0.12);
  scene.ground_albedo = rng.Uniform(0.45, 0.65);
  scene.ground_contrast = rng.Uniform(0.03, 0.15);
  scene.ground_texture_cell_m = rng.LogUniform(0.5, 3.0);
  scene.cloud_grey = std::clamp(scene.cloud_grey, -0.1, 0.1);
  return FamilySpec{.kinds = {{"aircraft", 0.7}, {"tower", 0.15}, {"building", 0.15}},
                    .z_lo = 200.0,
                    .z_hi = 1500.0,
                    .contrast_hi = 0.5,
                    .prefer_sky = true};
}

// "close": a wide-angle rig a few metres up; drones, poles and small balloons nearby.
FamilySpec SetUpClose(Rng& rng, Camera& cam) {
  DrawRig(rng, {0, 4, 300.0, 600.0, 0.1, 0.3}, cam);
  cam.height = rng.Uniform(1.5, 10.0);
  cam.pitch_deg = rng.Uniform(-5.0, 10.0);
  return FamilySpec{.kinds = {{"drone", 0.5}, {"pole", 0.35}, {"balloon", 0.15}},
                    .z_lo = 5.0,
                    .z_hi = 40.0,
                    .scale = 0.5};
}

// The rig, sky, ground and sensor of the family; returns its placement spec.
FamilySpec SetUpFamily(const std::string& family, Rng& rng, Camera& cam, SyntheticOptions& o) {
  Scene& scene = o.scene;
  scene = Scene{};
  // Sky and ground defaults, changed per family.
  DrawSkyAndGround(rng, scene);
  FamilySpec spec;
  if (family == "sky") {
    spec = SetUpSky(rng, cam);
  } else if (family == "airfield") {
    spec = SetUpAirfield(rng, cam, scene);
  } else if (family == "long_range") {
    spec = SetUpLongRange(rng, cam, scene);
  } else if (family == "close") {
    spec = SetUpClose(rng, cam);
  } else {
    throw std::invalid_argument("unknown random scene family '" + family + "'");
  }
  cam.Finish();
  scene.camera_height_m = cam.height;
  scene.camera_pitch_deg = cam.pitch_deg;
  o.width = cam.w;
  o.height = cam.h;
  o.f_px = cam.f;
  o.baseline_m = cam.baseline;
  o.fps = kFps;
  o.noise_sigma = rng.Uniform(1.0, 6.0);
  o.blur_sigma_px = rng.Chance(0.5) ? rng.Uniform(0.3, 1.5) : 0.0;
  o.right_gain = rng.Uniform(0.85, 1.15);
  o.vignetting = rng.Uniform(0.0, 0.3);
  o.right_vertical_shift_px = rng.Uniform(-0.5, 0.5);
  return spec;
}

double SkyGreyAt(const Scene& scene, const Camera& cam, double v) {
  const double horizon = cam.HorizonRow();
  if (v >= horizon) return scene.sky_horizon;
  const double frac = std::min(1.0, (horizon - v) / cam.cy);
  return scene.sky_horizon + (scene.sky_top - scene.sky_horizon) * frac;
}

// What placing the obstacles of one scene needs: the rig, the family's spec, the usable camera
// depths and the sequence's last time.
struct Placing {
  const Camera& cam;
  const FamilySpec& spec;
  double z_lo, z_hi;
  double t_end;
};

// Where an obstacle goes in the image, and at what camera depth.
struct ImageSpot {
  double u = 0, v = 0, z = 0;
  bool overlapping = false;  // partly over an earlier obstacle
};

// Draws obstacle k's image spot and depth: anywhere (above the horizon where the family prefers
// the sky), or sometimes partly over an earlier airborne obstacle of `placed`, at another range.
ImageSpot DrawSpot(Rng& rng, const Placing& p, int k, bool standing, const RandomScene& placed) {
  const Camera& cam = p.cam;
  ImageSpot spot;
  spot.z = rng.LogUniform(p.z_lo, p.z_hi);
  spot.u = rng.Uniform(0.12, 0.88) * cam.w;
  const double horizon = cam.HorizonRow();
  if (!standing && k > 0 && rng.Chance(0.3)) {
    const int j = rng.Int(0, k - 1);
    const RandomObstacleInfo& prev = placed.obstacles[static_cast<size_t>(j)];
    if (!prev.standing) {
      const Obstacle& pob = placed.scenario.options.scene.obstacles[static_cast<size_t>(j)];
      const cv::Point2d c = cam.Project(pob.path.start);
      const double ratio = rng.Chance(0.5) ? rng.Uniform(1.4, 3.0) : 1.0 / rng.Uniform(1.4, 3.0);
      spot.z = std::clamp(prev.depth_m * ratio, p.z_lo, p.z_hi);
      const double size_px = cam.f * prev.extent_m / prev.depth_m;
      spot.u = c.x + rng.Uniform(-0.6, 0.6) * size_px;
      spot.v = c.y + rng.Uniform(-0.4, 0.4) * size_px;
      spot.overlapping = true;
    }
  }
  if (!spot.overlapping) {
    double v_hi = 0.9 * cam.h;
    if (p.spec.prefer_sky) v_hi = std::min(v_hi, horizon - 0.03 * cam.h);
    if (v_hi < 0.1 * cam.h + 1) v_hi = 0.9 * cam.h;
    spot.v = rng.Uniform(0.1 * cam.h, v_hi);
  }
  return spot;
}

// Draws an airborne obstacle's velocity (world, m/s) at camera depth `depth`, and its image speed
// (px per frame) into speed_px: aircraft cross or approach along their heading, balloons drift,
// drones fly any way.
cv::Vec3d DrawVelocity(Rng& rng, const Camera& cam, const std::string& kind, const Shape& shape,
                       double depth, double& speed_px) {
  cv::Vec3d velocity(0, 0, 0);
  const double m_per_px = depth / cam.f;
  if (kind == "aircraft" && shape.heading_axis == 2) {
    velocity[2] = -shape.heading_sign * depth * rng.Uniform(0.005, 0.02) * kFps;
    speed_px = rng.Uniform(0.0, 1.0);
    velocity[0] = (rng.Chance(0.5) ? 1 : -1) * speed_px * kFps * m_per_px;
  } else if (kind == "aircraft") {
    speed_px = rng.Uniform(0.5, 3.0);
    velocity[0] = shape.heading_sign * speed_px * kFps * m_per_px;
  } else if (kind == "balloon") {
    speed_px = rng.Uniform(0.2, 1.0);
    velocity[0] = (rng.Chance(0.5) ? 1 : -1) * speed_px * kFps * m_per_px;
    velocity[1] = rng.Uniform(-0.3, 0.3) * speed_px * kFps * m_per_px;
  } else {
    speed_px = rng.Uniform(0.5, 3.0);
    const double angle = rng.Uniform(0.0, 2.0 * kPi);
    velocity[0] = std::cos(angle) * speed_px * kFps * m_per_px;
    velocity[1] = std::sin(angle) * speed_px * kFps * m_per_px;
    velocity[2] = rng.Uniform(-0.01, 0.01) * depth * kFps;
  }
  return velocity;
}

// Whether the obstacle is mostly in frame, big enough to be seen and (airborne) clear of the
// ground at both ends of the sequence.
bool StaysInView(const Placing& p, const Shape& shape, const cv::Vec3d& position,
                 const cv::Vec3d& velocity) {
  bool ok = true;
  for (const double t : {0.0, p.t_end}) {
    const cv::Vec3d at = position + velocity * t;
    if (!shape.standing && at[1] + shape.hi[1] > p.cam.height - 0.2) ok = false;
    const cv::Rect2d r = p.cam.ProjectBox(at + shape.lo, at + shape.hi);
    if (p.cam.InFrameFraction(r) < 0.6 || std::max(r.width, r.height) < 6.0) ok = false;
  }
  return ok;
}

// One attempt at obstacle k of `placed`'s scene: a kind, a shape, a spot, a motion and a contrast
// against the background at its centre row. False (ob and info untouched) when it does not fit:
// in the ground, out of the disparity range, or not in view.
bool TryObstacle(Rng& rng, const Placing& p, int k, const RandomScene& placed, Obstacle& ob,
                 RandomObstacleInfo& info) {
  const Camera& cam = p.cam;
  const Scene& scene = placed.scenario.options.scene;
  const std::string kind = PickKind(rng, p.spec);
  Shape shape = MakeShape(rng, kind, p.spec);
  const bool standing = shape.standing;
  const ImageSpot spot = DrawSpot(rng, p, k, standing, placed);
  cv::Vec3d position;
  if (standing) {
    // World z about z; the base on the ground.
    const cv::Vec3d at = cam.BackProject(spot.u, cam.cy, spot.z);
    position = cv::Vec3d(at[0], cam.height - shape.hi[1], at[2]);
  } else {
    position = cam.BackProject(spot.u, spot.v, spot.z);
    if (position[1] + shape.hi[1] > cam.height - 0.5) return false;  // in the ground
  }
  const cv::Vec3d centre = position + (shape.lo + shape.hi) * 0.5;
  const double depth = cam.ToCam(centre)[2];
  if (!(depth > 1.0)) return false;
  const double disparity = cam.fb() / depth;
  if (disparity < 3.0 || disparity > cam.w / 12.0) return false;
  double speed_px = 0;
  const cv::Vec3d velocity =
      standing ? cv::Vec3d(0, 0, 0) : DrawVelocity(rng, cam, kind, shape, depth, speed_px);
  if (!StaysInView(p, shape, position, velocity)) return false;

  // Contrast against the background at the centre row.
  const double v_centre = cam.Project(centre).y;
  const bool against_sky = v_centre < cam.HorizonRow();
  const double bg = against_sky ? SkyGreyAt(scene, cam, v_centre) : scene.ground_albedo;
  const double c = rng.Uniform(p.spec.contrast_lo, p.spec.contrast_hi);
  bool darker = rng.Chance(0.7);
  if (1.0 - bg < 0.15) darker = true;
  if (bg < 0.15) darker = false;
  const double albedo = darker ? bg * (1.0 - c) : bg + c * (1.0 - bg);

  ob = Obstacle{};
  ob.id = k + 1;
  ob.kind = kind;
  ob.name = kind + "-" + std::to_string(k + 1);
  ob.parts = shape.parts;
  ob.size_m = shape.hi - shape.lo;
  ob.albedo = std::clamp(albedo, 0.0, 1.0);
  ob.contrast = std::clamp(c * rng.Uniform(0.2, 0.4), 0.0, 1.0);
  ob.texture_cell_m =
      std::max(shape.extent_m * rng.Uniform(0.015, 0.05), depth / cam.f * rng.Uniform(1.5, 4.0));
  ob.path.kind = standing ? Path::Kind::kStatic : Path::Kind::kLinear;
  ob.path.start = position;
  ob.path.velocity_mps = velocity;
  ob.path.period_s = 0.0;

  info = RandomObstacleInfo{};
  info.id = ob.id;
  info.kind = kind;
  info.depth_m = depth;
  info.range_m = cv::norm(centre);
  info.disparity_px = disparity;
  info.extent_m = shape.extent_m;
  info.contrast = c;
  info.grey_step = ob.albedo - bg;
  info.background_grey = bg;
  info.standing = standing;
  info.overlapping = spot.overlapping;
  info.speed_px_per_frame = speed_px;
  return true;
}

// The scenario's description: the rig and how many obstacles.
std::string Describe(const std::string& family, uint64_t seed, const SyntheticOptions& o,
                     const Camera& cam) {
  return "random '" + family + "' scene " + std::to_string(seed) + ": " + std::to_string(o.width) +
         "x" + std::to_string(o.height) +
         ", f = " + std::to_string(static_cast<int>(std::lround(o.f_px))) +
         " px, B = " + std::to_string(o.baseline_m).substr(0, 4) + " m, camera " +
         std::to_string(static_cast<int>(std::lround(cam.height))) + " m up, pitch " +
         std::to_string(static_cast<int>(std::lround(cam.pitch_deg))) + " deg, " +
         std::to_string(o.scene.obstacles.size()) + " obstacles";
}

}  // namespace

const std::vector<std::string>& RandomSceneFamilies() {
  static const std::vector<std::string> families = {"sky", "airfield", "long_range", "close"};
  return families;
}

RandomScene GenerateRandomScene(const std::string& family, uint64_t seed) {
  Rng rng(SplitMix64(seed ^ SplitMix64(HashString(family))));
  RandomScene out;
  out.family = family;
  out.seed = seed;
  Scenario& sc = out.scenario;
  sc.name = family + "-" + std::to_string(seed);
  SyntheticOptions& o = sc.options;
  Camera cam;
  // The rig must leave a usable range of depths: disparity 3 .. width / 12 px within the
  // family's depths.
  FamilySpec spec;
  double z_lo = 0, z_hi = 0;
  for (int attempt = 0; attempt < 50; ++attempt) {
    spec = SetUpFamily(family, rng, cam, o);
    z_lo = std::max(spec.z_lo, cam.fb() / (cam.w / 12.0));
    z_hi = std::min(spec.z_hi, cam.fb() / 3.0);
    if (z_hi > z_lo * 1.3) break;
  }
  o.seed = SplitMix64(rng.Bits());
  sc.frames = rng.Int(4, 6);
  Scene& scene = o.scene;
  const Placing placing{cam, spec, z_lo, z_hi, (sc.frames - 1) / kFps};

  const int n = rng.Int(1, 5);
  for (int k = 0; k < n; ++k) {
    Obstacle ob;
    RandomObstacleInfo info;
    bool placed = false;
    for (int attempt = 0; attempt < 60 && !placed; ++attempt) {
      placed = TryObstacle(rng, placing, k, out, ob, info);
    }
    if (!placed) continue;
    ob.id = static_cast<int>(scene.obstacles.size()) + 1;
    ob.name = ob.kind + "-" + std::to_string(ob.id);
    info.id = ob.id;
    scene.obstacles.push_back(std::move(ob));
    out.obstacles.push_back(std::move(info));
  }
  sc.description = Describe(family, seed, o, cam);
  return out;
}

Scenario RandomScenario(const std::string& family, uint64_t seed) {
  return GenerateRandomScene(family, seed).scenario;
}

Scenario RandomScenario(uint64_t seed) {
  const std::vector<std::string>& families = RandomSceneFamilies();
  return RandomScenario(families[SplitMix64(seed) % families.size()], seed);
}

}  // namespace stevi::drivers
