// The synthetic renderer proper: SyntheticRenderer and its Impl's construction; the shading of
// what a pixel's ray hits (box faces by orientation, ellipsoids and hills lit by a fixed light, the
// ground under its marks, all textured with textures.h); the ray casting and shading of one row of
// one view, with its noise and its truth; the sensor effects (blur, vignetting, right gain, then
// noise and quantisation); a frame's left and right images rendered row by row in parallel; and the
// frame's truth (exact disparity and object id per pixel, box, position, range and median
// disparity per obstacle). The SyntheticRenderer::Impl methods here are those render_internal.h
// lists under renderer.cc.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <utility>

#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

#include "drivers/synthetic/ray_cast.h"
#include "drivers/synthetic/render_internal.h"
#include "drivers/synthetic/textures.h"

namespace stevi::drivers {

using internal::Box;
using internal::FrameSetup;
using internal::HillGeom;
using internal::Mix;
using internal::RowStat;
using internal::Texture;
using internal::Triplanar;

namespace {

using internal::HillCandidate;
using internal::MarkCandidate;
using internal::PixelHit;
using internal::RowScene;
using internal::RowStorage;
using internal::SolidCandidate;

// Grey factor per face orientation, so that box edges show.
constexpr float kShadeFront = 1.0f;   // the face towards the camera (normal -z)
constexpr float kShadeSide = 0.8f;    // faces of normal +-x
constexpr float kShadeTop = 1.1f;     // normal -y (seen from above)
constexpr float kShadeBottom = 0.7f;  // normal +y (the underside, seen from below)
// Hills are lit by a distant light from above, left and behind the camera: grey factor
// kHillAmbient + kHillDiffuse * (normal . light), so that slopes and silhouettes show.
constexpr double kHillAmbient = 0.8;
constexpr double kHillDiffuse = 0.35;
constexpr double kHillLight[3] = {-0.4, -1.0, -0.5};  // towards the light (normalised at use)
// Texture footprints on slanted hill surfaces grow as 1 / cos(incidence), capped here.
constexpr double kHillMaxStretch = 50.0;

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

SyntheticRenderer::Impl::Impl(SyntheticOptions o) : options(std::move(o)) {
  cx = options.width / 2.0;
  cy = options.height / 2.0;
  const double pitch_rad = options.scene.camera_pitch_deg * 3.14159265358979323846 / 180.0;
  pitched = pitch_rad != 0.0;
  cp = std::cos(pitch_rad);
  sp = std::sin(pitch_rad);
  horizon_v = pitched ? cy + options.f_px * std::tan(pitch_rad) : cy;
  effects = options.blur_sigma_px > 0.0 || options.vignetting > 0.0 || options.right_gain != 1.0 ||
            options.right_vertical_shift_px != 0.0;
  InitTextures();
  const double light_norm =
      std::sqrt(kHillLight[0] * kHillLight[0] + kHillLight[1] * kHillLight[1] +
                kHillLight[2] * kHillLight[2]);
  for (int k = 0; k < 3; ++k) hill_light[k] = kHillLight[k] / light_norm;
  BuildHills();
  if (options.scene.cloud_cover > 0.0) BuildSkyLayers();
}

inline float SyntheticRenderer::Impl::ShadeHill(const HillGeom& g, double x, double y,
                                                double z) const {
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

inline float SyntheticRenderer::Impl::ShadeEllipsoid(const Box& box, double x, double y, double z,
                                                     double depth) const {
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

inline float SyntheticRenderer::Impl::ShadeGround(const FrameSetup& setup, const RowScene& row,
                                                  double a) const {
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

inline float SyntheticRenderer::Impl::ShadePixel(const FrameSetup& setup, const RowScene& row,
                                                 PixelHit hit, double a, float sky) const {
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

inline void SyntheticRenderer::Impl::RenderRow(const FrameSetup& setup, int view, int v,
                                               uint8_t* grey, float* linear, float* disparity,
                                               int* ids, RowStat* stats, cv::RNG* rng) const {
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
  row.n_solids = internal::CollectSolids(setup, row, v, solids);
  row.solids = solids;
  RowStorage<HillCandidate, 16> hill_storage;
  HillCandidate* hill_cand = hill_storage.Reserve(hills.size());
  row.n_hills = internal::CollectHills(hills, row, v, hill_cand);
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
    const PixelHit hit = internal::NearestHit(setup.boxes, hills, row, u, a);
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

void SyntheticRenderer::Impl::ApplySensorEffects(cv::Mat1f lin[2], uint64_t frame_seed,
                                                 cv::Mat1b& left, cv::Mat1b& right) const {
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

void SyntheticRenderer::Impl::RenderFrame(int64_t index, StereoFrame* frame,
                                          FrameTruth* truth) const {
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

std::vector<cv::Vec3d> SyntheticRenderer::Impl::ReferencePoints(const FrameSetup& setup) const {
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

std::vector<ObstacleTruth> SyntheticRenderer::Impl::ObstacleTruths(
    const FrameSetup& setup, const cv::Mat1f& disparity, const cv::Mat1i& ids,
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

}  // namespace stevi::drivers
