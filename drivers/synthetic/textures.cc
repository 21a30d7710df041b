// The synthetic renderer's textures outside the per-pixel path (textures.h holds the noise and the
// textures themselves): the texture seeds of the ground and of every obstacle face, the sky's
// gradient and its clouds (fractal value noise, rendered once per view at construction), and the
// ground marks and dashed lines a row may show, with their coverage of the row's footprint. The
// SyntheticRenderer::Impl methods here are those render_internal.h lists under textures.cc.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>

#include <opencv2/core/utility.hpp>

#include "drivers/synthetic/render_internal.h"
#include "drivers/synthetic/textures.h"

namespace stevi::drivers {

using internal::MarkCandidate;
using internal::Mix;
using internal::RowScene;
using internal::SmoothStep;
using internal::ValueNoise;

namespace {

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

}  // namespace

void SyntheticRenderer::Impl::InitTextures() {
  ground_seed = static_cast<uint32_t>(Mix(options.seed, 0x67726F756E64ull));  // "ground"
  for (const Obstacle& ob : options.scene.obstacles) {
    std::array<uint32_t, 3> s{};
    for (int axis = 0; axis < 3; ++axis) {
      s[axis] = static_cast<uint32_t>(
          Mix(options.seed, (static_cast<uint64_t>(static_cast<uint32_t>(ob.id)) << 2) | axis));
    }
    face_seeds.push_back(s);
  }
}

float SyntheticRenderer::Impl::CloudDensity(uint32_t seed, double u, double vr) const {
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

void SyntheticRenderer::Impl::BuildSkyLayers() {
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

float SyntheticRenderer::Impl::SkyGrey(double v) const {
  const Scene& s = options.scene;
  if (v >= horizon_v) return static_cast<float>(s.sky_horizon);
  // 1 at row 0 (level camera), cy rows above the horizon; 0 at the horizon row.
  const double frac = std::min(1.0, (horizon_v - v) / cy);
  return static_cast<float>(s.sky_horizon + (s.sky_top - s.sky_horizon) * frac);
}

int SyntheticRenderer::Impl::CollectMarks(const RowScene& row, MarkCandidate* out) const {
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
    out[n++] =
        MarkCandidate{m.area_xz_m.x, m.area_xz_m.x + m.area_xz_m.width, covered / (z_far - z_near),
                      static_cast<float>(m.albedo), static_cast<float>(m.contrast)};
  }
  for (const DashedLine& line : scene.dashed_lines) {
    const double cover = DashedCoverZ(line, z_near, z_far);
    if (!(cover > 0.0)) continue;
    out[n++] = MarkCandidate{line.x_m - 0.5 * line.width_m, line.x_m + 0.5 * line.width_m, cover,
                             static_cast<float>(line.albedo), static_cast<float>(line.contrast)};
  }
  return n;
}

}  // namespace stevi::drivers
