#include "drivers/synthetic/synthetic_source.h"

#include "drivers/synthetic/scene_helpers.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <sstream>
#include <utility>

#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

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

// Triplanar texture at (x, y, z) for the unit normal n: the textures of the planes facing x, y
// and z (seeds seed[0..2], sampled on (z, y), (x, z) and (x, y)), weighted by n_i^2 above
// kHillBlendFloor times the largest n_j^2, normalised. Continuous in the normal, and only one or
// two planes are sampled per pixel (the texture is the cost).
inline float Triplanar(const double n[3], const uint32_t seed[3], double x, double y, double z,
                       double cell_m, double footprint_m) {
  const double n2[3] = {n[0] * n[0], n[1] * n[1], n[2] * n[2]};
  const double floor2 = kHillBlendFloor * std::max({n2[0], n2[1], n2[2]});
  const double wx = std::max(0.0, n2[0] - floor2);
  const double wy = std::max(0.0, n2[1] - floor2);
  const double wz = std::max(0.0, n2[2] - floor2);
  const double w_sum = wx + wy + wz;
  float tex = 0.0f;
  if (w_sum > 0.0) {
    if (wy > 0.0)
      tex += static_cast<float>(wy / w_sum) * Texture(seed[1], x, z, cell_m, footprint_m);
    if (wz > 0.0)
      tex += static_cast<float>(wz / w_sum) * Texture(seed[2], x, y, cell_m, footprint_m);
    if (wx > 0.0)
      tex += static_cast<float>(wx / w_sum) * Texture(seed[0], z, y, cell_m, footprint_m);
  }
  return tex;
}

// One solid of an obstacle at the frame's time: a box, or the ellipsoid inscribed in it.
struct Box {
  int id = 0;
  int obstacle = 0;  // index in Scene::obstacles
  bool ellipsoid = false;
  cv::Vec3d lo, hi, centre;  // corners and centre, world frame, metres
  cv::Vec3d inv_r;           // ellipsoid: 1 / semi-axes
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
  cv::Vec3d inv_r;             // 1 / radii
  double origin_s[2][3] = {};  // per view: (camera centre - hill centre) / radii
  double c[2] = {0.0, 0.0};    // per view: |origin_s|^2 - 1 (> 0: the camera is outside)
  PixelRect rect[2];           // per view: pixel bounds of the part above the ground
  float albedo = 0, contrast = 0;
  double cell_m = 0;
  uint32_t seed = 0;
};

// The paint of one mark or dashed line, with its coverage of the current row (z footprint).
struct MarkCandidate {
  double x0, x1;   // x extent on the ground, metres
  double cover_z;  // fraction of the row's z footprint that the mark covers
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
  std::vector<Box> boxes;               // every solid of every obstacle, in obstacle order
  std::vector<PixelRect> rects[2];      // per view: 0 left, 1 right
  double origin_x[2] = {0.0, 0.0};      // camera centre x per view, metres
  cv::Vec3d rig_offset{0.0, 0.0, 0.0};  // the moving rig's offset from its rest position
};

// A solid that one row may see: a box with its y and z slabs, or an ellipsoid with its row terms
// of the ray-ellipsoid quadratic (as the hills').
struct SolidCandidate {
  int index;  // in FrameSetup::boxes
  int u0, u1;
  double ty_min, ty_max;
  double tz_min, tz_max;
  bool y_enters_hi;
  double a_row, b_row, os_x, qc;  // ellipsoids
};

// A hill that one row may see, with the row's terms of the ray-ellipsoid quadratic
// A t^2 + 2 B t + C = 0 in the hill's scaled frame: A = (a/rx)^2 + a_row,
// B = ox_s a / rx + b_row.
struct HillCandidate {
  int index;  // in the renderer's hills
  int u0, u1;
  double a_row, b_row;
};

// Room for a row's candidates: N on the stack, the heap only past that.
template <typename T, size_t N>
struct RowStorage {
  T local[N];
  std::vector<T> many;

  T* Reserve(size_t n) {
    if (n <= N) return local;
    many.resize(n);
    return many.data();
  }
};

// One row of one view, as its pixels need it: the rays, and what they may hit (the candidates
// live in RenderRow's storage).
struct RowScene {
  int view = 0;
  double ox = 0.0;           // the view's camera centre x, metres
  double vr = 0.0;           // the row coordinate the rays go through
  double b = 0.0, dz = 1.0;  // the rays' world y and z direction (x: a = (u - cx) / f)
  const SolidCandidate* solids = nullptr;
  int n_solids = 0;
  const HillCandidate* hills = nullptr;
  int n_hills = 0;
  const MarkCandidate* marks = nullptr;  // only when shading a row that sees the ground
  int n_marks = 0;
  bool sees_ground = false;  // the row looks down
  double ground_t = 0.0;     // the ground's depth, the same across the row
  double ground_footprint = 0.0;
};

