// The options of the stereo half of every detector (hypotheses, their filters and their range:
// RangeRegions in regions.h), and the range fields of a detection from its disparity.
#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/fields.h"
#include "core/detection/detection.h"
#include "core/detection/ground.h"
#include "core/geometry/range.h"
#include "core/geometry/stereo_rig.h"
#include "core/stereo/disparity.h"

namespace stevi::detection {

struct StereoBlobOptions {
  // Hypotheses smaller than this (pixels of the processed image) are dropped. Not scaled with
  // the image: how many pixels it takes to see an object is a matter of the sensor's sampling,
  // and an obstacle of 100 camera pixels binned 2x2 covers 25.
  int min_area_px = 20;
  // Blobs wider than this fraction of the image width (the skyline, the ground) are dropped.
  double max_width_fraction = 0.8;
  // Hypotheses whose mask has fewer trusted disparities at their range than this fraction are
  // dropped. Low: a hypothesis is ranged even when few of its pixels have a disparity (a
  // low-contrast object matches on its outline only).
  double min_valid_fraction = 0.02;
  // ... and fewer than this many.
  int min_valid_px = 8;
  // Depth modes: a region's trusted disparities that are separated by an empty gap of more than
  // this (pixels) are different surfaces, and the region is split between them. 0 never splits.
  double max_disparity_step_px = 1.0;
  // Pieces at one range join when the gap between their boxes is at most this fraction of the
  // larger box's largest side (fragments of one low-contrast object). 0 never joins.
  double join_gap_fraction = 0.25;
  // Pieces at one range that lie in one region of the appearance cue join across larger gaps:
  // the region says they are one object (a uniform fuselage between a matched nose and tail).
  // The gap allowed, as a fraction of the smaller box's largest side (a region holding a hangar
  // and a drone at its range is not one object): region_gap_fraction, 0 = any gap. SteViE's
  // regions are closed contours, object outlines: any gap; and with 0 a hypothesis alone in its
  // region, where no other trusted disparity lies, takes the region's box (the outline says how
  // far the object reaches where the stereo matched only part of it). SteViS's salient blobs can
  // span neighbouring objects: 2, chosen on the tuning seeds of stevi-eval's families (figures:
  // core/detection/README.md, "Measured").
  bool join_within_region = false;
  double region_gap_fraction = 0.0;
  // The blob's disparity is the median over its interior: the mask eroded by this many pixels
  // (0 = the whole mask), unless fewer than 30 interior pixels remain. Block matching spreads an
  // object's disparity a few pixels into its surroundings.
  int interior_erode_px = 5;
  // Terrain is not an obstacle: a blob whose depth grows by more than this many metres per metre
  // of height (least squares over its pixels: a surface leaning back, like a hillside) is dropped.
  // Obstacles show vertical faces (about 0). 0 disables. Blobs of fewer than 12 rows (at 640 px
  // wide) are never judged, and the lean must exceed three standard errors of the fit: over a
  // small height the slope is mostly disparity noise.
  double max_depth_per_height = 0.6;
  // Blobs spanning less than this height (metres at their range), or fewer than 12 rows, are too
  // short for that test: the surroundings test below judges them.
  double min_terrain_height_m = 3.0;
  // Blobs too short for that test are judged by their surroundings, when the ground model says they
  // reach below the horizon: one whose ring of trusted disparities 6..12 px out lies at its own
  // range (within max(1 px, 10 %)) for more than this fraction is a patch of a continuous surface
  // that a threshold cut out (the ground margin, the disparity floor), not something standing out
  // from it. 1 disables.
  double max_attached_fraction = 0.5;

  std::vector<std::string> Validate() const;

  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Number(s.min_area_px,
             Field("min_area_px", "pixels", "smaller hypotheses are dropped (processed pixels)")
                 .AtLeast(1));
    v.Number(s.max_width_fraction,
             Field("max_width_fraction", "", "wider blobs (skyline, ground) are dropped")
                 .Above(0)
                 .AtMost(1));
    v.Number(s.min_valid_fraction,
             Field("min_valid_fraction", "",
                   "fraction of the mask that needs a trusted disparity at its range")
                 .In(0, 1));
    v.Number(
        s.min_valid_px,
        Field("min_valid_px", "pixels", "trusted disparities needed at the range").In(0, 100000));
    v.Number(s.max_disparity_step_px, Field("max_disparity_step_px", "pixels",
                                            "a wider empty gap splits depth modes; 0 never")
                                          .In(0, 1000));
    v.Number(s.join_gap_fraction,
             Field("join_gap_fraction", "", "pieces this near (of the larger box) join; 0 never")
                 .In(0, 10));
    v.Flag(s.join_within_region,
           Field("join_within_region", "", "pieces in one appearance region join across gaps"));
    v.Number(s.region_gap_fraction, Field("region_gap_fraction", "",
                                          "largest gap within a region (of the smaller box); 0 any")
                                        .In(0, 100));
    v.Number(s.interior_erode_px,
             Field("interior_erode_px", "pixels", "mask erosion for the median disparity; 0 none")
                 .In(0, 50));
    v.Number(s.max_depth_per_height, Field("max_depth_per_height", "m/m",
                                           "terrain: steeper depth over height is dropped; 0 off")
                                         .In(0, 100));
    v.Number(s.min_terrain_height_m,
             Field("min_terrain_height_m", "m", "shorter blobs are never judged as terrain")
                 .In(0, 1000));
    v.Number(s.max_attached_fraction,
             Field("max_attached_fraction", "",
                   "short blobs with more of their ring at their range are dropped; 1 off")
                 .In(0, 1));
  }

  // The defaults, with join_within_region on and the given region_gap_fraction.
  static StereoBlobOptions JoiningWithinRegions(double gap_fraction) {
    StereoBlobOptions o;
    o.join_within_region = true;
    o.region_gap_fraction = gap_fraction;
    return o;
  }
};

// Fills the fields derived from d.disparity_px (depth, range, sigma, position) from the rig.
void FillRange(Detection& d, const geometry::StereoRig& rig, const geometry::RangeOptions& range);

}  // namespace stevi::detection
