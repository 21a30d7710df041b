#include "server/runtime/pose_source.h"

#include <utility>

namespace stevi::server {

Result<std::unique_ptr<PoseSource>> PoseSource::Create(
    const geo::PoseBufferOptions& options, const std::optional<geo::VehicleState>& fixed) {
  std::vector<std::string> problems;
  AppendPrefixed(problems, "geo.", options.Validate());
  if (fixed) AppendPrefixed(problems, "geo.fixed_pose.", fixed->Validate());
  if (!problems.empty()) return InvalidArgument(problems);
  return std::unique_ptr<PoseSource>(new PoseSource(options, fixed));
}

void PoseSource::SetRecordedStates(const std::vector<geo::VehicleState>& states) {
  for (const geo::VehicleState& s : states) recorded_[s.t_ns] = s;
}

geo::PoseLookup PoseSource::At(int64_t t_ns, int64_t unix_time_ns) const {
  if (buffer_.size() > 0 || (!fixed_ && !path_ && recorded_.empty())) {
    return buffer_.At(unix_time_ns);
  }
  if (!recorded_.empty()) {
    geo::PoseLookup lookup;
    const auto it = recorded_.find(unix_time_ns);
    if (it == recorded_.end()) {
      lookup.status = geo::GeoStatus::kNoPose;
      lookup.message = "no pose was recorded with this frame";
      return lookup;
    }
    lookup.status = geo::GeoStatus::kOk;
    lookup.message = "recorded pose";
    lookup.pose = geo::VehiclePose{it->second, Eigen::Vector3d::Zero(), false};
    return lookup;
  }
  if (path_) {
    geo::PoseLookup lookup;
    lookup.status = geo::GeoStatus::kOk;
    lookup.message = "synthetic flight";
    geo::VehiclePose pose;
    pose.state = path_(t_ns);
    pose.state.t_ns = unix_time_ns;
    lookup.pose = pose;
    return lookup;
  }
  geo::PoseLookup lookup;
  lookup.status = geo::GeoStatus::kOk;
  lookup.message = "fixed pose";
  geo::VehiclePose pose;
  pose.state = *fixed_;
  pose.state.t_ns = unix_time_ns;
  lookup.pose = pose;
  return lookup;
}

Status PoseSource::Publish(const geo::VehicleState& state) { return buffer_.Add(state); }

}  // namespace stevi::server