// The nearest surface along one pixel's ray.
struct PixelHit {
  double t = std::numeric_limits<double>::infinity();
  int solid = -1;          // the solid's candidate index (-1: none, or a hill is nearer)
  int axis = 2;            // the box face's axis; -1 for an ellipsoid
  bool enters_hi = false;  // the ray enters the box through its high face on that axis
  int hill = -1;           // the hill's candidate index (-1: none)
  bool ground = false;     // the ground is nearer than any solid or hill
};

// The solids row v of `row.view` may see, with their per-row terms; returns how many (`out` holds
// one per box).
int CollectSolids(const FrameSetup& setup, const RowScene& row, int v, SolidCandidate* out) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  const double b = row.b, dz = row.dz;
  int n = 0;
  for (size_t i = 0; i < setup.boxes.size(); ++i) {
    const PixelRect& r = setup.rects[row.view][i];
    if (v < r.v0 || v > r.v1 || r.u0 > r.u1) continue;
    const Box& box = setup.boxes[i];
    SolidCandidate c{static_cast<int>(i), r.u0, r.u1, 0, 0, 0, 0, false, 0, 0, 0, 0};
    if (box.ellipsoid) {
      const double os_y = -box.centre[1] * box.inv_r[1];
      const double os_z = -box.centre[2] * box.inv_r[2];
      c.os_x = (row.ox - box.centre[0]) * box.inv_r[0];
      c.qc = c.os_x * c.os_x + os_y * os_y + os_z * os_z - 1.0;
      if (c.qc <= 0.0) continue;  // the camera is inside: it sees nothing of it
      const double by = b * box.inv_r[1], bz = dz * box.inv_r[2];
      c.a_row = by * by + bz * bz;
      c.b_row = os_y * by + os_z * bz;
      out[n++] = c;
      continue;
    }
    if (dz > 0.0) {
      c.tz_min = box.lo[2] / dz;
      c.tz_max = box.hi[2] / dz;
    } else if (dz < 0.0) {
      c.tz_min = box.hi[2] / dz;
      c.tz_max = box.lo[2] / dz;
    } else {
      if (box.lo[2] > 0.0 || box.hi[2] < 0.0) continue;
      c.tz_min = -kInf;
      c.tz_max = kInf;
    }
    if (b != 0.0) {
      const double t1 = box.lo[1] / b, t2 = box.hi[1] / b;
      c.ty_min = std::min(t1, t2);
      c.ty_max = std::max(t1, t2);
      c.y_enters_hi = b < 0.0;
    } else {
      if (box.lo[1] > 0.0 || box.hi[1] < 0.0) continue;
      c.ty_min = -kInf;
      c.ty_max = kInf;
    }
    out[n++] = c;
  }
  return n;
}

// The hills row v of `row.view` may see; returns how many (`out` holds one per hill).
int CollectHills(const std::vector<HillGeom>& hills, const RowScene& row, int v,
                 HillCandidate* out) {
  int n = 0;
  for (size_t i = 0; i < hills.size(); ++i) {
    const HillGeom& g = hills[i];
    const PixelRect& r = g.rect[row.view];
    if (v < r.v0 || v > r.v1 || r.u0 > r.u1) continue;
    const double by = row.b * g.inv_r[1];
    const double bz = row.dz * g.inv_r[2];
    out[n++] = HillCandidate{static_cast<int>(i), r.u0, r.u1, by * by + bz * bz,
                             g.origin_s[row.view][1] * by + g.origin_s[row.view][2] * bz};
  }
  return n;
}

// Where a ray from a camera outside an ellipsoid enters it: the nearer root t of the quadratic
// qa t^2 + 2 qb t + qc = 0 in the ellipsoid's scaled frame (qc > 0), in the cancellation-free
// form qc / (-qb + sqrt(qb^2 - qa qc)); -1 when the ray misses it or both roots are behind.
inline double EllipsoidEntry(double qa, double qb, double qc) {
  if (qb >= 0.0) return -1.0;  // the camera is outside: both roots are behind
  const double disc = qb * qb - qa * qc;
  if (disc < 0.0) return -1.0;
  return qc / (-qb + std::sqrt(disc));
}

