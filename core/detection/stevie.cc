#include "core/detection/stevie.h"

#include "core/common/error.h"

namespace stevi::detection {
std::vector<std::string> SteViEOptions::Validate() const {
  std::vector<std::string> problems;
  AppendPrefixed(problems, "edges.", edges.Validate());
  AppendPrefixed(problems, "morphology.", morphology.Validate());
  AppendPrefixed(problems, "ground.", ground.Validate());
  AppendPrefixed(problems, "blobs.", blobs.Validate());
  return problems;
}

std::vector<Detection> DetectSteViE(const cv::Mat1b& left, const stereo::DisparityMap& disparity,
                                    const geometry::StereoRig& rig,
                                    const geometry::RangeOptions& range,
                                    const SteViEOptions& options) {
  if (left.empty() || disparity.empty() || left.size() != disparity.fixed.size()) return {};
  const cv::Mat1b regions =
      extraction::CloseFillOpen(extraction::DetectEdges(left, options.edges), options.morphology);
  const std::optional<GroundModel> ground =
      options.ground.enabled ? FitGround(disparity, options.ground) : std::nullopt;
  const cv::Mat1b candidates =
      StereoCandidates(regions, disparity, rig, range, ground, options.ground);
  std::vector<Detection> out = RangeBlobs(candidates, disparity, rig, range, options.blobs, "stevie", ground);
  return out;
}

}  // namespace stevi::detection
