// Obstacle hypotheses that hold together: the appearance cue (closed edge contours for SteViE,
// salient segments for SteViS, the disparity's own clusters for the canonical detector) says what
// one object is, and the stereo says how far it is. How it works: core/detection/README.md.
#pragma once

#include <optional>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "core/detection/detection.h"
#include "core/detection/ground.h"
#include "core/detection/stereo_blobs.h"
#include "core/geometry/range.h"
#include "core/geometry/stereo_rig.h"
#include "core/stereo/disparity.h"

namespace stevi::detection {

// The rectified pair at the camera's own resolution, for the sub-pixel range of each hypothesis.
// When the pipeline bins its frames, the detectors work on the binned images while the range is
// measured on these (a box of the binned image times `binning`). Empty images: no refinement.
struct FullResolutionPair {
  cv::Mat1b left, right;  // grey, rectified, the camera's size
  int binning = 1;        // camera pixels per processed pixel
};

// Per-pixel evidence of the disparity map, as the hypotheses see it.
enum PixelClass : uint8_t {
  kNoDisparity = 0,  // unmatched, or an outlier of its region
  kCandidate = 1,    // trusted disparity standing out from the ground
  kGround = 2,       // trusted disparity on the ground (within the ground model's margin)
  kFar = 3,          // matched, below the trusted floor: farther than the rig can range
};

// Classifies every pixel of `disparity` (the same size as the map).
cv::Mat1b ClassifyPixels(const stereo::DisparityMap& disparity, const geometry::StereoRig& rig,
                         const geometry::RangeOptions& range,
                         const std::optional<GroundModel>& ground,
                         const GroundOptions& ground_options);

// Hypotheses from the regions of `appearance` (non-zero pixels, 8-connected), split where their
// trusted disparities form separate depth modes and joined with neighbouring pieces at the same
// range; filtered and ranged. `classes` is ClassifyPixels' output. `full` (optional) gives the
// sub-pixel range and its uncertainty.
std::vector<Detection> RangeRegions(const cv::Mat1b& appearance, const cv::Mat1b& classes,
                                    const stereo::DisparityMap& disparity,
                                    const geometry::StereoRig& rig,
                                    const geometry::RangeOptions& range,
                                    const StereoBlobOptions& options, std::string_view extractor,
                                    const std::optional<GroundModel>& ground,
                                    const FullResolutionPair* full);

// The stereo half of an appearance detector (SteViE's edges, SteViS's saliency): fits the ground
// when ground_options.enabled, classifies the pixels, and ranges the regions of `appearance` as
// RangeRegions does. `extractor` names the detector in each detection.
std::vector<Detection> RangeAppearance(const cv::Mat1b& appearance, std::string_view extractor,
                                       const stereo::DisparityMap& disparity,
                                       const geometry::StereoRig& rig,
                                       const geometry::RangeOptions& range,
                                       const GroundOptions& ground_options,
                                       const StereoBlobOptions& options,
                                       const FullResolutionPair* full);

// The disparity of one region measured on the full-resolution pair: the shift (and a vertical
// residual, a gain and an offset) that best maps the right image onto the left over the region's
// pixels, by robust Gauss-Newton from `initial_px` (camera pixels). The 1-sigma comes from the
// fit's residuals.
struct RefinedDisparity {
  double disparity_px = 0;  // camera pixels
  double sigma_px = 0;      // 1-sigma, camera pixels
  int pixels = 0;           // pixels that carried the fit
};
std::optional<RefinedDisparity> RefineDisparity(const cv::Mat1b& left, const cv::Mat1b& right,
                                                const cv::Mat1b& mask, const cv::Rect& box,
                                                double initial_px);

// A pixel size given for a 640-pixel-wide image, for an image `width_px` wide: odd, >= 1.
int ScaledKernel(int size_at_640, int width_px);

}  // namespace stevi::detection
