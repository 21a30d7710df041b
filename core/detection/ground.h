// The ground surface in v-disparity. Seen from a level camera at height h, flat ground on image row
// v below the horizon row v0 lies at disparity d(v) = (B / h) (v - v0): a straight line in the
// (row, disparity) plane. The fit finds that line from the disparity map alone (rows the ground
// dominates), so a detector can keep only what stands out from the ground.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "core/common/fields.h"
#include "core/stereo/disparity.h"

namespace stevi::detection {

struct GroundOptions {
  // Model the ground and drop what lies on it.
  bool enabled = true;
  // A row supports the fit when its most common disparity (1 px bins) holds at least this fraction
  // of the row's matched pixels, and at least min_row_pixels of them (block matching leaves much of
  // a steeply slanted ground unmatched, so the row's width is the wrong yardstick).
  double min_row_fraction = 0.3;
  int min_row_pixels = 15;
  // ... and spread across at least this fraction of the image width (the ground spans the view;
  // an aircraft filling a few rows does not).
  double min_row_spread = 0.3;
  // Rows whose mode lies below this disparity (pixels) are far terrain or the horizon, not the
  // ground near enough to matter; they do not vote.
  double min_mode_px = 1.0;
  // Rows that must support the fit for a model to be accepted.
  int min_support_rows = 20;
  // A row supports the line when its mode lies within this distance of it (pixels).
  double inlier_px = 1.0;
  // The supporting rows must span at least this much disparity (pixels): a fronto-parallel wall
  // filling many rows at one disparity is not ground, and ground that spans less lies beyond the
  // trusted range anyway.
  double min_span_px = 0.5;
  // A pixel stands out from the ground when its disparity exceeds the ground's on its row by more
  // than max(margin_px, margin_fraction * ground disparity).
  double margin_px = 1.0;
  double margin_fraction = 0.15;

  std::vector<std::string> Validate() const;

  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Flag(s.enabled, Field("enabled", "", "model the ground and drop what lies on it"));
    v.Number(s.min_row_fraction,
             Field("min_row_fraction", "", "fraction of a row's matched pixels its mode must hold")
                 .Above(0)
                 .AtMost(1));
    v.Number(s.min_row_pixels,
             Field("min_row_pixels", "pixels", "matched pixels a row's mode must hold").AtLeast(1));
    v.Number(
        s.min_row_spread,
        Field("min_row_spread", "", "fraction of the image width a row's mode must span").In(0, 1));
    v.Number(
        s.min_mode_px,
        Field("min_mode_px", "pixels", "rows whose mode lies below this do not vote").In(0, 64));
    v.Number(s.min_support_rows,
             Field("min_support_rows", "", "rows that must support the line").AtLeast(2));
    v.Number(s.inlier_px,
             Field("inlier_px", "pixels", "a row's mode this near the line supports it")
                 .Above(0)
                 .AtMost(16));
    v.Number(s.min_span_px,
             Field("min_span_px", "pixels", "disparity the supporting rows must span").In(0, 256));
    v.Number(
        s.margin_px,
        Field("margin_px", "pixels", "stand-out margin over the ground's disparity").In(0, 64));
    v.Number(s.margin_fraction,
             Field("margin_fraction", "",
                   "stand-out margin as a fraction of the ground's disparity (the larger applies)")
                 .In(0, 1));
  }
};

// d(v) = slope * (v - horizon_row) for v > horizon_row, else 0 (above the horizon there is no
// ground). slope = B / h for a level rig.
struct GroundModel {
  double slope = 0;        // pixels of disparity per image row (> 0)
  double horizon_row = 0;  // image row where the ground's disparity reaches 0
  int support_rows = 0;    // rows whose mode lies on the line

  double DisparityAt(double row) const {
    return row > horizon_row ? slope * (row - horizon_row) : 0.0;
  }
  // The camera height implied by the baseline (metres).
  double CameraHeight(double baseline_m) const { return slope > 0 ? baseline_m / slope : 0.0; }
};

// Fits the ground line by RANSAC over the rows' modes, then least squares over the inliers.
// nullopt when fewer than min_support_rows rows agree (no ground in view, e.g. clear sky).
std::optional<GroundModel> FitGround(const stereo::DisparityMap& disparity,
                                     const GroundOptions& options);

// True when disparity `d_px` on image row `row` stands out from the ground (nearer than it by the
// margin). Without a model, everything stands out.
bool StandsOutFromGround(const std::optional<GroundModel>& ground, double row, double d_px,
                         const GroundOptions& options);

}  // namespace stevi::detection
