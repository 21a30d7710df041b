// The stixel world: each image column, bottom to top, labelled ground, object or sky by dynamic
// programming over a dense disparity with a per-pixel confidence; obstacles are the object stixels
// grouped by disparity continuity. The geometry says that something stands there and how far it
// is; an appearance cue (SteViE's edges, SteViS's saliency) may only split a group.
// How and why: core/detection/README.md, "The stixel world".
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/fields.h"
#include "core/detection/detection.h"
#include "core/detection/ground_plane.h"
#include "core/geometry/range.h"
#include "core/geometry/stereo_rig.h"
#include "core/stereo/disparity.h"

namespace stevi::detection {

struct StixelOptions {
  // Which appearance cue may split a group of object stixels (never create or delete one).
  enum class Split { kNone, kEdges };

  // Column width as a fraction of the image width (8 px at 640), at least 2 px.
  double column_width_fraction = 1.0 / 80;
  // Cell height (the DP's row step) as a fraction of the image *width* (4 px at 640 wide), >= 1 px:
  // cells keep their angular size whatever the image's aspect (KITTI's 1242x375 included).
  double cell_height_fraction = 1.0 / 160;
  // 1-sigma disparity noise of one cell (pixels, processed images); 0 = the range options'
  // disparity_sigma_px divided by the binning.
  double disparity_sigma_px = 0.0;
  // An object stixel is fronto-parallel within this fraction of its disparity (its sigma grows
  // with it: a car's side, a slanted wall); the ground's likewise (plane misfit, slope changes).
  // The ground's is no wider than the object's: a wider ground lets a staircase of object segments,
  // each with its own fitted disparity, out-score a far ground seen from high up (the tracking
  // scenes' camera 12 m up: 16 false boxes a frame at 0.10).
  double object_spread_fraction = 0.05;
  double ground_spread_fraction = 0.05;
  // Even the most confident cell is an outlier with at least this probability.
  double min_outlier_probability = 0.05;
  // Cost of starting a segment (nats): fewer, longer stixels (the segment-length prior).
  double segment_penalty = 3.0;
  // Gravity: an object whose disparity lies below the ground's at its foot by more than 3 sigma
  // would stand behind the ground it sits on (nats); one above it floats (allowed: aircraft,
  // wires, a drone; a mild cost).
  double sinking_penalty = 20.0;
  double floating_penalty = 2.0;
  // Depth ordering: an object above another but nearer than it by 3 sigma (an overhang).
  double overhang_penalty = 4.0;
  // An object stixel becomes part of an obstacle when it spans at least this many cells ...
  int min_cells = 2;
  // ... and, when the ground is known, reaches at least this high above it (metres), and stands
  // up: an object stixel of 3 or more measured cells whose disparity grows down the image by more
  // than this fraction of the ground's (a kerb, a verge, a ramp) lies down, and is no obstacle.
  double min_height_above_ground_m = 0.3;
  double max_slope_fraction = 0.5;
  // ... and that height holds with the stixel's disparity this many noise sigmas smaller (the
  // frame's measured cell noise, StixelWorld::noise_px): a surface whose top stands up by less
  // than the noise can tell lies down (a far ground seen from high up, an SGM staircase).
  double height_sigmas = 2.0;
  // An object stixel standing on the ground (its foot within 1 m of it) must itself be at least
  // this tall (metres): shorter ones are the ground's own disparity errors. Airborne ones (above
  // the ground's horizon, or floating higher) need only min_cells.
  double min_standing_height_m = 0.25;
  // Object stixels of neighbouring columns join when their rows overlap and their disparities
  // differ by no more than this many sigmas of the difference (the cells' noise), or their points
  // lie within max_gap_m of each other in 3-D (a car's side or a wall receding at a slant leaves
  // such gaps between columns); columns this far apart still join (0 = adjacent only).
  double join_sigmas = 3.0;
  double max_gap_m = 1.0;
  int max_gap_columns = 2;
  // Groups with fewer columns than this are dropped, and those with fewer confident pixels than
  // this (the sum over their stixels of confidence x area): the smallest obstacle the detector
  // answers for, 100 camera pixels (the pipeline divides it by the binning squared; this
  // function takes it in the pixels of the map it is given).
  int min_columns = 1;
  double min_support_px = 100;
  Split split = Split::kNone;
  // With split = edges: neighbouring stixels whose disparities differ by more than the noise stay
  // apart when a Canny edge of the left image runs down at least this fraction of their shared
  // rows, at the boundary between their columns.
  double split_edge_fraction = 0.6;

  std::vector<std::string> Validate() const { return fields::Check(*this); }
  friend bool operator==(const StixelOptions&, const StixelOptions&) = default;

