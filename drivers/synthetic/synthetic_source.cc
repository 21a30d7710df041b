#include "drivers/synthetic/synthetic_source.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <sstream>
#include <utility>

#include <opencv2/core/utility.hpp>

namespace stevi::drivers {
namespace {

// Rays must hit a surface farther than this (metres) from the camera centre.
constexpr double kNearM = 0.01;
// Grey factor per face orientation, so that box edges show.
constexpr float kShadeFront = 1.0f;   // the face towards the camera (normal -z)
constexpr float kShadeSide = 0.8f;    // faces of normal +-x
constexpr float kShadeTop = 1.1f;     // normal -y (seen from above)
constexpr float kShadeBottom = 0.7f;  // normal +y (the underside, seen from below)
// Texture octaves: cell sizes 1, 3 and 9 times the finest cell, and their weights.
constexpr int kOctaves = 3;
constexpr double kOctaveScale[kOctaves] = {1.0, 3.0, 9.0};
constexpr float kOctaveWeight[kOctaves] = {0.5f, 0.3f, 0.2f};
// Hills are lit by a distant light from above, left and behind the camera: grey factor
// kHillAmbient + kHillDiffuse * (normal . light), so that slopes and silhouettes show.
constexpr double kHillAmbient = 0.8;
constexpr double kHillDiffuse = 0.35;
constexpr double kHillLight[3] = {-0.4, -1.0, -0.5};  // towards the light (normalised at use)
// Texture footprints on slanted hill surfaces grow as 1 / cos(incidence), capped here.
constexpr double kHillMaxStretch = 50.0;
// Triplanar texture blend: a plane counts where its squared normal component exceeds this
// fraction of the largest.
constexpr double kHillBlendFloor = 0.6;

uint64_t SplitMix64(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

uint64_t Mix(uint64_t a, uint64_t b) { return SplitMix64(a ^ SplitMix64(b)); }

inline uint32_t Fmix32(uint32_t h) {
  h ^= h >> 16;
  h *= 0x85EBCA6Bu;
  h ^= h >> 13;
  h *= 0xC2B2AE35u;
  h ^= h >> 16;
  return h;
}

// Hashed lattice value in [0, 1).
inline float Lattice(uint32_t seed, int64_t i, int64_t j) {
  const uint32_t h = Fmix32(seed + static_cast<uint32_t>(i) * 0x9E3779B1u +
                            static_cast<uint32_t>(j) * 0x85EBCA77u);
  return static_cast<float>(h >> 8) * (1.0f / 16777216.0f);
}

inline float SmoothStep(float x) { return x * x * (3.0f - 2.0f * x); }

// Smooth (C1) value noise in [0, 1) at lattice coordinates (s, t).
inline float ValueNoise(uint32_t seed, double s, double t) {
  const double fs = std::floor(s);
  const double ft = std::floor(t);
  const auto i = static_cast<int64_t>(fs);
  const auto j = static_cast<int64_t>(ft);
  const float ws = SmoothStep(static_cast<float>(s - fs));
  const float wt = SmoothStep(static_cast<float>(t - ft));
  const float v00 = Lattice(seed, i, j);
  const float v10 = Lattice(seed, i + 1, j);
  const float v01 = Lattice(seed, i, j + 1);
  const float v11 = Lattice(seed, i + 1, j + 1);
  const float a = v00 + (v10 - v00) * ws;
  const float b = v01 + (v11 - v01) * ws;
  return a + (b - a) * wt;
}

// Multi-octave texture at surface coordinates (s, t) metres, zero-mean, within +-0.5.
// Octaves finer than 2 px fade out (gone at 1 px): footprint_m is the size of one pixel on the
// surface. It depends on the depth only, so both views shade a world point alike.
inline float Texture(uint32_t seed, double s, double t, double cell_m, double footprint_m) {
  float sum = 0.0f;
  for (int k = 0; k < kOctaves; ++k) {
    const double cell = cell_m * kOctaveScale[k];
    const float fade = static_cast<float>(std::clamp(cell / footprint_m - 1.0, 0.0, 1.0));
    if (fade <= 0.0f) continue;
    const uint32_t octave_seed = seed + static_cast<uint32_t>(k) * 0x632BE5ABu;
    // Offsets keep the lattices of the octaves from lining up.
    const float n = ValueNoise(octave_seed, s / cell + 0.37 * k, t / cell + 0.61 * k);
    sum += kOctaveWeight[k] * fade * (n - 0.5f);
  }
  return sum;
}

// One obstacle at the frame's time.
struct Box {
  int id = 0;
  cv::Vec3d lo, hi, centre;  // corners and centre, world (= cam) frame, metres
  float albedo = 0, contrast = 0;
  double cell_m = 0;
  uint32_t seed[3] = {0, 0, 0};  // texture seed per face axis (x, y, z)
};

// Pixel range (inclusive) a box may cover in one view; empty when u0 > u1 or v0 > v1.
struct PixelRect {
  int u0 = 0, u1 = -1, v0 = 0, v1 = -1;
};

// Per-row visibility of one obstacle in the left image.
struct RowStat {
  int min_u = std::numeric_limits<int>::max();
  int max_u = -1;
  int count = 0;
};

// One hill, prepared for ray casting. Static over the sequence.
struct HillGeom {
  cv::Vec3d centre;
  cv::Vec3d inv_r;           // 1 / radii
  double origin_s[2][3] = {};  // per view: (camera centre - hill centre) / radii
  double c[2] = {0.0, 0.0};    // per view: |origin_s|^2 - 1 (> 0: the camera is outside)
  PixelRect rect[2];           // per view: pixel bounds of the part above the ground
  float albedo = 0, contrast = 0;
  double cell_m = 0;
  uint32_t seed = 0;
};

// The paint of one mark or dashed line, with its coverage of the current row (z footprint).
struct MarkCandidate {
  double x0, x1;     // x extent on the ground, metres
  double cover_z;    // fraction of the row's z footprint that the mark covers
  float albedo, contrast;
};

// Length of [z_start, z] covered by dashes of length dash starting every period metres at
// z_start (z >= z_start).
inline double DashedLength(double z, double z_start, double dash, double period) {
  const double s = z - z_start;
  const double k = std::floor(s / period);
  return k * dash + std::min(s - k * period, dash);
}

// Fraction of the ground interval [z0, z1] (z1 may be infinite) that a dashed line covers.
double DashedCoverZ(const DashedLine& line, double z0, double z1) {
  const double period = line.dash_m + line.gap_m;
  if (!std::isfinite(z1)) {
    return std::isfinite(line.z_end_m) ? 0.0 : line.dash_m / period;
  }
  const double a = std::max(z0, line.z_start_m);
  const double b = std::min(z1, line.z_end_m);
  if (!(b > a)) return 0.0;
  const double covered = DashedLength(b, line.z_start_m, line.dash_m, period) -
                         DashedLength(a, line.z_start_m, line.dash_m, period);
  return std::clamp(covered / (z1 - z0), 0.0, 1.0);
}

// Everything one frame's rows need; read-only while the rows render.
struct FrameSetup {
  std::vector<Box> boxes;
  std::vector<PixelRect> rects[2];  // per view: 0 left, 1 right
  double origin_x[2] = {0.0, 0.0};  // camera centre x per view, metres
  cv::Vec3d rig_offset{0.0, 0.0, 0.0};  // the moving rig's offset from its rest position
};

}  // namespace

struct SyntheticRenderer::Impl {
  SyntheticOptions options;
  double cx = 0, cy = 0;
  uint32_t ground_seed = 0;
  std::vector<std::array<uint32_t, 3>> face_seeds;  // per obstacle, per face axis
  std::vector<HillGeom> hills;                      // static terrain
  double hill_light[3] = {0.0, 0.0, 0.0};           // unit vector towards the light

