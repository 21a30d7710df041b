// Internal to core/detection: the two surface tests of RangeRegions' filters (step 3), which tell
// a patch of a continuous surface (AttachedFraction) and terrain leaning back or level ground
// (LeanBack) from an obstacle standing up.
#pragma once

#include <opencv2/core.hpp>

#include "core/geometry/stereo_rig.h"
#include "core/stereo/disparity.h"

namespace stevi::detection {

// The fraction of trusted disparities in a ring around the label's mask that lie at its range
// (see StereoBlobOptions::max_attached_fraction). -1 when the ring holds too few.
double AttachedFraction(const stereo::DisparityMap& disparity, const cv::Mat1i& labels, int label,
                        const cv::Rect& box, double median_px, double min_disparity_px, int ring_in,
                        int ring_out);

// How far the surface under the label's pixels leans back, as dZ/dH (metres of depth per metre of
// height; 0 for a vertical face, infinite for level ground). A plane n . P = D in the camera frame
// has the disparity d(u, v) = (B / D) (n_x (u - cx) + n_y (v - cy) + n_z f): linear in (u, v) for
// any plane, so the fit d = alpha u + beta v + gamma is well conditioned even for flat ground
// (whose depth, not height, varies), and n_y / n_z = beta f / (gamma + alpha cx + beta cy). 0 when
// the lean is not significant (beta within 3 standard errors of 0) or the label spans too few rows.
double LeanBack(const stereo::DisparityMap& disparity, const cv::Mat1i& labels, int label,
                const cv::Rect& box, double median_px, const geometry::StereoRig& rig,
                int min_rows);

}  // namespace stevi::detection
