#include "drivers/synthetic/random_scenes.h"

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

uint64_t SplitMix64(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

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

constexpr auto kBox = ObstaclePart::Shape::kBox;
constexpr auto kEllipsoid = ObstaclePart::Shape::kEllipsoid;

// A fixed-wing aircraft: fuselage (box or ellipsoid), wings, tailplane and fin; length in metres.
Shape Aircraft(Rng& rng, double length, bool standing) {
  Shape s;
  s.kind = "aircraft";
  s.standing = standing;
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
      return std::make_pair(cv::Vec3d(a * s.heading_sign, y, across),
                            cv::Vec3d(size_along_across[0], size_along_across[1],
                                      size_along_across[2]));
    }
    return std::make_pair(cv::Vec3d(across, y, a * s.heading_sign),
                          cv::Vec3d(size_along_across[2], size_along_across[1],
                                    size_along_across[0]));
  };
  auto add = [&](ObstaclePart::Shape shape, double a, double y, double across, cv::Vec3d size) {
    const auto [offset, sz] = along(a, y, across, size);
    AddPart(s, shape, offset, sz);
  };
  add(rng.Chance(0.5) ? kEllipsoid : kBox, 0.0, 0.0, 0.0, {L, D, D});
  add(kBox, L * 0.05, wing_y, 0.0, {chord, thick, span});
  add(kBox, -L * 0.42, -D * 0.2, 0.0, {chord * 0.7, thick, span * 0.35});
  add(kBox, -L * 0.42, -D * 0.5 - fin_h * 0.5, 0.0, {chord * 0.9, fin_h, thick});
  FinishShape(s);
  return s;
}

// A multirotor: body, two crossed arms and four rotor discs; span in metres.
Shape Drone(Rng& rng, double span) {
  Shape s;
  s.kind = "drone";
  const double W = span;
  AddPart(s, rng.Chance(0.5) ? kEllipsoid : kBox, {0, 0, 0}, {W * 0.3, W * 0.16, W * 0.3});
  AddPart(s, kBox, {0, -W * 0.03, 0}, {W, W * 0.04, W * 0.05});
  AddPart(s, kBox, {0, -W * 0.03, 0}, {W * 0.05, W * 0.04, W});
  for (const auto& [x, z] : std::array<std::pair<double, double>, 4>{
           {{W * 0.5, 0.0}, {-W * 0.5, 0.0}, {0.0, W * 0.5}, {0.0, -W * 0.5}}}) {
    AddPart(s, kEllipsoid, {x, -W * 0.07, z}, {W * 0.32, W * 0.03, W * 0.32});
  }
  if (rng.Chance(0.5)) AddPart(s, kBox, {0, W * 0.12, 0}, {W * 0.2, W * 0.1, W * 0.12});  // camera
  FinishShape(s);
  return s;
}

// A balloon: an ellipsoid envelope, and a basket under the large ones; diameter in metres.
Shape Balloon(Rng& rng, double diameter) {
  Shape s;
  s.kind = "balloon";
  const double Dm = diameter;
  AddPart(s, kEllipsoid, {0, 0, 0}, {Dm, Dm * rng.Uniform(1.0, 1.25), Dm});
  if (Dm > 5.0) AddPart(s, kBox, {0, Dm * 0.78, 0}, {Dm * 0.12, Dm * 0.1, Dm * 0.12});
  FinishShape(s);
  return s;
}

// A tower standing on the ground: three tapering sections and a mast; height in metres.
Shape Tower(Rng& rng, double height) {
  Shape s;
  s.kind = "tower";
  s.standing = true;
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
  FinishShape(s);
  return s;
}

// A pole standing on the ground, with a cross-arm half the time; height in metres.
Shape Pole(Rng& rng, double height) {
  Shape s;
  s.kind = "pole";
  s.standing = true;
  const double w = rng.Uniform(0.2, 0.5);
  AddPart(s, kBox, {0, -height / 2, 0}, {w, height, w});
  if (rng.Chance(0.5)) AddPart(s, kBox, {0, -height * 0.92, 0}, {w * 8, w * 0.5, w * 0.6});
  FinishShape(s);
  return s;
}

