// Internal to drivers/synthetic: the state of SyntheticRenderer (its Impl) and the types one
// frame's rows share: the solids, hills and marks a row may see and what a pixel's ray hits. Used
// by textures.cc (seeds, sky and clouds, ground marks), ray_cast.h/.cc (the scene's solids and
// hills, their pixel bounds, the nearest hit along a ray) and renderer.cc (shading, rows, sensor
// effects, frames and their truth). Not part of the drivers' interface.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include <opencv2/core.hpp>

#include "drivers/synthetic/scene_helpers.h"
#include "drivers/synthetic/synthetic_source.h"

namespace stevi::drivers {
namespace internal {

inline uint64_t Mix(uint64_t a, uint64_t b) { return SplitMix64(a ^ SplitMix64(b)); }

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

}  // namespace internal

// The renderer's state: the options and what follows from them, fixed at construction. Its
// methods are spread over textures.cc, ray_cast.cc and renderer.cc (the comments below say which
// holds which).
struct SyntheticRenderer::Impl {
  SyntheticOptions options;
  double cx = 0, cy = 0;
  uint32_t ground_seed = 0;
  std::vector<std::array<uint32_t, 3>> face_seeds;  // per obstacle, per face axis
  std::vector<internal::HillGeom> hills;            // static terrain
  double hill_light[3] = {0.0, 0.0, 0.0};           // unit vector towards the light
  // The pitch: a camera ray (a, b, 1) is the world direction (a, b cp - sp, b sp + cp), whose
  // parameter t is still the camera depth. Level: cp = 1, sp = 0 exactly.
  bool pitched = false;
  double cp = 1.0, sp = 0.0;
  double horizon_v = 0.0;  // the row of the horizon (cy + f tan(pitch))
  // Clouds: per view, the sky's grey per pixel (gradient and clouds), computed once.
  cv::Mat1f sky_layer[2];
  bool effects = false;  // any sensor effect besides the noise

  // renderer.cc.
  explicit Impl(SyntheticOptions o);

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

  double TimeOf(int64_t index) const { return static_cast<double>(index) / options.fps; }

  // textures.cc: the texture seeds (ground, obstacle faces).
  void InitTextures();
  // Cloud density 0..1 at pixel (u, vr): thresholded fractal value noise, fading out towards
  // the horizon. A function of the ray's direction only (clouds are at infinity): both views
  // see it alike.
  float CloudDensity(uint32_t seed, double u, double vr) const;
  void BuildSkyLayers();
  float SkyGrey(double v) const;
  // The marks and dashed lines the ground of `row` may show, with their coverage of the row's z
  // footprint (only to shade: the truth does not need them). `out` holds one per mark and line.
  int CollectMarks(const internal::RowScene& row, internal::MarkCandidate* out) const;

  // ray_cast.cc: the hills, prepared for ray casting (after the pitch is known).
  void BuildHills();
  // The frame's solids at time t_s and their pixel bounds in both views.
  internal::FrameSetup Setup(double t_s) const;
  // Conservative pixel bounds of a box seen from a camera centred at (ox, 0, 0).
  internal::PixelRect Project(const internal::Box& box, double ox) const;

  // renderer.cc, inline (they run per pixel, in RenderRow's loop: only renderer.cc uses them).
  // Grey of the hill surface point (x, y, z). A function of the world point alone, so both views
  // shade it alike: the texture is triplanar in world coordinates (blended by the normal), its
  // footprint the pixel size at depth z stretched by the incidence seen from the rig's
  // mid-baseline, and the light is fixed.
  inline float ShadeHill(const internal::HillGeom& g, double x, double y, double z) const;
  // Grey of the ellipsoid solid's surface point (x, y, z) (world), seen at camera depth `depth`:
  // lit like a hill, textured triplanar in the solid's own frame (so the texture moves with it).
  // A function of the world point and its depth alone, so both views shade it alike.
  inline float ShadeEllipsoid(const internal::Box& box, double x, double y, double z,
                              double depth) const;
  // Grey of the ground at the pixel whose ray has x-direction a: its texture (in world x, z,
  // moving with the rig) under the marks that cover the pixel's footprint.
  inline float ShadeGround(const internal::FrameSetup& setup, const internal::RowScene& row,
                           double a) const;
  // Grey of what the pixel's ray (x-direction a) hits: the ground, a hill or a solid; `sky` when
  // it hits nothing.
  inline float ShadePixel(const internal::FrameSetup& setup, const internal::RowScene& row,
                          internal::PixelHit hit, double a, float sky) const;

  // renderer.cc, inline as well. Ray-casts and shades row v of one view. `grey` (nullable) gets the
  // 8-bit image row with its noise, or `linear` (nullable) the row's grey 0..255 before any sensor
  // effect; `disparity`, `ids` and `stats` (all nullable; stats per obstacle) the truth of the row.
  inline void RenderRow(const internal::FrameSetup& setup, int view, int v, uint8_t* grey,
                        float* linear, float* disparity, int* ids, internal::RowStat* stats,
                        cv::RNG* rng) const;
  // renderer.cc. The sensor effects on the linear images: blur, vignetting, the right gain, then
  // the noise (per row from its own generator, as the plain path) and the 8-bit quantisation.
  void ApplySensorEffects(cv::Mat1f lin[2], uint64_t frame_seed, cv::Mat1b& left,
                          cv::Mat1b& right) const;
  // Renders frame `index`: the images when `frame` is given, the truth when `truth` is.
  void RenderFrame(int64_t index, StereoFrame* frame, FrameTruth* truth) const;
  // Per obstacle, its reference point in the camera frame: the centre of the face towards the
  // camera of its single box, or of its solids' bounding box.
  std::vector<cv::Vec3d> ReferencePoints(const internal::FrameSetup& setup) const;
  // The truth of every obstacle of the frame, from its truth images and row statistics.
  std::vector<ObstacleTruth> ObstacleTruths(const internal::FrameSetup& setup,
                                            const cv::Mat1f& disparity, const cv::Mat1i& ids,
                                            const std::vector<internal::RowStat>& stats) const;
};

}  // namespace stevi::drivers