  explicit Impl(SyntheticOptions o) : options(std::move(o)) {
    cx = options.width / 2.0;
    cy = options.height / 2.0;
    ground_seed = static_cast<uint32_t>(Mix(options.seed, 0x67726F756E64ull));  // "ground"
    for (const Obstacle& ob : options.scene.obstacles) {
      std::array<uint32_t, 3> s{};
      for (int axis = 0; axis < 3; ++axis) {
        s[axis] = static_cast<uint32_t>(
            Mix(options.seed, (static_cast<uint64_t>(static_cast<uint32_t>(ob.id)) << 2) | axis));
      }
      face_seeds.push_back(s);
    }
    const double light_norm =
        std::sqrt(kHillLight[0] * kHillLight[0] + kHillLight[1] * kHillLight[1] +
                  kHillLight[2] * kHillLight[2]);
    for (int k = 0; k < 3; ++k) hill_light[k] = kHillLight[k] / light_norm;
    const double h = options.scene.camera_height_m;
    for (size_t i = 0; i < options.scene.hills.size(); ++i) {
      const Hill& hill = options.scene.hills[i];
      HillGeom g;
      g.centre = hill.centre_m;
      for (int k = 0; k < 3; ++k) g.inv_r[k] = 1.0 / hill.radii_m[k];
      g.albedo = static_cast<float>(hill.albedo);
      g.contrast = static_cast<float>(hill.contrast);
      g.cell_m = hill.texture_cell_m;
      g.seed = static_cast<uint32_t>(Mix(options.seed, 0x68696C6C00000000ull + i));  // "hill"
      // The bounding box of the part above the ground (empty when the hill is buried).
      Box bounds;
      bounds.lo = hill.centre_m - hill.radii_m;
      bounds.hi = hill.centre_m + hill.radii_m;
      bounds.hi[1] = std::min(bounds.hi[1], h);
      for (int view = 0; view < 2; ++view) {
        const double ox = view == 0 ? 0.0 : options.baseline_m;
        const double rel[3] = {ox - g.centre[0], -g.centre[1], -g.centre[2]};
        double c = -1.0;
        for (int k = 0; k < 3; ++k) {
          g.origin_s[view][k] = rel[k] * g.inv_r[k];
          c += g.origin_s[view][k] * g.origin_s[view][k];
        }
        g.c[view] = c;
        // A camera inside a hill sees nothing of it.
        if (bounds.lo[1] < bounds.hi[1] && c > 0.0) g.rect[view] = Project(bounds, ox);
      }
      hills.push_back(g);
    }
  }

