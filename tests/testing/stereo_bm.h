// cv::StereoBM configured as the project's SAD block matcher (core/stereo/block_matcher.h): the
// reference its tests compare against and the baseline the stage benchmarks time.
#pragma once

#include <opencv2/calib3d.hpp>

#include "core/stereo/block_matcher.h"

namespace stevi::testing {

// cv::StereoBM with every parameter of `p`, the x-Sobel prefilter and no left-right check, all
// set explicitly (the last two are also OpenCV's defaults).
inline cv::Ptr<cv::StereoBM> StereoBMFor(const stereo::SadBlockMatcherParams& p) {
  cv::Ptr<cv::StereoBM> bm = cv::StereoBM::create(p.num_disparities, p.block_size);
  bm->setPreFilterType(cv::StereoBM::PREFILTER_XSOBEL);
  bm->setPreFilterCap(p.prefilter_cap);
  bm->setMinDisparity(p.min_disparity);
  bm->setTextureThreshold(p.texture_threshold);
  bm->setUniquenessRatio(p.uniqueness_ratio);
  bm->setSpeckleWindowSize(p.speckle_window_size);
  bm->setSpeckleRange(p.speckle_range);
  bm->setDisp12MaxDiff(-1);
  return bm;
}

}  // namespace stevi::testing
