#include "core/detection/stevie.h"

#include <algorithm>

#include "core/stereo/matcher.h"

namespace stevi::detection {
namespace {
constexpr double kEdgeReferenceNoise = 2.0;
}  // namespace
std::vector<std::string> SteViEOptions::Validate() const { return fields::Check(*this); }

std::vector<Detection> DetectSteViE(const cv::Mat1b& left, const stereo::DisparityMap& disparity,
                                    const geometry::StereoRig& rig,
                                    const geometry::RangeOptions& range,
                                    const SteViEOptions& options, const FullResolutionPair* full) {
  if (left.empty() || disparity.empty() || left.size() != disparity.fixed.size()) return {};
  // The morphology's sizes are given for a 640-pixel-wide image.
  extraction::MorphologyOptions morphology = options.morphology;
  morphology.close_size = ScaledKernel(morphology.close_size, left.cols);
  morphology.open_size = ScaledKernel(morphology.open_size, left.cols);
  // The Canny thresholds are given for a pixel noise of 2 grey levels and follow the frame's own
  // (within a factor of 2 either way): noise must not draw contours, nor a faint outline vanish.
  extraction::EdgeOptions edges = options.edges;
  const double noise_scale =
      std::clamp(stereo::EstimateNoiseSigma(left) / kEdgeReferenceNoise, 0.5, 2.0);
  edges.canny_low *= noise_scale;
  edges.canny_high *= noise_scale;
  const cv::Mat1b regions =
      extraction::CloseFillOpen(extraction::DetectEdges(left, edges), morphology);
  return RangeAppearance(regions, "stevie", disparity, rig, range, options.ground, options.blobs,
                         full);
}

}  // namespace stevi::detection