  double TimeOf(int64_t index) const { return static_cast<double>(index) / options.fps; }

  FrameSetup Setup(double t_s) const {
    FrameSetup setup;
    setup.origin_x[1] = options.baseline_m;
    setup.rig_offset = options.scene.RigOffsetAt(t_s);
    const auto& obstacles = options.scene.obstacles;
    for (size_t i = 0; i < obstacles.size(); ++i) {
      const Obstacle& ob = obstacles[i];
      Box box;
      box.id = ob.id;
      box.centre = ob.path.PositionAt(t_s) - setup.rig_offset;
      box.lo = box.centre - ob.size_m * 0.5;
      box.hi = box.centre + ob.size_m * 0.5;
      box.albedo = static_cast<float>(ob.albedo);
      box.contrast = static_cast<float>(ob.contrast);
      box.cell_m = ob.texture_cell_m;
      for (int axis = 0; axis < 3; ++axis) box.seed[axis] = face_seeds[i][axis];
      setup.boxes.push_back(box);
    }
    for (int view = 0; view < 2; ++view) {
      for (const Box& box : setup.boxes) {
        setup.rects[view].push_back(Project(box, setup.origin_x[view]));
      }
    }
    return setup;
  }

  // Conservative pixel bounds of a box seen from a camera centred at (ox, 0, 0).
  PixelRect Project(const Box& box, double ox) const {
    const int w = options.width, h = options.height;
    PixelRect r;
    if (box.hi[2] <= kNearM) return r;  // behind the camera
    if (box.lo[2] <= kNearM) return PixelRect{0, w - 1, 0, h - 1};
    const double f = options.f_px;
    double umin = std::numeric_limits<double>::infinity(), umax = -umin;
    double vmin = umin, vmax = -umin;
    for (double z : {box.lo[2], box.hi[2]}) {
      for (double x : {box.lo[0], box.hi[0]}) {
        const double u = cx + f * (x - ox) / z;
        umin = std::min(umin, u);
        umax = std::max(umax, u);
      }
      for (double y : {box.lo[1], box.hi[1]}) {
        const double v = cy + f * y / z;
        vmin = std::min(vmin, v);
        vmax = std::max(vmax, v);
      }
    }
    // Clamp in double first: far-off boxes must not overflow int.
    auto to_px = [](double x, int hi) {
      return static_cast<int>(std::clamp(x, -2.0, static_cast<double>(hi) + 2.0));
    };
    r.u0 = std::max(0, to_px(std::floor(umin) - 1, w));
    r.u1 = std::min(w - 1, to_px(std::ceil(umax) + 1, w));
    r.v0 = std::max(0, to_px(std::floor(vmin) - 1, h));
    r.v1 = std::min(h - 1, to_px(std::ceil(vmax) + 1, h));
    return r;
  }

