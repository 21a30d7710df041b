// The range scan: the nearest obstacle's horizontal range per azimuth bin across the camera's field
// of view, in the body frame, from the disparity map alone (no segmentation). It feeds MAVLink
// OBSTACLE_DISTANCE. How it works and its limits: core/detection/README.md, "The range scan".
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "core/common/fields.h"
#include "core/detection/ground_plane.h"
#include "core/geometry/range.h"
#include "core/geometry/stereo_rig.h"
#include "core/stereo/disparity.h"

namespace stevi::detection {

struct RangeScanOptions {
  // Compute the scan each frame.
  bool enabled = true;
  // Azimuth bin width, degrees. Bins are centred on multiples of it (0 is a bin's centre), so a
  // width that divides 5 into an odd number of bins (1, 5/3, 5) nests whole bins in each
  // 5-degree OBSTACLE_DISTANCE sector, which autopilots centre on multiples of 5.
  double bin_width_deg = 1.0;
  // A bin reports the nearest range that at least this many pixels support (processed pixels
  // within support_window_px of disparity, in the bin and its two neighbours, a quarter of them in
  // the bin itself): fewer are speckle or a coherent mismatch.
  int min_support_px = 20;
  // The disparity window (pixels) over which a range's support is counted and its value averaged:
  // a few times the block matcher's scatter on one surface.
  double support_window_px = 1.0;
  // Every row_step-th row is read (1 = every row); min_support_px is divided by it.
  int row_step = 1;
  // Points more than this far below the vehicle's reference point (body z, metres) are dropped;
  // 0 = no limit (the ground plane removes the ground; see the README for why no band is the
  // default).
  double max_below_m = 0.0;
  // Points more than this far above it are dropped; 0 = no limit.
  double max_above_m = 0.0;
  // The ground the scan leaves out: a plane, fitted to each frame's disparity.
  GroundPlaneOptions ground;

  // Every problem, prefixed with the sub-struct ("ground.min_row_pixels: ...").
  std::vector<std::string> Validate() const;

  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Flag(s.enabled, Field("enabled", "", "compute the range scan each frame"));
    v.Number(s.bin_width_deg,
             Field("bin_width_deg", "degrees", "azimuth bin width; bins centred on its multiples")
                 .In(0.1, 5));
    v.Number(s.min_support_px,
             Field("min_support_px", "pixels", "pixels that must support a bin's nearest range")
                 .In(1, 100000));
    v.Number(s.support_window_px,
             Field("support_window_px", "pixels", "disparity window the support is counted in")
                 .In(0.25, 16));
    v.Number(s.row_step, Field("row_step", "rows", "read every row_step-th row").In(1, 16));
    v.Number(s.max_below_m,
             Field("max_below_m", "m", "drop points more than this below the vehicle")
                 .Above(0)
                 .AtMost(10000)
                 .Or(0, "no limit"));
    v.Number(s.max_above_m,
             Field("max_above_m", "m", "drop points more than this above the vehicle")
                 .Above(0)
                 .AtMost(10000)
                 .Or(0, "no limit"));
    v.Nested(s.ground, Field("ground"));
  }
};

// The scan of one frame, in the body frame (x forward, y right, z down). Azimuths are degrees from
// body x towards body y (atan2(y, x)); ranges are horizontal, hypot(x, y), metres from the
// vehicle's reference point.
struct RangeScan {
  double start_azimuth_deg = 0;  // the left edge of bin 0, in (-180, 180]
  double bin_width_deg = 1;      // bin i covers [start + i w, start + (i + 1) w), mod 360
  // Per bin: the nearest range; 0 = seen and nothing stands out nearer than max_range_m.
  std::vector<float> range_m;
  double min_range_m = 0;  // the depth of the largest disparity searched: nearer reads as this
  double max_range_m = 0;  // the depth of the trusted disparity floor: farther reads as clear
  // Per bin: the pixels that supported its range (0 when clear). For diagnostics and tests.
  std::vector<int> support_px;

  // The centre of bin i, degrees, in (-180, 180].
  double BinCentreDeg(int i) const;
  // The bin holding azimuth `deg` (any value; wrapped), or -1 outside the scan.
  int BinOf(double deg) const;
};

// The scan of `disparity` (the processed map, `rig` its rig). `range` gives the trusted floor in
// the map's own pixels (the camera floor divided by the binning) and max_range_m. A pixel counts
// when its disparity is trusted and stands out from `ground` (StandsOutFromPlane, with
// options.ground's margins; FitGroundPlane gives it); its point in the cam frame, through
// body_from_cam, gives its bin and horizontal range. The bins cover the image's azimuth span in the
// body frame (from its border's rays, at infinity and at min_range_m), or the whole circle when
// the image holds the body's vertical. Thread-safe (per-thread buffers).
RangeScan ComputeRangeScan(const stereo::DisparityMap& disparity, const geometry::StereoRig& rig,
                           const geometry::RangeOptions& range,
                           const Eigen::Isometry3d& body_from_cam,
                           const std::optional<GroundPlane>& ground,
                           const RangeScanOptions& options);

}  // namespace stevi::detection
