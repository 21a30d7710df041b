// The canonical detector (thesis section 4.1): blobs of the disparity map nearer than a range.
#pragma once

#include <string>
#include <vector>

#include "core/common/fields.h"
#include "core/detection/detection.h"
#include "core/detection/regions.h"
#include "core/detection/stereo_blobs.h"
#include "core/geometry/range.h"
#include "core/geometry/stereo_rig.h"
#include "core/stereo/disparity.h"

namespace stevi::detection {

struct CanonicalOptions {
  // Pixels nearer than this (metres) are obstacle candidates. 0: as far as the rig ranges to 5 %
  // (a disparity of 20 times range.disparity_sigma_px; 84 m on the demo rig, 840 m on a
  // telephoto of f B = 4200 px m).
  double threshold_range_m = 0.0;
  // Morphological opening (square, pixels at 640 px wide, odd; 1 disables) to cut thin bridges
  // between blobs.
  int open_size_px = 3;
  // Blobs, their filters and their range.
  StereoBlobOptions blobs;

  std::vector<std::string> Validate() const;

  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Number(s.threshold_range_m,
             Field("threshold_range_m", "m",
                   "nearer pixels are candidates; 0 = 20 disparity sigmas (5 % of depth)")
                 .AtLeast(0));
    v.Number(
        s.open_size_px,
        Field("open_size_px", "pixels", "opening at 640 px wide; 1 disables").Odd().AtLeast(1));
    v.Nested(s.blobs, Field("blobs"));
  }
};

// Detects obstacles in a disparity map of the rig's rectified left image.
std::vector<Detection> DetectCanonical(const stereo::DisparityMap& disparity,
                                       const geometry::StereoRig& rig,
                                       const geometry::RangeOptions& range,
                                       const CanonicalOptions& options,
                                       const FullResolutionPair* full = nullptr);

}  // namespace stevi::detection