  float SkyGrey(int v) const {
    const Scene& s = options.scene;
    if (v >= cy) return static_cast<float>(s.sky_horizon);
    const double frac = (cy - v) / cy;  // 1 at row 0, 0 at the horizon row
    return static_cast<float>(s.sky_horizon + (s.sky_top - s.sky_horizon) * frac);
  }

  // Grey of the hill surface point (x, y, z). A function of the world point alone, so both
  // views shade it alike: the texture is triplanar in world coordinates (blended by the normal),
  // its footprint the pixel size at depth z stretched by the incidence seen from the rig's
  // mid-baseline, and the light is fixed.
  float ShadeHill(const HillGeom& g, double x, double y, double z) const {
    double n[3] = {(x - g.centre[0]) * g.inv_r[0] * g.inv_r[0],
                   (y - g.centre[1]) * g.inv_r[1] * g.inv_r[1],
                   (z - g.centre[2]) * g.inv_r[2] * g.inv_r[2]};
    const double n_norm = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    for (double& c : n) c /= n_norm;
    const double w[3] = {0.5 * options.baseline_m - x, -y, -z};
    const double w_norm = std::sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
    const double incidence = std::abs(n[0] * w[0] + n[1] * w[1] + n[2] * w[2]) / w_norm;
    const double footprint = z / options.f_px * std::min(1.0 / incidence, kHillMaxStretch);
    // Triplanar weights: n_i^2 above 0.6 times the largest n_j^2, normalised. Continuous in the
    // normal, and only one or two planes are sampled per pixel (the texture is the cost).
    const double n2[3] = {n[0] * n[0], n[1] * n[1], n[2] * n[2]};
    const double floor2 = kHillBlendFloor * std::max({n2[0], n2[1], n2[2]});
    const double wx = std::max(0.0, n2[0] - floor2);
    const double wy = std::max(0.0, n2[1] - floor2);
    const double wz = std::max(0.0, n2[2] - floor2);
    const double w_sum = wx + wy + wz;
    float tex = 0.0f;
    if (wy > 0.0) {
      tex += static_cast<float>(wy / w_sum) * Texture(g.seed, x, z, g.cell_m, footprint);
    }
    if (wz > 0.0) {
      tex += static_cast<float>(wz / w_sum) * Texture(g.seed + 1u, x, y, g.cell_m, footprint);
    }
    if (wx > 0.0) {
      tex += static_cast<float>(wx / w_sum) * Texture(g.seed + 2u, z, y, g.cell_m, footprint);
    }
    const double lit = n[0] * hill_light[0] + n[1] * hill_light[1] + n[2] * hill_light[2];
    const auto shade = static_cast<float>(kHillAmbient + kHillDiffuse * lit);
    return shade * (g.albedo + 2.0f * g.contrast * tex);
  }

