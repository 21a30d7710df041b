// The synthetic renderer's scene geometry: the solids of every obstacle at a frame's time (boxes
// and the ellipsoids inscribed in them), the hills prepared for ray casting, the conservative pixel
// bounds of both in each view, and the solids and hills each row may see (with the row's terms of
// their intersection with its rays). ray_cast.h holds the per-pixel part, the nearest hit along a
// ray. The SyntheticRenderer::Impl methods here are those render_internal.h lists under
// ray_cast.cc.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <vector>

#include "drivers/synthetic/ray_cast.h"
#include "drivers/synthetic/render_internal.h"

namespace stevi::drivers {

using internal::Box;
using internal::FrameSetup;
using internal::HillGeom;
using internal::kNearM;
using internal::Mix;
using internal::PixelRect;

namespace internal {

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

}  // namespace internal

void SyntheticRenderer::Impl::BuildHills() {
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

FrameSetup SyntheticRenderer::Impl::Setup(double t_s) const {
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

PixelRect SyntheticRenderer::Impl::Project(const Box& box, double ox) const {
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

}  // namespace stevi::drivers
