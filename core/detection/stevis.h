// SteViS, stereo plus saliency (thesis chapter 4): a VOCUS-style saliency map of the left image
// marks what stands out to the eye, either by a threshold or by keeping the graph-based segments
// (Felzenszwalb-Huttenlocher) whose mean saliency is high; the stereo then keeps the pixels that
// have a trusted disparity and stand out from the ground, and ranges the blobs.
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/fields.h"
#include "core/detection/detection.h"
#include "core/detection/ground.h"
#include "core/detection/regions.h"
#include "core/detection/stereo_blobs.h"
#include "core/extraction/morphology.h"
#include "core/extraction/saliency.h"
#include "core/extraction/segmentation.h"
#include "core/geometry/range.h"
#include "core/geometry/stereo_rig.h"
#include "core/stereo/disparity.h"

namespace stevi::detection {

struct SteViSOptions {
  enum class Segmentation {
    kThreshold,  // saliency >= saliency_threshold (fast)
    kGraph,      // graph segments whose mean saliency >= saliency_threshold
  };

  extraction::SaliencyOptions saliency;
  Segmentation segmentation = Segmentation::kThreshold;
  // Salient when the map (in [0, 1]) reaches this.
  double saliency_threshold = 0.02;
  // Threshold mode: the salient mask is closed, filled and opened, so that a textured object whose
  // saliency is patchy becomes one region.
  extraction::MorphologyOptions morphology = {extraction::StructuringShape::kEllipse, 3, 3, true};
  // Graph segmentation, run on the left image shrunk by 2^graph_level.
  extraction::GraphSegmentationOptions graph;
  int graph_level = 1;
  GroundOptions ground;
  StereoBlobOptions blobs = StereoBlobOptions::JoiningWithinRegions(2.0);

  // Every problem, prefixed with the sub-struct; graph's only in graph mode.
  std::vector<std::string> Validate() const;

  static constexpr fields::ChoiceName<Segmentation> kSegmentationNames[] = {
      {Segmentation::kThreshold, "threshold"}, {Segmentation::kGraph, "graph"}};
  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Nested(s.saliency, Field("saliency"));
    v.Choice(s.segmentation, Field("segmentation", "", "how the saliency map becomes regions"),
             kSegmentationNames);
    v.Number(s.saliency_threshold,
             Field("saliency_threshold", "", "salient when the map (in [0, 1]) reaches this")
                 .Above(0)
                 .AtMost(1));
    v.Nested(s.morphology, Field("morphology"));
    v.Nested(s.graph, Field("graph"));
    v.Number(s.graph_level,
             Field("graph_level", "", "graph mode: the image is shrunk by 2^graph_level").In(0, 3));
    v.Nested(s.ground, Field("ground"));
    v.Nested(s.blobs, Field("blobs"));
  }
};

std::vector<Detection> DetectSteViS(const cv::Mat1b& left, const stereo::DisparityMap& disparity,
                                    const geometry::StereoRig& rig,
                                    const geometry::RangeOptions& range,
                                    const SteViSOptions& options,
                                    const FullResolutionPair* full = nullptr);

// The appearance mask alone (255 where salient), at the size of `left`.
cv::Mat1b SalientRegions(const cv::Mat1b& left, const SteViSOptions& options);

}  // namespace stevi::detection
