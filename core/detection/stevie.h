// SteViE, stereo plus edges (thesis chapter 4): the shapes come from the left image's edges, closed
// and filled into regions; the stereo keeps the regions' pixels that have a trusted disparity and
// stand out from the ground; each blob gets the median disparity of its interior.
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/fields.h"
#include "core/detection/detection.h"
#include "core/detection/ground.h"
#include "core/detection/regions.h"
#include "core/detection/stereo_blobs.h"
#include "core/extraction/edges.h"
#include "core/extraction/morphology.h"
#include "core/geometry/range.h"
#include "core/geometry/stereo_rig.h"
#include "core/stereo/disparity.h"

namespace stevi::detection {

struct SteViEOptions {
  extraction::EdgeOptions edges;             // Gaussian + Canny
  extraction::MorphologyOptions morphology;  // close the contours, fill, open to separate
  GroundOptions ground;                      // the ground and what lies on it are not obstacles
  StereoBlobOptions blobs = StereoBlobOptions::JoiningWithinRegions(0.0);

  // Every problem, prefixed with the sub-struct ("edges.canny_low: ...").
  std::vector<std::string> Validate() const;

  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Nested(s.edges, Field("edges"));
    v.Nested(s.morphology, Field("morphology"));
    v.Nested(s.ground, Field("ground"));
    v.Nested(s.blobs, Field("blobs"));
  }
};

// `left` is the rectified left image (8-bit grey) that `disparity` belongs to.
std::vector<Detection> DetectSteViE(const cv::Mat1b& left, const stereo::DisparityMap& disparity,
                                    const geometry::StereoRig& rig,
                                    const geometry::RangeOptions& range,
                                    const SteViEOptions& options,
                                    const FullResolutionPair* full = nullptr);

}  // namespace stevi::detection
