// Internal to drivers/synthetic: the renderer's ray casting per pixel, the nearest surface along a
// pixel's ray (a box, an ellipsoid, a hill, the ground or nothing), and the row candidates it
// tests, which ray_cast.cc collects. The per-pixel functions are inline and in an unnamed namespace
// on purpose: every includer gets its own copy, which the compiler inlines into renderer.cc's
// per-pixel loop as readily as a file-local helper (as textures.h). Only renderer.cc and
// ray_cast.cc include it.
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "drivers/synthetic/render_internal.h"

namespace stevi::drivers::internal {

// ray_cast.cc. The solids row v of `row.view` may see, with their per-row terms; returns how many
// (`out` holds one per box).
int CollectSolids(const FrameSetup& setup, const RowScene& row, int v, SolidCandidate* out);

// ray_cast.cc. The hills row v of `row.view` may see; returns how many (`out` holds one per hill).
int CollectHills(const std::vector<HillGeom>& hills, const RowScene& row, int v,
                 HillCandidate* out);

namespace {  // internal linkage on purpose: see above

// Rays must hit a surface farther than this (metres) from the camera centre.
constexpr double kNearM = 0.01;

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

}  // namespace
}  // namespace stevi::drivers::internal