  // Ray-casts and shades row v of one view. `grey` (nullable) gets the 8-bit image row,
  // `disparity`, `ids` and `stats` (all nullable) the truth of the row.
  void RenderRow(const FrameSetup& setup, int view, int v, uint8_t* grey, float* disparity,
                 int* ids, RowStat* stats, cv::RNG* rng) const {
    const Scene& scene = options.scene;
    const double f = options.f_px;
    const double fb = options.f_px * options.baseline_m;
    const double ox = setup.origin_x[view];
    const double b = (v - cy) / f;  // ray y-direction (z-direction is 1, so t = depth)
    const float sky = SkyGrey(v);
    const double sigma = options.noise_sigma;

    // Boxes this row may see, with their y slab.
    struct Candidate {
      int index;
      int u0, u1;
      double ty_min, ty_max;
      bool y_enters_hi;
    };
    Candidate candidates[64];
    std::vector<Candidate> many;
    Candidate* cand = candidates;
    if (setup.boxes.size() > 64) {
      many.resize(setup.boxes.size());
      cand = many.data();
    }
    int n_cand = 0;
    for (size_t i = 0; i < setup.boxes.size(); ++i) {
      const PixelRect& r = setup.rects[view][i];
      if (v < r.v0 || v > r.v1 || r.u0 > r.u1) continue;
      const Box& box = setup.boxes[i];
      Candidate c{static_cast<int>(i), r.u0, r.u1, 0, 0, false};
      if (b != 0.0) {
        const double t1 = box.lo[1] / b, t2 = box.hi[1] / b;
        c.ty_min = std::min(t1, t2);
        c.ty_max = std::max(t1, t2);
        c.y_enters_hi = b < 0.0;
      } else {
        if (box.lo[1] > 0.0 || box.hi[1] < 0.0) continue;
        c.ty_min = -std::numeric_limits<double>::infinity();
        c.ty_max = std::numeric_limits<double>::infinity();
      }
      cand[n_cand++] = c;
    }

    // The ground, if this row looks down: the same depth across the row.
    const bool sees_ground = b > 0.0;
    const double ground_t = sees_ground ? scene.camera_height_m / b : 0.0;
    const double ground_footprint =
        sees_ground ? ground_t / f * std::max(1.0, ground_t / scene.camera_height_m) : 0.0;
    const float ground_albedo = static_cast<float>(scene.ground_albedo);
    const float ground_contrast = static_cast<float>(scene.ground_contrast);

    // Hills this row may see, with the row's terms of the ray-ellipsoid quadratic
    // A t^2 + 2 B t + C = 0 in the hill's scaled frame: A = (a/rx)^2 + a_row,
    // B = ox_s a / rx + b_row.
    struct HillCandidate {
      int index;
      int u0, u1;
      double a_row, b_row;
    };
    HillCandidate hill_candidates[16];
    std::vector<HillCandidate> many_hills;
    HillCandidate* hill_cand = hill_candidates;
    if (hills.size() > 16) {
      many_hills.resize(hills.size());
      hill_cand = many_hills.data();
    }
    int n_hill = 0;
    for (size_t i = 0; i < hills.size(); ++i) {
      const HillGeom& g = hills[i];
      const PixelRect& r = g.rect[view];
      if (v < r.v0 || v > r.v1 || r.u0 > r.u1) continue;
      const double by = b * g.inv_r[1];
      const double bz = g.inv_r[2];
      hill_cand[n_hill++] = HillCandidate{static_cast<int>(i), r.u0, r.u1, by * by + bz * bz,
                                          g.origin_s[view][1] * by + g.origin_s[view][2] * bz};
    }

    // Marks this row's ground may show (only to shade: the truth does not need them).
    MarkCandidate mark_candidates[32];
    std::vector<MarkCandidate> many_marks;
    MarkCandidate* mark_cand = mark_candidates;
    int n_mark = 0;
    const size_t n_paint = scene.marks.size() + scene.dashed_lines.size();
    if (grey != nullptr && sees_ground && n_paint > 0) {
      if (n_paint > 32) {
        many_marks.resize(n_paint);
        mark_cand = many_marks.data();
      }
      // The row's footprint on the ground: depths seen by rays through v - 0.5 .. v + 0.5.
      const double b_far = (v - 0.5 - cy) / f, b_near = (v + 0.5 - cy) / f;
      const double z_near = scene.camera_height_m / b_near;
      const double z_far =
          b_far > 0.0 ? scene.camera_height_m / b_far : std::numeric_limits<double>::infinity();
      for (const GroundMark& m : scene.marks) {
        const double mz0 = m.area_xz_m.y, mz1 = m.area_xz_m.y + m.area_xz_m.height;
        if (!std::isfinite(z_far)) continue;  // a finite mark covers none of an endless row
        const double covered = std::min(z_far, mz1) - std::max(z_near, mz0);
        if (!(covered > 0.0)) continue;
        mark_cand[n_mark++] = MarkCandidate{m.area_xz_m.x, m.area_xz_m.x + m.area_xz_m.width,
                                            covered / (z_far - z_near),
                                            static_cast<float>(m.albedo),
                                            static_cast<float>(m.contrast)};
      }
      for (const DashedLine& line : scene.dashed_lines) {
        const double cover = DashedCoverZ(line, z_near, z_far);
        if (!(cover > 0.0)) continue;
        mark_cand[n_mark++] = MarkCandidate{line.x_m - 0.5 * line.width_m,
                                            line.x_m + 0.5 * line.width_m, cover,
                                            static_cast<float>(line.albedo),
                                            static_cast<float>(line.contrast)};
      }
    }

    for (int u = 0; u < options.width; ++u) {
      const double a = (u - cx) / f;  // ray x-direction
      double best_t = std::numeric_limits<double>::infinity();
      int best = -1;  // candidate index
      int best_axis = 2;
      bool best_enters_hi = false;
      for (int k = 0; k < n_cand; ++k) {
        const Candidate& c = cand[k];
        if (u < c.u0 || u > c.u1) continue;
        const Box& box = setup.boxes[c.index];
        double tmin = box.lo[2], tmax = box.hi[2];
        int axis = 2;
        bool enters_hi = false;
        if (c.ty_min > tmin) {
          tmin = c.ty_min;
          axis = 1;
          enters_hi = c.y_enters_hi;
        }
        tmax = std::min(tmax, c.ty_max);
        if (a != 0.0) {
          const double t1 = (box.lo[0] - ox) / a, t2 = (box.hi[0] - ox) / a;
          const double tx_min = std::min(t1, t2), tx_max = std::max(t1, t2);
          if (tx_min > tmin) {
            tmin = tx_min;
            axis = 0;
            enters_hi = a < 0.0;
          }
          tmax = std::min(tmax, tx_max);
        } else if (ox < box.lo[0] || ox > box.hi[0]) {
          continue;
        }
        if (tmin <= tmax && tmin > kNearM && tmin < best_t) {
          best_t = tmin;
          best = k;
          best_axis = axis;
          best_enters_hi = enters_hi;
        }
      }
      // Hills: the nearest entry into an ellipsoid. An entry below the ground plane is always
      // farther than the ray's ground hit (the ray crosses the plane first, outside the hill),
      // so the plain nearest-hit rule is exact for the half-buried hills.
      int best_hill = -1;
      for (int k = 0; k < n_hill; ++k) {
        const HillCandidate& c = hill_cand[k];
        if (u < c.u0 || u > c.u1) continue;
        const HillGeom& g = hills[c.index];
        const double ax = a * g.inv_r[0];
        const double qa = ax * ax + c.a_row;
        const double qb = g.origin_s[view][0] * ax + c.b_row;
        const double qc = g.c[view];
        if (qb >= 0.0) continue;  // the camera is outside (qc > 0): both roots are behind
        const double disc = qb * qb - qa * qc;
        if (disc < 0.0) continue;
        // The nearer root, in the cancellation-free form C / (-B + sqrt(B^2 - A C)).
        const double t_hit = qc / (-qb + std::sqrt(disc));
        if (t_hit > kNearM && t_hit < best_t) {
          best_t = t_hit;
          best_hill = k;
        }
      }
      if (best_hill >= 0) best = -1;
      const bool ground = sees_ground && ground_t < best_t;

      if (disparity != nullptr) {
        if (ground) {
          disparity[u] = static_cast<float>(fb / ground_t);
          ids[u] = 0;
        } else if (best_hill >= 0) {
          disparity[u] = static_cast<float>(fb / best_t);
          ids[u] = 0;
        } else if (best >= 0) {
          disparity[u] = static_cast<float>(fb / best_t);
          const int index = cand[best].index;
          ids[u] = setup.boxes[index].id;
          RowStat& st = stats[index];
          st.min_u = std::min(st.min_u, u);
          st.max_u = std::max(st.max_u, u);
          ++st.count;
        } else {
          disparity[u] = 0.0f;
          ids[u] = -1;
        }
      }
      if (grey == nullptr) continue;

      float value = sky;
      if (ground) {
        const double x = ox + a * ground_t;
        const float n = Texture(ground_seed, x + setup.rig_offset[0],
                                ground_t + setup.rig_offset[2], scene.ground_texture_cell_m,
                                ground_footprint);
        value = ground_albedo + 2.0f * ground_contrast * n;
        if (n_mark > 0) {
          // Box filter of the pixel's footprint: ground_t / f wide in x, the row's z footprint.
          const double half = 0.5 * ground_t / f;
          for (int k = 0; k < n_mark; ++k) {
            const MarkCandidate& m = mark_cand[k];
            const double covered_x = std::min(x + half, m.x1) - std::max(x - half, m.x0);
            if (!(covered_x > 0.0)) continue;
            const auto cover = static_cast<float>(std::min(1.0, covered_x / (2.0 * half)) *
                                                  m.cover_z);
            const float paint = m.albedo + 2.0f * m.contrast * n;
            value += cover * (paint - value);
          }
        }
      } else if (best_hill >= 0) {
        value = ShadeHill(hills[hill_cand[best_hill].index], ox + a * best_t, b * best_t, best_t);
      } else if (best >= 0) {
        const Box& box = setup.boxes[cand[best].index];
        // Surface point in the box's own frame, so the texture moves with the box.
        const double px = ox + a * best_t - box.centre[0];
        const double py = b * best_t - box.centre[1];
        const double pz = best_t - box.centre[2];
        double s = px, t = py;
        float shade = kShadeFront;
        if (best_axis == 0) {
          s = pz;
          shade = kShadeSide;
        } else if (best_axis == 1) {
          t = pz;
          shade = best_enters_hi ? kShadeBottom : kShadeTop;
        }
        const float n = Texture(box.seed[best_axis], s, t, box.cell_m, best_t / f);
        value = shade * (box.albedo + 2.0f * box.contrast * n);
      }
      double level = std::clamp(value, 0.0f, 1.0f) * 255.0;
      if (sigma > 0.0) level += rng->gaussian(sigma);
      grey[u] = cv::saturate_cast<uint8_t>(level);
    }
  }

