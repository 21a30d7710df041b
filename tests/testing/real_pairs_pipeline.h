// Runs the pipeline on one real pair (real_pairs.h), as stevi-eval-real and real_pairs_test do.
// Header-only: whoever includes it links stevi_pipeline.
#pragma once

#include <memory>

#include "core/common/error.h"
#include "core/common/stereo_frame.h"
#include "core/geometry/stereo_rig.h"
#include "core/pipeline/config.h"
#include "core/pipeline/pipeline.h"
#include "tests/testing/gt_obstacles.h"
#include "tests/testing/real_pairs.h"

namespace stevi::testing {

// One frame of the pair through a fresh Pipeline with the default configuration but `algorithm`
// and `max_width_px`, on an ideal rectified rig of the pair (the pairs are rectified). The
// detections come from the front end, before the tracker, so one frame is enough.
inline Result<pipeline::FrameResult> RunPipelineOnPair(const RealPair& pair,
                                                       pipeline::Algorithm algorithm,
                                                       int max_width_px) {
  pipeline::PipelineConfig config = pipeline::ConfigForAlgorithm(algorithm);
  config.max_width_px = max_width_px;
  const auto rig = std::make_shared<const geometry::StereoRig>(geometry::StereoRig::Ideal(
      pair.left.size(), pair.f_px, pair.baseline_m, pair.cx, pair.cy, pair.name));
  const pipeline::Snapshot snapshot{std::make_shared<const pipeline::PipelineConfig>(config), rig};
  StereoFrame frame;
  frame.left = pair.left;
  frame.right = pair.right;
  frame.rectified = true;
  pipeline::Pipeline pipe;
  return pipe.Process(frame, snapshot);
}

// The frame's detections in camera pixels (boxes times FrameResult::binning), for ScoreDetections.
inline std::vector<ScoredBox> CameraBoxes(const pipeline::FrameResult& result) {
  std::vector<ScoredBox> boxes;
  const int bin = result.binning > 0 ? result.binning : 1;
  for (const detection::Detection& d : result.detections) {
    boxes.push_back(
        {cv::Rect(d.bbox.x * bin, d.bbox.y * bin, d.bbox.width * bin, d.bbox.height * bin),
         d.depth_m});
  }
  return boxes;
}

}  // namespace stevi::testing
