// A picture for people: the rectified left image with each track's box, id and range.
#pragma once

#include <opencv2/core.hpp>

#include "core/pipeline/pipeline.h"

namespace stevi::pipeline {

// BGR copy of the frame's rectified left image with a box per track, labelled with its track id
// and its range in metres with the 1-sigma error: confirmed tracks orange, coasting ones (box and
// range predicted, "(pred)") blue-grey, tentative ones thin yellow ("?").
cv::Mat3b AnnotateTracks(const FrameResult& result);

}  // namespace stevi::pipeline
