// The calibration of the synthetic renderer's rig, for tests and tools that hand its frames to a
// binary as files (images, video, RTSP) with a --calibration YAML.
#pragma once

#include <opencv2/core.hpp>

#include "core/geometry/calibration_io.h"
#include "drivers/synthetic/synthetic_source.h"

namespace stevi::testing {

// The ideal (rectified, undistorted) calibration of the rig `options` renders with: its focal
// length and baseline, the principal point at the image centre.
inline geometry::StereoCalibration SyntheticCalibration(const drivers::SyntheticOptions& options) {
  return geometry::IdealCalibration(cv::Size(options.width, options.height), options.f_px,
                                    options.baseline_m, options.width / 2.0, options.height / 2.0);
}

}  // namespace stevi::testing