// A building standing on the ground, sometimes with a smaller box on its roof; width in metres.
Shape Building(Rng& rng, double width) {
  Shape s;
  s.kind = "building";
  s.standing = true;
  const double W = width, H = width * rng.Uniform(0.3, 0.9), D = width * rng.Uniform(0.5, 1.0);
  AddPart(s, kBox, {0, -H / 2, 0}, {W, H, D});
  if (rng.Chance(0.5)) {
    const double rh = H * rng.Uniform(0.15, 0.35);
    AddPart(s, kBox, {W * rng.Uniform(-0.2, 0.2), -H - rh / 2, 0}, {W * 0.35, rh, D * 0.5});
  }
  FinishShape(s);
  return s;
}

// A family: its rig, environment and what it places.
struct FamilySpec {
  std::vector<std::pair<std::string, double>> kinds;  // kind and weight
  double z_lo = 5, z_hi = 1500;                       // camera depth range, metres
  double contrast_lo = 0.1, contrast_hi = 1.0;
  bool prefer_sky = false;      // airborne obstacles above the horizon
  double parked = 0.0;          // the chance that an aircraft stands on the ground
  double scale = 1.0;           // size factor (close: smaller things)
};

const std::vector<cv::Size>& AllSizes() {
  static const std::vector<cv::Size> sizes = {{640, 480},   {752, 480},   {800, 600},
                                              {1024, 768},  {1280, 720},  {1280, 1024},
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

Shape MakeShape(Rng& rng, const std::string& kind, const FamilySpec& spec) {
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

// The rig, sky, ground and sensor of the family; returns its placement spec.
FamilySpec SetUpFamily(const std::string& family, Rng& rng, Camera& cam, SyntheticOptions& o) {
  Scene& scene = o.scene;
  scene = Scene{};
  FamilySpec spec;
  cv::Size size;
  // Sky and ground defaults, changed per family below.
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
  if (family == "sky") {
    size = PickSize(rng, 0, AllSizes().size() - 1);
    cam.f = rng.LogUniform(500.0, 2500.0);
    cam.baseline = rng.Uniform(0.2, 1.0);
    if (rng.Chance(0.6)) {
      cam.height = rng.LogUniform(60.0, 400.0);
      cam.pitch_deg = rng.Uniform(0.0, 12.0);
    } else {
      cam.height = rng.Uniform(2.0, 30.0);
      cam.pitch_deg = rng.Uniform(10.0, 25.0);
    }
    spec.kinds = {{"aircraft", 0.4}, {"drone", 0.35}, {"balloon", 0.25}};
    spec.z_lo = 10.0;
    spec.z_hi = 800.0;
    spec.prefer_sky = true;
  } else if (family == "airfield") {
    size = PickSize(rng, 0, AllSizes().size() - 1);
    cam.f = rng.LogUniform(400.0, 1600.0);
    cam.baseline = rng.Uniform(0.2, 0.8);
    cam.height = rng.LogUniform(2.0, 30.0);
    cam.pitch_deg = rng.Uniform(-10.0, 5.0);
    spec.kinds = {{"tower", 0.2},    {"pole", 0.2},  {"building", 0.2},
                  {"aircraft", 0.25}, {"drone", 0.15}};
    spec.z_lo = 15.0;
    spec.z_hi = 400.0;
    spec.parked = 0.3;
    if (rng.Chance(0.5)) {  // a runway along z, with edge lines and a dashed centreline
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
    if (rng.Chance(0.3)) {  // a far ridge
      const int n = rng.Int(1, 3);
      for (int k = 0; k < n; ++k) {
        Hill hill;
        const double z = rng.Uniform(400.0, 900.0);
        hill.radii_m = {rng.Uniform(80.0, 250.0), rng.Uniform(20.0, 60.0), rng.Uniform(40.0, 90.0)};
        hill.centre_m = {rng.Uniform(-400.0, 400.0), cam.height + rng.Uniform(0.0, 10.0), z};
        hill.albedo = rng.Uniform(0.4, 0.55);
        hill.contrast = rng.Uniform(0.1, 0.25);
        hill.texture_cell_m = rng.Uniform(1.0, 3.0);
        scene.hills.push_back(hill);
      }
    }
  } else if (family == "long_range") {
    size = PickSize(rng, 4, AllSizes().size() - 1);
    cam.f = rng.LogUniform(2000.0, 6000.0);
    cam.baseline = rng.Uniform(0.3, 1.0);
    cam.height = rng.Uniform(2.0, 20.0);
    cam.pitch_deg = rng.Uniform(0.0, 5.0);
    spec.kinds = {{"aircraft", 0.7}, {"tower", 0.15}, {"building", 0.15}};
    spec.z_lo = 200.0;
    spec.z_hi = 1500.0;
    spec.contrast_hi = 0.5;
    spec.prefer_sky = true;
    // Haze: a pale, flat sky, faint ground texture, faint clouds.
    scene.sky_horizon = rng.Uniform(0.75, 0.95);
    scene.sky_top = scene.sky_horizon - rng.Uniform(0.0, 0.12);
    scene.ground_albedo = rng.Uniform(0.45, 0.65);
    scene.ground_contrast = rng.Uniform(0.03, 0.15);
    scene.ground_texture_cell_m = rng.LogUniform(0.5, 3.0);
    scene.cloud_grey = std::clamp(scene.cloud_grey, -0.1, 0.1);
  } else if (family == "close") {
    size = PickSize(rng, 0, 4);
    cam.f = rng.LogUniform(300.0, 600.0);
    cam.baseline = rng.Uniform(0.1, 0.3);
    cam.height = rng.Uniform(1.5, 10.0);
    cam.pitch_deg = rng.Uniform(-5.0, 10.0);
    spec.kinds = {{"drone", 0.5}, {"pole", 0.35}, {"balloon", 0.15}};
    spec.z_lo = 5.0;
    spec.z_hi = 40.0;
    spec.scale = 0.5;
  } else {
    throw std::invalid_argument("unknown random scene family '" + family + "'");
  }
  cam.w = size.width;
  cam.h = size.height;
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
  const double t_end = (sc.frames - 1) / kFps;
  const double max_disparity = cam.w / 12.0;

  const int n = rng.Int(1, 5);
  for (int k = 0; k < n; ++k) {
    Obstacle best_ob;
    RandomObstacleInfo best_info;
    bool placed = false;
    for (int attempt = 0; attempt < 60 && !placed; ++attempt) {
      const std::string kind = PickKind(rng, spec);
      Shape shape = MakeShape(rng, kind, spec);
      const bool standing = shape.standing;
      double z = rng.LogUniform(z_lo, z_hi);
      double u = rng.Uniform(0.12, 0.88) * cam.w;
      const double horizon = cam.HorizonRow();
      double v = 0;
      bool overlapping = false;
      // Sometimes partly over an earlier airborne obstacle, at another range.
      if (!standing && k > 0 && rng.Chance(0.3)) {
        const int j = rng.Int(0, k - 1);
        const RandomObstacleInfo& prev = out.obstacles[static_cast<size_t>(j)];
        if (!prev.standing) {
          const Obstacle& pob = scene.obstacles[static_cast<size_t>(j)];
          const cv::Point2d c = cam.Project(pob.path.start);
          const double ratio = rng.Chance(0.5) ? rng.Uniform(1.4, 3.0) : 1.0 / rng.Uniform(1.4, 3.0);
          z = std::clamp(prev.depth_m * ratio, z_lo, z_hi);
          const double size_px = cam.f * prev.extent_m / prev.depth_m;
          u = c.x + rng.Uniform(-0.6, 0.6) * size_px;
          v = c.y + rng.Uniform(-0.4, 0.4) * size_px;
          overlapping = true;
        }
      }
      if (!overlapping) {
        double v_hi = 0.9 * cam.h;
        if (spec.prefer_sky) v_hi = std::min(v_hi, horizon - 0.03 * cam.h);
        if (v_hi < 0.1 * cam.h + 1) v_hi = 0.9 * cam.h;
        v = rng.Uniform(0.1 * cam.h, v_hi);
      }
      cv::Vec3d position;
      if (standing) {
        // World z about z; the base on the ground.
        const cv::Vec3d p = cam.BackProject(u, cam.cy, z);
        position = cv::Vec3d(p[0], cam.height - shape.hi[1], p[2]);
      } else {
        position = cam.BackProject(u, v, z);
        if (position[1] + shape.hi[1] > cam.height - 0.5) continue;  // in the ground
      }
      const cv::Vec3d centre = position + (shape.lo + shape.hi) * 0.5;
      const double depth = cam.ToCam(centre)[2];
      if (!(depth > 1.0)) continue;
      const double disparity = cam.fb() / depth;
      if (disparity < 3.0 || disparity > max_disparity) continue;
      // Motion.
      cv::Vec3d velocity(0, 0, 0);
      double speed_px = 0;
      if (!standing) {
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
      }
      // Mostly in frame and big enough to be seen at both ends of the sequence.
      bool ok = true;
      for (const double t : {0.0, t_end}) {
        const cv::Vec3d p = position + velocity * t;
        if (!standing && p[1] + shape.hi[1] > cam.height - 0.2) ok = false;
        const cv::Rect2d r = cam.ProjectBox(p + shape.lo, p + shape.hi);
        if (cam.InFrameFraction(r) < 0.6 || std::max(r.width, r.height) < 6.0) ok = false;
      }
      if (!ok) continue;

      // Contrast against the background at the centre row.
      const double v_centre = cam.Project(centre).y;
      const bool against_sky = v_centre < cam.HorizonRow();
      const double bg = against_sky ? SkyGreyAt(scene, cam, v_centre) : scene.ground_albedo;
      const double c = rng.Uniform(spec.contrast_lo, spec.contrast_hi);
      bool darker = rng.Chance(0.7);
      if (1.0 - bg < 0.15) darker = true;
      if (bg < 0.15) darker = false;
      const double albedo = darker ? bg * (1.0 - c) : bg + c * (1.0 - bg);

      Obstacle ob;
      ob.id = k + 1;
      ob.kind = kind;
      ob.name = kind + "-" + std::to_string(k + 1);
      ob.parts = shape.parts;
      ob.size_m = shape.hi - shape.lo;
      ob.albedo = std::clamp(albedo, 0.0, 1.0);
      ob.contrast = std::clamp(c * rng.Uniform(0.2, 0.4), 0.0, 1.0);
      ob.texture_cell_m = std::max(shape.extent_m * rng.Uniform(0.015, 0.05),
                                   depth / cam.f * rng.Uniform(1.5, 4.0));
      ob.path.kind = standing ? Path::Kind::kStatic : Path::Kind::kLinear;
      ob.path.start = position;
      ob.path.velocity_mps = velocity;
      ob.path.period_s = 0.0;

      RandomObstacleInfo info;
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
      info.overlapping = overlapping;
      info.speed_px_per_frame = speed_px;
      best_ob = std::move(ob);
      best_info = std::move(info);
      placed = true;
    }
    if (!placed) continue;
    best_ob.id = static_cast<int>(scene.obstacles.size()) + 1;
    best_ob.name = best_ob.kind + "-" + std::to_string(best_ob.id);
    best_info.id = best_ob.id;
    scene.obstacles.push_back(std::move(best_ob));
    out.obstacles.push_back(std::move(best_info));
  }
  sc.description = "random '" + family + "' scene " + std::to_string(seed) + ": " +
                   std::to_string(o.width) + "x" + std::to_string(o.height) +
                   ", f = " + std::to_string(static_cast<int>(std::lround(o.f_px))) +
                   " px, B = " + std::to_string(o.baseline_m).substr(0, 4) + " m, camera " +
                   std::to_string(static_cast<int>(std::lround(cam.height))) + " m up, pitch " +
                   std::to_string(static_cast<int>(std::lround(cam.pitch_deg))) + " deg, " +
                   std::to_string(scene.obstacles.size()) + " obstacles";
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