// The nearest solid along pixel u's ray (x-direction a); solid -1 when there is none.
inline PixelHit NearestSolid(const std::vector<Box>& boxes, const RowScene& row, int u, double a) {
  // Scalars, not the PixelHit: they stay in registers.
  double best_t = std::numeric_limits<double>::infinity();
  int best = -1;
  int best_axis = 2;
  bool best_enters_hi = false;
  for (int k = 0; k < row.n_solids; ++k) {
    const SolidCandidate& c = row.solids[k];
    if (u < c.u0 || u > c.u1) continue;
    const Box& box = boxes[c.index];
    if (box.ellipsoid) {
      const double ax = a * box.inv_r[0];
      const double t_hit = EllipsoidEntry(ax * ax + c.a_row, c.os_x * ax + c.b_row, c.qc);
      if (t_hit > kNearM && t_hit < best_t) {
        best_t = t_hit;
        best = k;
        best_axis = -1;
      }
      continue;
    }
    double tmin = c.tz_min, tmax = c.tz_max;
    int axis = 2;
    bool enters_hi = false;
    if (c.ty_min > tmin) {
      tmin = c.ty_min;
      axis = 1;
      enters_hi = c.y_enters_hi;
    }
    tmax = std::min(tmax, c.ty_max);
    if (a != 0.0) {
      const double t1 = (box.lo[0] - row.ox) / a, t2 = (box.hi[0] - row.ox) / a;
      const double tx_min = std::min(t1, t2), tx_max = std::max(t1, t2);
      if (tx_min > tmin) {
        tmin = tx_min;
        axis = 0;
        enters_hi = a < 0.0;
      }
      tmax = std::min(tmax, tx_max);
    } else if (row.ox < box.lo[0] || row.ox > box.hi[0]) {
      continue;
    }
    if (tmin <= tmax && tmin > kNearM && tmin < best_t) {
      best_t = tmin;
      best = k;
      best_axis = axis;
      best_enters_hi = enters_hi;
    }
  }
  return PixelHit{.t = best_t, .solid = best, .axis = best_axis, .enters_hi = best_enters_hi};
}

// What pixel u's ray (x-direction a) hits first: a solid, a hill, the ground or nothing (the sky).
inline PixelHit NearestHit(const std::vector<Box>& boxes, const std::vector<HillGeom>& hills,
                           const RowScene& row, int u, double a) {
  PixelHit hit = NearestSolid(boxes, row, u, a);
  // Hills: the nearest entry into an ellipsoid. An entry below the ground plane is always
  // farther than the ray's ground hit (the ray crosses the plane first, outside the hill), so
  // the plain nearest-hit rule is exact for the half-buried hills.
  double best_t = hit.t;
  int best_hill = -1;
  for (int k = 0; k < row.n_hills; ++k) {
    const HillCandidate& c = row.hills[k];
    if (u < c.u0 || u > c.u1) continue;
    const HillGeom& g = hills[c.index];
    const double ax = a * g.inv_r[0];
    const double t_hit =
        EllipsoidEntry(ax * ax + c.a_row, g.origin_s[row.view][0] * ax + c.b_row, g.c[row.view]);
    if (t_hit > kNearM && t_hit < best_t) {
      best_t = t_hit;
      best_hill = k;
    }
  }
  hit.t = best_t;
  hit.hill = best_hill;
  if (best_hill >= 0) hit.solid = -1;
  hit.ground = row.sees_ground && row.ground_t < best_t;
  return hit;
}

// The truth of pixel u: its exact disparity (fb = f B), its object id (0 ground and hills, -1
// sky), and its obstacle's row statistics.
inline void WriteTruth(const std::vector<Box>& boxes, const RowScene& row, PixelHit hit, double fb,
                       int u, float* disparity, int* ids, RowStat* stats) {
  if (hit.ground) {
    disparity[u] = static_cast<float>(fb / row.ground_t);
    ids[u] = 0;
  } else if (hit.hill >= 0) {
    disparity[u] = static_cast<float>(fb / hit.t);
    ids[u] = 0;
  } else if (hit.solid >= 0) {
    disparity[u] = static_cast<float>(fb / hit.t);
    const Box& box = boxes[row.solids[hit.solid].index];
    ids[u] = box.id;
    RowStat& st = stats[box.obstacle];
    st.min_u = std::min(st.min_u, u);
    st.max_u = std::max(st.max_u, u);
    ++st.count;
  } else {
    disparity[u] = 0.0f;
    ids[u] = -1;
  }
}

// Grey of the box face `hit` entered, at the world point (x, y, z), f the focal length in pixels.
// Textured in the box's own frame, so the texture moves with the box; shaded by the face's
// orientation.
inline float ShadeBoxFace(const Box& box, PixelHit hit, double x, double y, double z, double f) {
  const double px = x - box.centre[0];
  const double py = y - box.centre[1];
  const double pz = z - box.centre[2];
  double s = px, t = py;
  float shade = kShadeFront;
  if (hit.axis == 0) {
    s = pz;
    shade = kShadeSide;
  } else if (hit.axis == 1) {
    t = pz;
    shade = hit.enters_hi ? kShadeBottom : kShadeTop;
  }
  const float n = Texture(box.seed[hit.axis], s, t, box.cell_m, hit.t / f);
  return shade * (box.albedo + 2.0f * box.contrast * n);
}

// Per obstacle, the exact disparities of its visible pixels in the left image's truth.
std::vector<std::vector<float>> VisibleDisparities(const std::vector<Obstacle>& obstacles,
                                                   const cv::Mat1f& disparity,
                                                   const cv::Mat1i& ids) {
  std::map<int, size_t> index_of_id;
  for (size_t i = 0; i < obstacles.size(); ++i) index_of_id[obstacles[i].id] = i;
  std::vector<std::vector<float>> visible(obstacles.size());
  const int w = ids.cols, h = ids.rows;
  for (int v = 0; v < h; ++v) {
    const int* id_row = ids[v];
    const float* d_row = disparity[v];
    for (int u = 0; u < w; ++u) {
      if (id_row[u] <= 0) continue;
      const auto it = index_of_id.find(id_row[u]);
      if (it != index_of_id.end()) visible[it->second].push_back(d_row[u]);
    }
  }
  return visible;
}

}  // namespace

