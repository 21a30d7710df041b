// Internal to core/detection: the sub-pixel range of one hypothesis on the full-resolution pair
// (RefineDisparity over the hypothesis' pixels at its own range), used by RangeRegions. The patch
// refinement itself, RefineDisparity, is declared in regions.h and defined in patch_refinement.cc.
#pragma once

#include <optional>

#include <opencv2/core.hpp>

#include "core/detection/regions.h"

namespace stevi::detection {

// The disparity of a hypothesis measured on `full` (RefineDisparity from `median_px`, over the
// pixels of `mask`, the hypothesis' pixels in `box` of the processed image, whose class in
// `classes` is kCandidate and whose disparity in `fixed` lies at the hypothesis' own range), in
// processed pixels. nullopt when there is no fit, or when it lies too far from the median.
std::optional<RefinedDisparity> RefineOnFullPair(const FullResolutionPair& full,
                                                 const cv::Mat1s& fixed, const cv::Mat1b& classes,
                                                 const cv::Rect& box, const cv::Mat1b& mask,
                                                 double median_px);

}  // namespace stevi::detection
