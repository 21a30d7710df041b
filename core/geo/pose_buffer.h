// A thread-safe buffer of recent vehicle states that gives the pose at a frame's capture time:
// position interpolated in a local tangent plane, attitude by quaternion slerp, and a short
// extrapolation with the NED velocity. When it cannot, it says why (GeoStatus and a message).
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/fields.h"
#include "core/common/error.h"
#include "core/geo/vehicle_state.h"

namespace stevi::geo {

// Why a frame has (or has not) a pose. The server sends it with each frame's tracks.
enum class GeoStatus {
  kOk,           // a pose was interpolated (or extrapolated within max_extrapolation_s)
  kNoPose,       // no state yet
  kPoseTooOld,   // the newest state is older than the frame by more than max_extrapolation_s
  kFrameTooOld,  // the frame is older than the newest state by more than max_age_s, or older
                 // than the oldest state kept
  kPoseGap,      // the states around the frame are more than max_gap_s apart
};

// "OK", "NO_POSE", "POSE_TOO_OLD", "FRAME_TOO_OLD", "POSE_GAP".
std::string_view GeoStatusName(GeoStatus status);

// The defaults suit a pose stream of 10 Hz or more.
struct PoseBufferOptions {
  // States kept (the oldest are dropped first), >= 2. 1000 is 10 s at 100 Hz.
  int capacity = 1000;
  // A frame time more than this before the newest state is refused (kFrameTooOld): its result
  // would be stale. Seconds, > 0.
  double max_age_s = 0.5;
  // A frame time up to this after the newest state is extrapolated (position with the NED
  // velocity, attitude with the last angular rate); later is refused (kPoseTooOld). Seconds, >= 0.
  double max_extrapolation_s = 0.1;
  // Two states further apart than this are not interpolated between (kPoseGap): the stream had a
  // dropout. Seconds, > 0.
  double max_gap_s = 0.5;

  // Every problem, as "field: problem (got X)".
  std::vector<std::string> Validate() const;
  bool operator==(const PoseBufferOptions&) const = default;

  // The fields of stevi.v1.GeoConfig (the capacity is not configurable over the wire).
  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Number(s.max_age_s,
             Field("max_age_s", "s", "oldest frame against the newest state").Above(0));
    v.Number(s.max_extrapolation_s,
             Field("max_extrapolation_s", "s", "extrapolation past the newest state").AtLeast(0));
    v.Number(s.max_gap_s, Field("max_gap_s", "s", "largest gap interpolated over").Above(0));
  }
};

// The answer of PoseBuffer::At.
struct PoseLookup {
  GeoStatus status = GeoStatus::kNoPose;
  // Why, for people and the wire: "ok", "no pose yet", "pose too old (0.82 s)",
  // "frame too old (0.82 s before the newest pose)", "pose gap (2.30 s)", ...
  std::string message;
  // Set exactly when status is kOk. Its state.t_ns is the requested time; its yaw is in
  // (-180, 180] degrees unless it is a stored state returned as is.
  std::optional<VehiclePose> pose;

  bool ok() const { return status == GeoStatus::kOk; }
};

// Thread-safe: Add() and At() may be called concurrently from any threads.
class PoseBuffer {
 public:
  // The options must be valid (call Validate() first): invalid options are a programming error
  // (std::invalid_argument listing the problems).
  explicit PoseBuffer(PoseBufferOptions options = {});

  // Appends a state. Refused (kInvalidArgument, naming the fields) when the state is invalid or
  // not strictly after the newest state; the buffer is then unchanged.
  Status Add(const VehicleState& state);

  // The pose at `t_ns` (the frame's capture time, same clock as VehicleState::t_ns).
  // Between two states s0 <= t <= s1: the position is interpolated linearly in the local NED
  // tangent plane at s0 (GeographicLib::LocalCartesian), the attitude by slerp, the velocity and
  // the sigmas linearly, and the angular rate is that of the slerp (constant between s0 and s1).
  // After the newest state (up to max_extrapolation_s): position + velocity * dt in the tangent
  // plane at the newest state, attitude turned by the angular rate of the last two states (zero if
  // there is only one, or they are more than max_gap_s apart).
  PoseLookup At(int64_t t_ns) const;

  void Clear();
  std::size_t size() const;
  std::optional<VehicleState> Newest() const;
  const PoseBufferOptions& options() const { return options_; }

 private:
  const PoseBufferOptions options_;
  mutable std::mutex mutex_;
  std::deque<VehicleState> states_;  // strictly increasing t_ns
};

}  // namespace stevi::geo