  static constexpr fields::ChoiceName<Split> kSplitNames[] = {{Split::kNone, "none"},
                                                              {Split::kEdges, "edges"}};
  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Number(s.column_width_fraction,
             Field("column_width_fraction", "", "column width over the image width")
                 .Above(0)
                 .AtMost(0.25));
    v.Number(s.cell_height_fraction,
             Field("cell_height_fraction", "", "cell height over the image width")
                 .Above(0)
                 .AtMost(0.25));
    v.Number(
        s.disparity_sigma_px,
        Field("disparity_sigma_px", "pixels", "a cell's disparity noise; 0 = range's").In(0, 16));
    v.Number(
        s.object_spread_fraction,
        Field("object_spread_fraction", "", "object disparity spread over its disparity").In(0, 1));
    v.Number(
        s.ground_spread_fraction,
        Field("ground_spread_fraction", "", "ground disparity spread over its disparity").In(0, 1));
    v.Number(s.min_outlier_probability,
             Field("min_outlier_probability", "", "outlier probability of the surest cell")
                 .Above(0)
                 .AtMost(0.5));
    v.Number(s.segment_penalty,
             Field("segment_penalty", "nats", "cost of a new segment").In(0, 100));
    v.Number(s.sinking_penalty,
             Field("sinking_penalty", "nats", "object behind the ground at its foot").In(0, 1000));
    v.Number(s.floating_penalty,
             Field("floating_penalty", "nats", "object before the ground at its foot").In(0, 1000));
    v.Number(s.overhang_penalty,
             Field("overhang_penalty", "nats", "object above a farther object").In(0, 1000));
    v.Number(s.min_cells, Field("min_cells", "cells", "shortest object stixel kept").In(1, 1000));
    v.Number(s.min_height_above_ground_m,
             Field("min_height_above_ground_m", "m", "lowest top of an obstacle over the ground")
                 .In(0, 100));
    v.Number(s.height_sigmas,
             Field("height_sigmas", "", "the height must hold this many noise sigmas farther")
                 .In(0, 10));
    v.Number(s.min_standing_height_m,
             Field("min_standing_height_m", "m", "shortest object stixel standing on the ground")
                 .In(0, 100));
    v.Number(s.max_slope_fraction,
             Field("max_slope_fraction", "", "steeper disparity slope (of the ground's) lies down")
                 .In(0, 10));
    v.Number(s.join_sigmas,
             Field("join_sigmas", "", "neighbouring stixels join within this many sigmas")
                 .Above(0)
                 .AtMost(100));
    v.Number(s.max_gap_m, Field("max_gap_m", "m", "neighbours this near in 3-D join").In(0, 1000));
    v.Number(s.max_gap_columns,
             Field("max_gap_columns", "columns", "columns a group may skip").In(0, 16));
    v.Number(s.min_columns, Field("min_columns", "columns", "narrowest group kept").In(1, 1000));
    v.Number(
        s.min_support_px,
        Field("min_support_px", "pixels", "fewest confident pixels of a group kept").In(0, 1e6));
    v.Choice(s.split, Field("split", "", "appearance cue that may split a group"), kSplitNames);
    v.Number(
        s.split_edge_fraction,
        Field("split_edge_fraction", "", "edge share of a boundary that splits a group").In(0, 1));
  }
};

enum class StixelClass { kGround, kObject, kSky };

// One labelled segment of a column, in processed-image pixels.
struct Stixel {
  int column = 0;  // column index; pixels [x0, x0 + width)
  int x0 = 0;
  int width = 0;
  int top_row = 0;     // first image row (inclusive)
  int bottom_row = 0;  // last image row (inclusive)
  StixelClass label = StixelClass::kSky;
  double disparity_px = 0;  // the segment's disparity (objects; the ground's mean otherwise)
  double sigma_px = 0;      // its 1-sigma model spread
  double confidence = 0;    // mean inlier probability of its cells, 0..1
  // How its cells' disparities change down the image (pixels of disparity per image row, a
  // confidence-weighted least-squares fit; 0 for fewer than 3 measured cells): about 0 for
  // something standing up, the ground plane's own b for a surface lying down.
  double slope_px_per_row = 0;
  int measured_cells = 0;
};

struct StixelWorld {
  int columns = 0;
  int column_width = 0;
  int cell_height = 0;
  // A cell's disparity noise (processed pixels) for the standing test (height_sigmas): the larger
  // of the configured one and the frame's own, measured as the robust spread (1.4826 MAD) of the
  // confident cells below the ground's horizon about the ground plane. Dense matchers' errors are
  // correlated over their window and step in staircases on slanted surfaces, so cells are noisier
  // than pixel noise over the cell's area would say. The labelling itself uses the configured
  // noise (StixelOptions::disparity_sigma_px).
  double noise_px = 0;
  std::vector<Stixel> stixels;  // column by column, bottom to top
};

// Labels every column of `disparity` (with its confidence, when the matcher gives one) bottom to
// top. `ground` is the frame's ground plane (FitGroundPlane); without one no cell is ground.
// `rig` and `range` are the processed images'. An object segment is cut where nothing was
// measured over more than max_gap_m (metres at its disparity).
StixelWorld ComputeStixels(const stereo::DisparityMap& disparity, const geometry::StereoRig& rig,
                           const std::optional<GroundPlane>& ground,
                           const geometry::RangeOptions& range, const StixelOptions& options);

// The obstacles of a stixel world: object stixels at trusted disparities that stand above the
// ground, grouped by disparity continuity across columns; each group's disparity is the median of
// its pixels that agree with their stixels, with an honest sigma. `left` (8-bit grey, the
// processed left image) feeds the split cue; it may be empty when options.split is kNone.
std::vector<Detection> ObstaclesFromStixels(const StixelWorld& world,
                                            const stereo::DisparityMap& disparity,
                                            const cv::Mat& left, const geometry::StereoRig& rig,
                                            const std::optional<GroundPlane>& ground,
                                            const geometry::RangeOptions& range,
                                            const StixelOptions& options);

// Height (metres) of the point at pixel (u, v) with disparity d above the ground plane (the
// plane's own 3-D form); positive above it.
double HeightAboveGround(const GroundPlane& ground, const geometry::StereoRig& rig, double u,
                         double v, double d_px);

}  // namespace stevi::detection
