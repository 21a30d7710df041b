// A picture for people: the rectified left image with each detection's box, id and range.
#pragma once

#include <opencv2/core.hpp>

#include "core/pipeline/pipeline.h"

namespace stevi::pipeline {

// BGR copy of the frame's rectified left image with a box per detection, labelled with its id
// (1-based, as the frame's tracks are numbered) and its range in metres with the 1-sigma error.
cv::Mat3b AnnotateDetections(const FrameResult& result);

}  // namespace stevi::pipeline
