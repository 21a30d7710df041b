#include "core/detection/stevie.h"

namespace stevi::detection {
namespace {

void Append(std::vector<std::string>& out, const char* prefix, const std::vector<std::string>& in) {
  for (const std::string& p : in) out.push_back(prefix + p);
}

}  // namespace

std::vector<std::string> SteViEOptions::Validate() const {
  std::vector<std::string> problems;
  Append(problems, "edges.", edges.Validate());
  Append(problems, "morphology.", morphology.Validate());
  Append(problems, "ground.", ground.Validate());
  Append(problems, "blobs.", blobs.Validate());
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
  std::vector<Detection> out = RangeBlobs(candidates, disparity, rig, range, options.blobs, "stevie");
  return out;
}

}  // namespace stevi::detection