struct SyntheticRenderer::Impl {
  SyntheticOptions options;
  double cx = 0, cy = 0;
  uint32_t ground_seed = 0;
  std::vector<std::array<uint32_t, 3>> face_seeds;  // per obstacle, per face axis
  std::vector<HillGeom> hills;                      // static terrain
  double hill_light[3] = {0.0, 0.0, 0.0};           // unit vector towards the light
  // The pitch: a camera ray (a, b, 1) is the world direction (a, b cp - sp, b sp + cp), whose
  // parameter t is still the camera depth. Level: cp = 1, sp = 0 exactly.
  bool pitched = false;
  double cp = 1.0, sp = 0.0;
  double horizon_v = 0.0;  // the row of the horizon (cy + f tan(pitch))
  // Clouds: per view, the sky's grey per pixel (gradient and clouds), computed once.
  cv::Mat1f sky_layer[2];
  bool effects = false;  // any sensor effect besides the noise

  explicit Impl(SyntheticOptions o) : options(std::move(o)) {
    cx = options.width / 2.0;
    cy = options.height / 2.0;
    const double pitch_rad = options.scene.camera_pitch_deg * 3.14159265358979323846 / 180.0;
    pitched = pitch_rad != 0.0;
    cp = std::cos(pitch_rad);
    sp = std::sin(pitch_rad);
    horizon_v = pitched ? cy + options.f_px * std::tan(pitch_rad) : cy;
    effects = options.blur_sigma_px > 0.0 || options.vignetting > 0.0 ||
              options.right_gain != 1.0 || options.right_vertical_shift_px != 0.0;
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
    if (options.scene.cloud_cover > 0.0) BuildSkyLayers();
  }

  // The row coordinate the rays of `view`'s row v go through (the right image's misalignment).
  double RayRow(int view, int v) const {
    return view == 1 && options.right_vertical_shift_px != 0.0 ? v - options.right_vertical_shift_px
                                                               : static_cast<double>(v);
  }

  // World direction (per row): y and z components of the ray through row coordinate vr.
  void RowDirection(double vr, double& dy, double& dz) const {
    const double b = (vr - cy) / options.f_px;
    dy = b * cp - sp;
    dz = b * sp + cp;
  }

  // Cloud density 0..1 at pixel (u, vr): thresholded fractal value noise, fading out towards
  // the horizon. A function of the ray's direction only (clouds are at infinity): both views
  // see it alike.
  float CloudDensity(uint32_t seed, double u, double vr) const {
    const Scene& scene = options.scene;
    const double above = horizon_v - vr;
    if (above <= 0.0) return 0.0f;
    const double scale_px = scene.cloud_scale * options.width;
    double n = 0.0, weight = 0.5, norm = 0.0, size = scale_px;
    for (int k = 0; k < 4; ++k) {
      n += weight * ValueNoise(seed + static_cast<uint32_t>(k) * 0x5BD1E995u, u / size + 0.31 * k,
                               vr / size + 0.57 * k);
      norm += weight;
      weight *= 0.5;
      size *= 0.5;
    }
    n /= norm;  // ~0.5 +- 0.2
    const double threshold = 0.5 + 0.3 * (0.5 - scene.cloud_cover);
    const double density = std::clamp((n - threshold) / 0.12, 0.0, 1.0);
    const double fade = std::clamp(above / (0.08 * options.height), 0.0, 1.0);
    return static_cast<float>(SmoothStep(static_cast<float>(density)) * fade);
  }