  // Renders frame `index`: the images when `frame` is given, the truth when `truth` is.
  void RenderFrame(int64_t index, StereoFrame* frame, FrameTruth* truth) const {
    const double t_s = TimeOf(index);
    const FrameSetup setup = Setup(t_s);
    const int w = options.width, h = options.height;
    const size_t n_obstacles = setup.boxes.size();

    cv::Mat1b left, right;
    if (frame != nullptr) {
      left.create(h, w);
      right.create(h, w);
    }
    cv::Mat1f disparity;
    cv::Mat1i ids;
    std::vector<RowStat> stats;
    if (truth != nullptr) {
      disparity.create(h, w);
      ids.create(h, w);
      stats.resize(static_cast<size_t>(h) * n_obstacles);
    }

    const uint64_t frame_seed = Mix(options.seed, static_cast<uint64_t>(index));
    cv::parallel_for_(cv::Range(0, h), [&](const cv::Range& rows) {
      for (int v = rows.start; v < rows.end; ++v) {
        float* d_row = truth != nullptr ? disparity[v] : nullptr;
        int* id_row = truth != nullptr ? ids[v] : nullptr;
        RowStat* st_row = truth != nullptr ? stats.data() + static_cast<size_t>(v) * n_obstacles
                                           : nullptr;
        if (frame == nullptr) {
          RenderRow(setup, 0, v, nullptr, d_row, id_row, st_row, nullptr);
          continue;
        }
        for (int view = 0; view < 2; ++view) {
          // The noise of each row comes from its own generator: the result does not depend on
          // how rows are split between threads.
          cv::RNG rng(Mix(frame_seed, static_cast<uint64_t>(v) * 2 + view));
          uint8_t* out = view == 0 ? left[v] : right[v];
          RenderRow(setup, view, v, out, view == 0 ? d_row : nullptr,
                    view == 0 ? id_row : nullptr, view == 0 ? st_row : nullptr, &rng);
        }
      }
    });

    if (frame != nullptr) {
      frame->left = left;
      frame->right = right;
      frame->index = index;
      frame->t_ns = std::llround(t_s * 1e9);
      frame->unix_time_ns = 0;
      frame->rectified = true;
    }
    if (truth == nullptr) return;

    truth->index = index;
    truth->t_s = t_s;
    truth->disparity_px = disparity;
    truth->object_id = ids;
    truth->obstacles.clear();
    for (size_t i = 0; i < n_obstacles; ++i) {
      const Box& box = setup.boxes[i];
      ObstacleTruth ot;
      ot.id = box.id;
      ot.name = options.scene.obstacles[i].name;
      int u0 = std::numeric_limits<int>::max(), u1 = -1, v0 = -1, v1 = -1;
      for (int v = 0; v < h; ++v) {
        const RowStat& st = stats[static_cast<size_t>(v) * n_obstacles + i];
        if (st.count == 0) continue;
        ot.visible_px += st.count;
        u0 = std::min(u0, st.min_u);
        u1 = std::max(u1, st.max_u);
        if (v0 < 0) v0 = v;
        v1 = v;
      }
      if (ot.visible_px > 0) ot.bbox = cv::Rect(u0, v0, u1 - u0 + 1, v1 - v0 + 1);
      ot.position_cam_m = cv::Vec3d(box.centre[0], box.centre[1], box.lo[2]);
      ot.depth_m = box.lo[2];
      ot.range_m = cv::norm(ot.position_cam_m);
      truth->obstacles.push_back(std::move(ot));
    }
  }
};

std::vector<std::string> SyntheticOptions::Validate() const {
  std::vector<std::string> problems;
  if (width < 16 || width > 8192) problems.push_back("width: must be in 16..8192");
  if (height < 16 || height > 8192) problems.push_back("height: must be in 16..8192");
  if (!(f_px > 0.0) || !std::isfinite(f_px)) problems.push_back("f_px: must be > 0");
  if (!(baseline_m > 0.0) || !std::isfinite(baseline_m)) {
    problems.push_back("baseline_m: must be > 0");
  }
  if (!(fps > 0.0) || !std::isfinite(fps)) problems.push_back("fps: must be > 0");
  if (!(noise_sigma >= 0.0) || !std::isfinite(noise_sigma)) {
    problems.push_back("noise_sigma: must be >= 0");
  }
  if (loop_frames < 0 || loop_frames > kMaxLoopFrames) {
    problems.push_back("loop_frames: must be in 0.." + std::to_string(kMaxLoopFrames) +
                       Got(loop_frames));
  }
  for (const std::string& p : scene.Validate()) problems.push_back("scene." + p);
  return problems;
}

SyntheticRenderer::SyntheticRenderer(SyntheticOptions options)
    : impl_(std::make_unique<Impl>(std::move(options))) {}
SyntheticRenderer::~SyntheticRenderer() = default;
SyntheticRenderer::SyntheticRenderer(SyntheticRenderer&&) noexcept = default;
SyntheticRenderer& SyntheticRenderer::operator=(SyntheticRenderer&&) noexcept = default;

const SyntheticOptions& SyntheticRenderer::options() const { return impl_->options; }

geometry::StereoRig SyntheticRenderer::Rig() const {
  const SyntheticOptions& o = impl_->options;
  return geometry::StereoRig::Ideal(cv::Size(o.width, o.height), o.f_px, o.baseline_m, impl_->cx,
                                    impl_->cy, "synthetic");
}

StereoFrame SyntheticRenderer::Render(int64_t index, FrameTruth* truth) const {
  StereoFrame frame;
  impl_->RenderFrame(index, &frame, truth);
  return frame;
}

FrameTruth SyntheticRenderer::Truth(int64_t index) const {
  FrameTruth truth;
  impl_->RenderFrame(index, nullptr, &truth);
  return truth;
}

SyntheticSource::SyntheticSource(SyntheticOptions options)
    : renderer_(std::move(options)),
      rig_(std::make_shared<const geometry::StereoRig>(renderer_.Rig())) {}

std::string SyntheticSource::Describe() const {
  const SyntheticOptions& o = renderer_.options();
  std::ostringstream out;
  out << "synthetic " << o.width << "x" << o.height << " f=" << o.f_px << "px B=" << o.baseline_m
      << "m";
  return out.str();
}

std::shared_ptr<const geometry::StereoRig> SyntheticSource::Rig() const { return rig_; }

Result<StereoFrame> SyntheticSource::Next() {
  const int loop_frames = renderer_.options().loop_frames;
  if (loop_frames <= 0) {
    StereoFrame frame = renderer_.Render(next_index_, &truth_);
    ++next_index_;
    return frame;
  }
  const size_t k = static_cast<size_t>(next_index_ % loop_frames);
  if (k >= loop_.size()) loop_.push_back(renderer_.Render(next_index_));  // the first lap
  StereoFrame frame = loop_[k];  // shares the images: nobody writes into a source's frames
  frame.index = next_index_;
  const double t_s = static_cast<double>(next_index_) / renderer_.options().fps;  // as Render
  frame.t_ns = std::llround(t_s * 1e9);
  ++next_index_;
  return frame;
}

double SyntheticSource::NominalFps() const { return renderer_.options().fps; }

Result<std::unique_ptr<SyntheticSource>> OpenSyntheticSource(SyntheticOptions options) {
  const std::vector<std::string> problems = options.Validate();
  if (!problems.empty()) return Error::Invalid(problems);
  return std::make_unique<SyntheticSource>(std::move(options));
}

}  // namespace stevi::drivers
