// The canonical detector (thesis section 4.1): blobs of the disparity map nearer than a range.
#pragma once

#include <string>
#include <vector>

#include "core/detection/detection.h"
#include "core/geometry/range.h"
#include "core/geometry/stereo_rig.h"
#include "core/stereo/disparity.h"

namespace stevi::detection {

struct CanonicalOptions {
  // Pixels nearer than this (metres) are obstacle candidates.
  double threshold_range_m = 80.0;
  // Blobs smaller than this (pixels) are dropped.
  int min_area_px = 60;
  // Blobs wider than this fraction of the image width (the skyline, the ground) are dropped.
  double max_width_fraction = 0.8;
  // Morphological opening (square, pixels, odd; 1 disables) to cut thin bridges between blobs.
  int open_size_px = 3;
  // Neighbouring pixels whose disparities differ by more than this (pixels) belong to different
  // blobs, so that touching obstacles at different ranges separate. 0 joins every neighbour.
  double max_disparity_step_px = 1.0;
  // The blob's disparity is the median over its interior: the mask eroded by this many pixels
  // (0 = the whole mask), unless fewer than 30 interior pixels remain.
  int interior_erode_px = 5;
  // Blobs whose mask has fewer trusted disparities than this fraction are dropped.
  double min_valid_fraction = 0.3;

  std::vector<std::string> Validate() const;
};

// Detects obstacles in a disparity map of the rig's rectified left image.
std::vector<Detection> DetectCanonical(const stereo::DisparityMap& disparity,
                                       const geometry::StereoRig& rig,
                                       const geometry::RangeOptions& range,
                                       const CanonicalOptions& options);

// Fills disparity_px's derived fields of `d` (depth, range, sigma, position) from the rig.
// Shared by every detector.
void FillRange(Detection& d, const geometry::StereoRig& rig, const geometry::RangeOptions& range);

}  // namespace stevi::detection