  void BuildSkyLayers() {
    const uint32_t seed = static_cast<uint32_t>(Mix(options.seed, 0x636C6F7564ull));  // "cloud"
    const auto grey = static_cast<float>(options.scene.cloud_grey);
    for (int view = 0; view < 2; ++view) {
      if (view == 1 && options.right_vertical_shift_px == 0.0) {
        sky_layer[1] = sky_layer[0];
        break;
      }
      cv::Mat1f& layer = sky_layer[view];
      layer.create(options.height, options.width);
      cv::parallel_for_(cv::Range(0, options.height), [&](const cv::Range& rows) {
        for (int v = rows.start; v < rows.end; ++v) {
          const double vr = RayRow(view, v);
          const float sky = SkyGrey(vr);
          float* out = layer[v];
          for (int u = 0; u < options.width; ++u) {
            out[u] = sky + grey * CloudDensity(seed, u, vr);
          }
        }
      });
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
      const cv::Vec3d position = ob.path.PositionAt(t_s) - setup.rig_offset;
      const size_t n_parts = std::max<size_t>(1, ob.parts.size());
      for (size_t k = 0; k < n_parts; ++k) {
        Box box;
        box.id = ob.id;
        box.obstacle = static_cast<int>(i);
        cv::Vec3d size = ob.size_m;
        box.centre = position;
        if (!ob.parts.empty()) {
          const ObstaclePart& part = ob.parts[k];
          size = part.size_m;
          box.centre = position + part.offset_m;
          box.ellipsoid = part.shape == ObstaclePart::Shape::kEllipsoid;
        }
        box.lo = box.centre - size * 0.5;
        box.hi = box.centre + size * 0.5;
        for (int axis = 0; axis < 3; ++axis) box.inv_r[axis] = 2.0 / size[axis];
        box.albedo = static_cast<float>(ob.albedo);
        box.contrast = static_cast<float>(ob.contrast);
        box.cell_m = ob.texture_cell_m;
        for (int axis = 0; axis < 3; ++axis) box.seed[axis] = face_seeds[i][axis];
        setup.boxes.push_back(box);
      }
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
    const double f = options.f_px;
    double umin = std::numeric_limits<double>::infinity(), umax = -umin;
    double vmin = umin, vmax = -umin;
    if (pitched) {
      // The eight corners in the camera frame: cam = R^T world.
      int behind = 0;
      for (double z : {box.lo[2], box.hi[2]}) {
        for (double y : {box.lo[1], box.hi[1]}) {
          const double yc = y * cp + z * sp, zc = z * cp - y * sp;
          if (zc <= kNearM) {
            ++behind;
            continue;
          }
          for (double x : {box.lo[0], box.hi[0]}) {
            const double u = cx + f * (x - ox) / zc;
            umin = std::min(umin, u);
            umax = std::max(umax, u);
          }
          const double v = cy + f * yc / zc;
          vmin = std::min(vmin, v);
          vmax = std::max(vmax, v);
        }
      }
      if (behind == 4) return r;  // all behind the camera
      if (behind > 0) return PixelRect{0, w - 1, 0, h - 1};
    } else {
      if (box.hi[2] <= kNearM) return r;  // behind the camera
      if (box.lo[2] <= kNearM) return PixelRect{0, w - 1, 0, h - 1};
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

  float SkyGrey(double v) const {
    const Scene& s = options.scene;
    if (v >= horizon_v) return static_cast<float>(s.sky_horizon);
    // 1 at row 0 (level camera), cy rows above the horizon; 0 at the horizon row.
    const double frac = std::min(1.0, (horizon_v - v) / cy);
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
    const uint32_t seeds[3] = {g.seed + 2u, g.seed, g.seed + 1u};
    const float tex = Triplanar(n, seeds, x, y, z, g.cell_m, footprint);
    const double lit = n[0] * hill_light[0] + n[1] * hill_light[1] + n[2] * hill_light[2];
    const auto shade = static_cast<float>(kHillAmbient + kHillDiffuse * lit);
    return shade * (g.albedo + 2.0f * g.contrast * tex);
  }

  // Grey of the ellipsoid solid's surface point (x, y, z) (world), seen at camera depth `depth`:
  // lit like a hill, textured triplanar in the solid's own frame (so the texture moves with it).
  // A function of the world point and its depth alone, so both views shade it alike.
  float ShadeEllipsoid(const Box& box, double x, double y, double z, double depth) const {
    const double p[3] = {x - box.centre[0], y - box.centre[1], z - box.centre[2]};
    double n[3] = {p[0] * box.inv_r[0] * box.inv_r[0], p[1] * box.inv_r[1] * box.inv_r[1],
                   p[2] * box.inv_r[2] * box.inv_r[2]};
    const double n_norm = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (n_norm > 0.0) {
      for (double& c : n) c /= n_norm;
    }
    const double footprint = depth / options.f_px;
    const float tex = Triplanar(n, box.seed, p[0], p[1], p[2], box.cell_m, footprint);
    const double lit = n[0] * hill_light[0] + n[1] * hill_light[1] + n[2] * hill_light[2];
    const auto shade = static_cast<float>(kHillAmbient + kHillDiffuse * lit);
    return shade * (box.albedo + 2.0f * box.contrast * tex);
  }

  // The marks and dashed lines the ground of `row` may show, with their coverage of the row's z
  // footprint (only to shade: the truth does not need them). `out` holds one per mark and line.
  int CollectMarks(const RowScene& row, MarkCandidate* out) const {
    const Scene& scene = options.scene;
    int n = 0;
    // The row's footprint on the ground: world z seen by rays through vr - 0.5 .. vr + 0.5.
    double b_far = 0.0, dz_far = 1.0, b_near = 0.0, dz_near = 1.0;
    RowDirection(row.vr - 0.5, b_far, dz_far);
    RowDirection(row.vr + 0.5, b_near, dz_near);
    const double z_near = scene.camera_height_m * dz_near / b_near;
    const double z_far = b_far > 0.0 ? scene.camera_height_m * dz_far / b_far
                                     : std::numeric_limits<double>::infinity();
    for (const GroundMark& m : scene.marks) {
      const double mz0 = m.area_xz_m.y, mz1 = m.area_xz_m.y + m.area_xz_m.height;
      if (!std::isfinite(z_far)) continue;  // a finite mark covers none of an endless row
      const double covered = std::min(z_far, mz1) - std::max(z_near, mz0);
      if (!(covered > 0.0)) continue;
      out[n++] = MarkCandidate{m.area_xz_m.x, m.area_xz_m.x + m.area_xz_m.width,
                               covered / (z_far - z_near), static_cast<float>(m.albedo),
                               static_cast<float>(m.contrast)};
    }
    for (const DashedLine& line : scene.dashed_lines) {
      const double cover = DashedCoverZ(line, z_near, z_far);
      if (!(cover > 0.0)) continue;
      out[n++] = MarkCandidate{line.x_m - 0.5 * line.width_m, line.x_m + 0.5 * line.width_m, cover,
                               static_cast<float>(line.albedo), static_cast<float>(line.contrast)};
    }
    return n;
  }

  // Grey of the ground at the pixel whose ray has x-direction a: its texture (in world x, z,
  // moving with the rig) under the marks that cover the pixel's footprint.
  float ShadeGround(const FrameSetup& setup, const RowScene& row, double a) const {
    const Scene& scene = options.scene;
    const double x = row.ox + a * row.ground_t;
    const float n =
        Texture(ground_seed, x + setup.rig_offset[0], row.dz * row.ground_t + setup.rig_offset[2],
                scene.ground_texture_cell_m, row.ground_footprint);
    float value = static_cast<float>(scene.ground_albedo) +
                  2.0f * static_cast<float>(scene.ground_contrast) * n;
    if (row.n_marks > 0) {
      // Box filter of the pixel's footprint: ground_t / f wide in x, the row's z footprint.
      const double half = 0.5 * row.ground_t / options.f_px;
      for (int k = 0; k < row.n_marks; ++k) {
        const MarkCandidate& m = row.marks[k];
        const double covered_x = std::min(x + half, m.x1) - std::max(x - half, m.x0);
        if (!(covered_x > 0.0)) continue;
        const auto cover = static_cast<float>(std::min(1.0, covered_x / (2.0 * half)) * m.cover_z);
        const float paint = m.albedo + 2.0f * m.contrast * n;
        value += cover * (paint - value);
      }
    }
    return value;
  }

  // Grey of what the pixel's ray (x-direction a) hits: the ground, a hill or a solid; `sky` when
  // it hits nothing.
  float ShadePixel(const FrameSetup& setup, const RowScene& row, PixelHit hit, double a,
                   float sky) const {
    const double t = hit.t;
    if (hit.ground) return ShadeGround(setup, row, a);
    if (hit.hill >= 0) {
      return ShadeHill(hills[row.hills[hit.hill].index], row.ox + a * t, row.b * t, row.dz * t);
    }
    if (hit.solid < 0) return sky;
    const Box& box = setup.boxes[row.solids[hit.solid].index];
    if (hit.axis < 0) return ShadeEllipsoid(box, row.ox + a * t, row.b * t, row.dz * t, t);
    return ShadeBoxFace(box, hit, row.ox + a * t, row.b * t, row.dz * t, options.f_px);
  }

  // Ray-casts and shades row v of one view. `grey` (nullable) gets the 8-bit image row with its
  // noise, or `linear` (nullable) the row's grey 0..255 before any sensor effect; `disparity`,
  // `ids` and `stats` (all nullable; stats per obstacle) the truth of the row.
  void RenderRow(const FrameSetup& setup, int view, int v, uint8_t* grey, float* linear,
                 float* disparity, int* ids, RowStat* stats, cv::RNG* rng) const {
    const Scene& scene = options.scene;
    const double f = options.f_px;
    const double fb = options.f_px * options.baseline_m;
    RowScene row;
    row.view = view;
    row.ox = setup.origin_x[view];
    row.vr = RayRow(view, v);
    // The ray's world y- and z-direction (level camera: b = (v - cy) / f and dz = 1; the x
    // direction is a = (u - cx) / f, and the ray parameter t is the camera depth).
    RowDirection(row.vr, row.b, row.dz);
    const bool shading = grey != nullptr || linear != nullptr;
    const float sky = SkyGrey(row.vr);
    const float* sky_px = sky_layer[view].empty() ? nullptr : sky_layer[view][v];
    const double sigma = options.noise_sigma;

    // What this row may see, on the stack (the heap only for crowded scenes).
    RowStorage<SolidCandidate, 64> solid_storage;
    SolidCandidate* solids = solid_storage.Reserve(setup.boxes.size());
    row.n_solids = CollectSolids(setup, row, v, solids);
    row.solids = solids;
    RowStorage<HillCandidate, 16> hill_storage;
    HillCandidate* hill_cand = hill_storage.Reserve(hills.size());
    row.n_hills = CollectHills(hills, row, v, hill_cand);
    row.hills = hill_cand;
    // The ground, if this row looks down: the same depth across the row.
    row.sees_ground = row.b > 0.0;
    row.ground_t = row.sees_ground ? scene.camera_height_m / row.b : 0.0;
    row.ground_footprint =
        row.sees_ground ? row.ground_t / f * std::max(1.0, row.ground_t / scene.camera_height_m)
                        : 0.0;
    RowStorage<MarkCandidate, 32> mark_storage;
    const size_t n_paint = scene.marks.size() + scene.dashed_lines.size();
    if (shading && row.sees_ground && n_paint > 0) {
      MarkCandidate* marks = mark_storage.Reserve(n_paint);
      row.n_marks = CollectMarks(row, marks);
      row.marks = marks;
    }

    for (int u = 0; u < options.width; ++u) {
      const double a = (u - cx) / f;  // ray x-direction
      const PixelHit hit = NearestHit(setup.boxes, hills, row, u, a);
      if (disparity != nullptr) WriteTruth(setup.boxes, row, hit, fb, u, disparity, ids, stats);
      if (!shading) continue;

      const float value = ShadePixel(setup, row, hit, a, sky_px != nullptr ? sky_px[u] : sky);
      if (linear != nullptr) {
        linear[u] = std::clamp(value, 0.0f, 1.0f) * 255.0f;
        continue;
      }
      double level = std::clamp(value, 0.0f, 1.0f) * 255.0;
      if (sigma > 0.0) level += rng->gaussian(sigma);
      grey[u] = cv::saturate_cast<uint8_t>(level);
    }
  }

  // The sensor effects on the linear images: blur, vignetting, the right gain, then the noise
  // (per row from its own generator, as the plain path) and the 8-bit quantisation.
  void ApplySensorEffects(cv::Mat1f lin[2], uint64_t frame_seed, cv::Mat1b& left,
                          cv::Mat1b& right) const {
    const int w = options.width, h = options.height;
    for (int view = 0; view < 2; ++view) {
      if (options.blur_sigma_px > 0.0) {
        cv::GaussianBlur(lin[view], lin[view], cv::Size(0, 0), options.blur_sigma_px,
                         options.blur_sigma_px, cv::BORDER_REFLECT_101);
      }
    }
    const double r2_corner = cx * cx + cy * cy;
    cv::parallel_for_(cv::Range(0, h), [&](const cv::Range& rows) {
      std::vector<float> fall(static_cast<size_t>(w), 1.0f);
      for (int v = rows.start; v < rows.end; ++v) {
        if (options.vignetting > 0.0) {
          const double dv = v + 0.5 - cy;
          for (int u = 0; u < w; ++u) {
            const double du = u + 0.5 - cx;
            fall[static_cast<size_t>(u)] =
                static_cast<float>(1.0 - options.vignetting * (du * du + dv * dv) / r2_corner);
          }
        }
        for (int view = 0; view < 2; ++view) {
          cv::RNG rng(Mix(frame_seed, static_cast<uint64_t>(v) * 2 + view));
          const auto gain = static_cast<float>(view == 1 ? options.right_gain : 1.0);
          const float* in = lin[view][v];
          uint8_t* out = view == 0 ? left[v] : right[v];
          for (int u = 0; u < w; ++u) {
            double level = in[u] * fall[static_cast<size_t>(u)] * gain;
            if (options.noise_sigma > 0.0) level += rng.gaussian(options.noise_sigma);
            out[u] = cv::saturate_cast<uint8_t>(level);
          }
        }
      }
    });
  }

  // Renders frame `index`: the images when `frame` is given, the truth when `truth` is.
  void RenderFrame(int64_t index, StereoFrame* frame, FrameTruth* truth) const {
    const double t_s = TimeOf(index);
    const FrameSetup setup = Setup(t_s);
    const int w = options.width, h = options.height;
    const size_t n_obstacles = options.scene.obstacles.size();

    cv::Mat1b left, right;
    cv::Mat1f lin[2];
    if (frame != nullptr) {
      left.create(h, w);
      right.create(h, w);
      if (effects) {
        lin[0].create(h, w);
        lin[1].create(h, w);
      }
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
        RowStat* st_row =
            truth != nullptr ? stats.data() + static_cast<size_t>(v) * n_obstacles : nullptr;
        if (frame == nullptr) {
          RenderRow(setup, 0, v, nullptr, nullptr, d_row, id_row, st_row, nullptr);
          continue;
        }
        for (int view = 0; view < 2; ++view) {
          float* d = view == 0 ? d_row : nullptr;
          int* i = view == 0 ? id_row : nullptr;
          RowStat* st = view == 0 ? st_row : nullptr;
          if (effects) {
            RenderRow(setup, view, v, nullptr, lin[view][v], d, i, st, nullptr);
            continue;
          }
          // The noise of each row comes from its own generator: the result does not depend on
          // how rows are split between threads.
          cv::RNG rng(Mix(frame_seed, static_cast<uint64_t>(v) * 2 + view));
          uint8_t* out = view == 0 ? left[v] : right[v];
          RenderRow(setup, view, v, out, nullptr, d, i, st, &rng);
        }
      }
    });
    if (frame != nullptr && effects) ApplySensorEffects(lin, frame_seed, left, right);

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
    truth->obstacles = ObstacleTruths(setup, disparity, ids, stats);
  }

  // Per obstacle, its reference point in the camera frame: the centre of the face towards the
  // camera of its single box, or of its solids' bounding box.
  std::vector<cv::Vec3d> ReferencePoints(const FrameSetup& setup) const {
    const size_t n_obstacles = options.scene.obstacles.size();
    std::vector<cv::Vec3d> lo(n_obstacles, cv::Vec3d::all(std::numeric_limits<double>::max()));
    std::vector<cv::Vec3d> hi(n_obstacles, cv::Vec3d::all(-std::numeric_limits<double>::max()));
    std::vector<int> solids(n_obstacles, 0);
    std::vector<cv::Vec3d> centre(n_obstacles);
    for (const Box& box : setup.boxes) {
      const auto i = static_cast<size_t>(box.obstacle);
      for (int k = 0; k < 3; ++k) {
        lo[i][k] = std::min(lo[i][k], box.lo[k]);
        hi[i][k] = std::max(hi[i][k], box.hi[k]);
      }
      centre[i] = box.centre;
      ++solids[i];
    }
    std::vector<cv::Vec3d> points(n_obstacles);
    for (size_t i = 0; i < n_obstacles; ++i) {
      // A single box: its own centre, exactly; a composite: its bounding box's.
      const cv::Vec3d c = solids[i] == 1 ? centre[i] : (lo[i] + hi[i]) * 0.5;
      cv::Vec3d p(c[0], c[1], lo[i][2]);
      if (pitched) p = cv::Vec3d(p[0], p[1] * cp + p[2] * sp, p[2] * cp - p[1] * sp);
      points[i] = p;
    }
    return points;
  }

  // The truth of every obstacle of the frame, from its truth images and row statistics.
  std::vector<ObstacleTruth> ObstacleTruths(const FrameSetup& setup, const cv::Mat1f& disparity,
                                            const cv::Mat1i& ids,
                                            const std::vector<RowStat>& stats) const {
    const size_t n_obstacles = options.scene.obstacles.size();
    std::vector<std::vector<float>> visible =
        VisibleDisparities(options.scene.obstacles, disparity, ids);
    const std::vector<cv::Vec3d> points = ReferencePoints(setup);
    std::vector<ObstacleTruth> out;
    for (size_t i = 0; i < n_obstacles; ++i) {
      const Obstacle& ob = options.scene.obstacles[i];
      ObstacleTruth ot;
      ot.id = ob.id;
      ot.name = ob.name;
      ot.kind = ob.kind;
      int u0 = std::numeric_limits<int>::max(), u1 = -1, v0 = -1, v1 = -1;
      for (int v = 0; v < options.height; ++v) {
        const RowStat& st = stats[static_cast<size_t>(v) * n_obstacles + i];
        if (st.count == 0) continue;
        ot.visible_px += st.count;
        u0 = std::min(u0, st.min_u);
        u1 = std::max(u1, st.max_u);
        if (v0 < 0) v0 = v;
        v1 = v;
      }
      if (ot.visible_px > 0) ot.bbox = cv::Rect(u0, v0, u1 - u0 + 1, v1 - v0 + 1);
      ot.position_cam_m = points[i];
      ot.depth_m = points[i][2];
      ot.range_m = cv::norm(ot.position_cam_m);
      std::vector<float>& d = visible[i];
      if (!d.empty()) {
        auto mid = d.begin() + static_cast<std::ptrdiff_t>(d.size() / 2);
        std::nth_element(d.begin(), mid, d.end());
        ot.median_disparity_px = *mid;
      }
      out.push_back(std::move(ot));
    }
    return out;
  }
};

std::vector<std::string> SyntheticOptions::Validate() const {
  std::vector<std::string> problems = fields::Check(*this);
  if (!(fps > 0.0) || !std::isfinite(fps)) problems.push_back("fps: must be > 0");
  if (!(blur_sigma_px >= 0.0 && blur_sigma_px <= 10.0)) {
    problems.push_back("blur_sigma_px: must be in 0..10" + Got(blur_sigma_px));
  }
  if (!(vignetting >= 0.0 && vignetting <= 0.9)) {
    problems.push_back("vignetting: must be in 0..0.9" + Got(vignetting));
  }
  if (!(right_gain >= 0.5 && right_gain <= 2.0)) {
    problems.push_back("right_gain: must be in 0.5..2" + Got(right_gain));
  }
  if (!(std::abs(right_vertical_shift_px) <= 2.0)) {
    problems.push_back("right_vertical_shift_px: must be in -2..2" + Got(right_vertical_shift_px));
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
