#include "core/detection/stevis.h"

#include <string>
#include <vector>

#include <opencv2/imgproc.hpp>

namespace stevi::detection {
std::vector<std::string> SteViSOptions::Validate() const {
  std::vector<std::string> problems = fields::Check(*this);
  // The graph's options matter in graph mode only.
  if (segmentation != Segmentation::kGraph) {
    std::erase_if(problems, [](const std::string& p) { return p.starts_with("graph."); });
  }
  return problems;
}

cv::Mat1b SalientRegions(const cv::Mat1b& left, const SteViSOptions& options) {
  const cv::Mat1f saliency = extraction::SaliencyAtFullSize(left, options.saliency);
  cv::Mat1b mask;
  if (options.segmentation == SteViSOptions::Segmentation::kThreshold) {
    cv::compare(saliency, options.saliency_threshold, mask, cv::CMP_GE);
    extraction::MorphologyOptions morphology = options.morphology;
    morphology.close_size = ScaledKernel(morphology.close_size, left.cols);
    morphology.open_size = ScaledKernel(morphology.open_size, left.cols);
    return extraction::CloseFillOpen(mask, morphology);
  }
  // Graph segments at reduced scale; a segment is salient when its mean saliency is.
  const double scale = 1.0 / (1 << options.graph_level);
  cv::Mat1b small = left;
  cv::Mat1f small_saliency = saliency;
  if (options.graph_level > 0) {
    cv::resize(left, small, cv::Size(), scale, scale, cv::INTER_AREA);
    cv::resize(saliency, small_saliency, small.size(), 0, 0, cv::INTER_AREA);
  }
  const cv::Mat1i segments = extraction::SegmentGraph(small, options.graph);
  double max_label = 0;
  cv::minMaxLoc(segments, nullptr, &max_label);
  std::vector<double> sum(static_cast<size_t>(max_label) + 1, 0.0);
  std::vector<int> count(sum.size(), 0);
  for (int y = 0; y < segments.rows; ++y) {
    for (int x = 0; x < segments.cols; ++x) {
      sum[segments(y, x)] += small_saliency(y, x);
      ++count[segments(y, x)];
    }
  }
  cv::Mat1b small_mask(segments.size());
  for (int y = 0; y < segments.rows; ++y) {
    for (int x = 0; x < segments.cols; ++x) {
      const int s = segments(y, x);
      small_mask(y, x) = sum[s] >= options.saliency_threshold * count[s] ? 255 : 0;
    }
  }
  if (options.graph_level == 0) return small_mask;
  cv::resize(small_mask, mask, left.size(), 0, 0, cv::INTER_NEAREST);
  return mask;
}

std::vector<Detection> DetectSteViS(const cv::Mat1b& left, const stereo::DisparityMap& disparity,
                                    const geometry::StereoRig& rig,
                                    const geometry::RangeOptions& range,
                                    const SteViSOptions& options, const FullResolutionPair* full) {
  if (left.empty() || disparity.empty() || left.size() != disparity.fixed.size()) return {};
  const cv::Mat1b salient = SalientRegions(left, options);
  return RangeAppearance(salient, "stevis", disparity, rig, range, options.ground, options.blobs,
                         full);
}

}  // namespace stevi::detection
