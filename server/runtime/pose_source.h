// Where the server's vehicle pose comes from: states the autopilot publishes (PublishVehicleState)
// into a pose buffer, else a fixed pose from the configuration, else none (tracks then go out
// without geodetic positions, and the frame says why).
#pragma once

#include <functional>
#include <optional>
#include <unordered_map>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/error.h"
#include "core/geo/pose_buffer.h"
#include "core/geo/vehicle_state.h"

namespace stevi::server {

// Thread-safe.
class PoseSource {
 public:
  // The published states' buffer options and the fixed pose (nullopt: none): kInvalidArgument
  // naming every bad field as the configuration's GeoConfig names it ("geo.max_age_s: ...",
  // "geo.fixed_pose.lat_deg: ...").
  static Result<std::unique_ptr<PoseSource>> Create(const geo::PoseBufferOptions& options,
                                                    const std::optional<geo::VehicleState>& fixed);

  // The synthetic rig's own flight: its pose at a frame's source time (t_ns, the scene clock).
  // Used instead of the fixed pose until an autopilot publishes states. Set before the engine
  // starts.
  void SetSyntheticPath(std::function<geo::VehicleState(int64_t t_ns)> path) {
    path_ = std::move(path);
  }

  // A replay's recorded poses (drivers::ReplaySource::vehicle_states()): each frame's pose was
  // recorded with the frame's wall-clock time, and is found again by it, exactly. Used instead of
  // the fixed pose and the synthetic path. Set before the engine starts.
  void SetRecordedStates(const std::vector<geo::VehicleState>& states);

  // The pose at a frame's capture time (Unix ns): from the published states once any arrived,
  // else the recorded one of a replay, else the synthetic path, else the fixed pose (its time set
  // to the frame's), else kNoPose.
  geo::PoseLookup At(int64_t t_ns, int64_t unix_time_ns) const;
  // A published state: refused (kInvalidArgument naming the field, or out of order) without
  // changing anything.
  Status Publish(const geo::VehicleState& state);

 private:
  PoseSource(geo::PoseBufferOptions options, std::optional<geo::VehicleState> fixed)
      : buffer_(options), fixed_(std::move(fixed)) {}

  geo::PoseBuffer buffer_;
  const std::optional<geo::VehicleState> fixed_;
  std::function<geo::VehicleState(int64_t)> path_;
  std::unordered_map<int64_t, geo::VehicleState> recorded_;  // by the frame's unix_time_ns
};

}  // namespace stevi::server
