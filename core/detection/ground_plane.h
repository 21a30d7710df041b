// The ground as a plane, fitted to the disparity map with the vehicle's down axis as a prior: the
// range scan's ground (core/detection/README.md, "The range scan"). Any plane in the camera frame
// has a disparity linear in the pixel, d(u, v) = a u + b v + c, so the fit is linear; unlike the
// v-disparity line (ground.h) it needs no rows the ground dominates, and it holds a rolled camera.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/common/fields.h"
#include "core/geometry/stereo_rig.h"
#include "core/stereo/disparity.h"

namespace stevi::detection {

struct GroundPlaneOptions {
  // Model the ground and leave out what lies on it.
  bool enabled = true;
  // The plane's normal lies within this angle of the vehicle's down axis (degrees): the vehicle is
  // about level, and a wall or a fronto-parallel face is never ground.
  double max_tilt_deg = 30.0;
  // A pixel lies on the plane when its disparity is within max(inlier_px, inlier_fraction x the
  // plane's) of the plane's.
  double inlier_px = 0.5;
  double inlier_fraction = 0.05;
  // The plane needs this many pixels on it (processed pixels) ...
  int min_pixels = 400;
  // ... the middle 90 % of them spread over at least this fraction of the image width.
  double min_spread = 0.3;
  // A pixel stands out from the ground when its disparity exceeds the plane's by more than
  // max(margin_px, margin_fraction x the plane's).
  double margin_px = 1.0;
  double margin_fraction = 0.15;

  std::vector<std::string> Validate() const { return fields::Check(*this); }

  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Flag(s.enabled, Field("enabled", "", "model the ground and leave out what lies on it"));
    v.Number(s.max_tilt_deg,
             Field("max_tilt_deg", "degrees", "the plane's normal within this of the body's down")
                 .In(0, 60));
    v.Number(s.inlier_px,
             Field("inlier_px", "pixels", "a pixel this near the plane's disparity is on it")
                 .Above(0)
                 .AtMost(16));
    v.Number(s.inlier_fraction,
             Field("inlier_fraction", "",
                   "... or within this fraction of the plane's disparity (the larger applies)")
                 .In(0, 1));
    v.Number(s.min_pixels,
             Field("min_pixels", "pixels", "pixels the plane needs on it").In(3, 1000000));
    v.Number(
        s.min_spread,
        Field("min_spread", "", "fraction of the image width its middle 90 % must span").In(0, 1));
    v.Number(s.margin_px,
             Field("margin_px", "pixels", "stand-out margin over the plane's disparity").In(0, 64));
    v.Number(s.margin_fraction,
             Field("margin_fraction", "",
                   "stand-out margin as a fraction of the plane's disparity (the larger applies)")
                 .In(0, 1));
  }
};

// d(u, v) = a u + b v + c over the processed image (pixels); where it is <= 0 the pixel's ray
// does not meet the ground (above its horizon).
struct GroundPlane {
  double a = 0, b = 0, c = 0;
  int pixels = 0;       // pixels on it
  double height_m = 0;  // the camera's distance from the plane

  double DisparityAt(double u, double v) const { return a * u + b * v + c; }
};

// Fits the ground to the trusted disparities (>= floor_px, on a grid of about 160 samples across):
// the candidate depths below the camera along `down_in_cam` (the vehicle's down axis in the camera
// frame, from the mount) that many samples share, deepest first, each refined by least squares
// into a plane; the one with the most samples on it less twice those clearly beyond it (seen
// through the ground: nothing real is) wins, so the lowest surface beats roofs, hilltops and
// mismatched layers. Deterministic. nullopt when no plane meets the options (a clear sky, a wall).
// How and why: core/detection/README.md, "The range scan".
std::optional<GroundPlane> FitGroundPlane(const stereo::DisparityMap& disparity,
                                          const geometry::StereoRig& rig,
                                          const Eigen::Vector3d& down_in_cam, double floor_px,
                                          const GroundPlaneOptions& options);

// True when disparity `d_px` at (u, v) stands out from the plane (nearer by the margins). Without a
// plane, everything does.
bool StandsOutFromPlane(const std::optional<GroundPlane>& plane, double u, double v, double d_px,
                        const GroundPlaneOptions& options);

}  // namespace stevi::detection
