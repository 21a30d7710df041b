#include "core/geo/pose_buffer.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <deque>
#include <optional>
#include <stdexcept>
#include <utility>

#include <GeographicLib/LocalCartesian.hpp>

namespace stevi::geo {
namespace {

// (later - earlier) in seconds, for later >= earlier; exact in nanoseconds even when the signed
// difference would overflow.
double SecondsBetween(int64_t later, int64_t earlier) {
  const uint64_t diff_ns = static_cast<uint64_t>(later) - static_cast<uint64_t>(earlier);
  return static_cast<double>(diff_ns) / 1e9;  // correctly rounded: 100 ms is exactly 0.1
}

PoseLookup Refused(GeoStatus status, const char* format, double seconds) {
  char buf[128];
  std::snprintf(buf, sizeof buf, format, seconds);
  return PoseLookup{status, buf, std::nullopt};
}

// The body angular rate (rad/s, body axes) that turns s0's attitude into s1's at a constant rate:
// ned_from_body(t) = q0 * exp(omega * (t - t0)), the path of the slerp.
Eigen::Vector3d AngularRate(const VehicleState& s0, const VehicleState& s1) {
  const double dt = SecondsBetween(s1.t_ns, s0.t_ns);
  if (!(dt > 0)) return Eigen::Vector3d::Zero();
  Eigen::Quaterniond delta = NedFromBody(s0).conjugate() * NedFromBody(s1);
  if (delta.w() < 0) delta.coeffs() = -delta.coeffs();  // the shorter way, as slerp goes
  const Eigen::AngleAxisd aa(delta.normalized());
  return aa.axis() * (aa.angle() / dt);
}

void SetAttitude(VehicleState& state, const Eigen::Quaterniond& ned_from_body) {
  const EulerDeg e = EulerFromNedFromBody(ned_from_body);
  state.roll_deg = e.roll_deg;
  state.pitch_deg = e.pitch_deg;
  state.yaw_deg = e.yaw_deg;
}

double Lerp(double a, double b, double w) { return a + (b - a) * w; }

const PoseBufferOptions& Checked(const PoseBufferOptions& options) {
  if (std::vector<std::string> problems = options.Validate(); !problems.empty()) {
    throw std::invalid_argument("PoseBufferOptions: " + InvalidArgument(problems).message);
  }
  return options;
}

// The states around a frame's time, as PoseBuffer::At uses them.
struct Around {
  enum class Case { kExact, kInterpolate, kExtrapolate };
  Case kind = Case::kExact;
  VehicleState s0;  // kExact: the state; kInterpolate: the one before; kExtrapolate: unused
  VehicleState s1;  // kInterpolate: the one after; kExtrapolate: the newest
  std::optional<std::pair<VehicleState, VehicleState>> rate_pair;  // for the angular rate
};

// The states of `states` (strictly increasing t_ns) around t_ns into `around`; the refusal when
// there is no pose for t_ns (none yet, too old, too far ahead, across a gap), else nullopt.
std::optional<PoseLookup> FindAround(const std::deque<VehicleState>& states,
                                     const PoseBufferOptions& options, int64_t t_ns,
                                     Around& around) {
  using Case = Around::Case;
  if (states.empty()) return PoseLookup{GeoStatus::kNoPose, "no pose yet", std::nullopt};
  const VehicleState& newest = states.back();
  const std::size_t n = states.size();
  if (t_ns > newest.t_ns) {
    const double ahead_s = SecondsBetween(t_ns, newest.t_ns);
    if (ahead_s > options.max_extrapolation_s) {
      return Refused(GeoStatus::kPoseTooOld, "pose too old (%.2f s)", ahead_s);
    }
    around.kind = Case::kExtrapolate;
    around.s1 = newest;
    if (n >= 2) around.rate_pair.emplace(states[n - 2], newest);
    return std::nullopt;
  }
  const double behind_s = SecondsBetween(newest.t_ns, t_ns);
  if (behind_s > options.max_age_s) {
    return Refused(GeoStatus::kFrameTooOld, "frame too old (%.2f s before the newest pose)",
                   behind_s);
  }
  if (t_ns < states.front().t_ns) {
    return Refused(GeoStatus::kFrameTooOld, "frame before the oldest pose (%.2f s)",
                   SecondsBetween(states.front().t_ns, t_ns));
  }
  // The first state after t_ns (there is one unless t_ns is the newest's time).
  const auto after = std::upper_bound(states.begin(), states.end(), t_ns,
                                      [](int64_t t, const VehicleState& s) { return t < s.t_ns; });
  const std::size_t i = static_cast<std::size_t>(after - states.begin());  // >= 1
  around.s0 = states[i - 1];
  if (around.s0.t_ns == t_ns) {
    around.kind = Case::kExact;
    if (i < n) {
      around.rate_pair.emplace(around.s0, states[i]);
    } else if (i >= 2) {
      around.rate_pair.emplace(states[i - 2], around.s0);
    }
    return std::nullopt;
  }
  around.kind = Case::kInterpolate;
  around.s1 = states[i];
  const double gap_s = SecondsBetween(around.s1.t_ns, around.s0.t_ns);
  if (gap_s > options.max_gap_s) {
    return Refused(GeoStatus::kPoseGap, "pose gap (%.2f s) at the frame", gap_s);
  }
  around.rate_pair.emplace(around.s0, around.s1);
  return std::nullopt;
}

// The state at t_ns between s0 and s1: the position linear in the local tangent plane at s0, the
// attitude by slerp, the velocity and the sigmas linear.
VehicleState Interpolate(const VehicleState& s0, const VehicleState& s1, int64_t t_ns) {
  const double w = SecondsBetween(t_ns, s0.t_ns) / SecondsBetween(s1.t_ns, s0.t_ns);
  VehicleState s = s0;
  s.t_ns = t_ns;
  // Position: linear in the local tangent plane at s0 (east, north, up).
  const GeographicLib::LocalCartesian local(s0.lat_deg, s0.lon_deg, s0.alt_m);
  double e = 0, n = 0, u = 0;
  local.Forward(s1.lat_deg, s1.lon_deg, s1.alt_m, e, n, u);
  local.Reverse(w * e, w * n, w * u, s.lat_deg, s.lon_deg, s.alt_m);
  SetAttitude(s, NedFromBody(s0).slerp(w, NedFromBody(s1)));
  s.velocity_ned_mps = s0.velocity_ned_mps + (s1.velocity_ned_mps - s0.velocity_ned_mps) * w;
  s.sigma.horizontal_m = Lerp(s0.sigma.horizontal_m, s1.sigma.horizontal_m, w);
  s.sigma.vertical_m = Lerp(s0.sigma.vertical_m, s1.sigma.vertical_m, w);
  s.sigma.tilt_deg = Lerp(s0.sigma.tilt_deg, s1.sigma.tilt_deg, w);
  s.sigma.yaw_deg = Lerp(s0.sigma.yaw_deg, s1.sigma.yaw_deg, w);
  return s;
}

// The state at t_ns after the newest state s1: the position moved by s1's NED velocity in the
// tangent plane at s1, the attitude turned by the body angular rate.
VehicleState Extrapolate(const VehicleState& s1, int64_t t_ns,
                         const Eigen::Vector3d& angular_rate_body_rps) {
  const double dt = SecondsBetween(t_ns, s1.t_ns);
  VehicleState s = s1;
  s.t_ns = t_ns;
  const Eigen::Vector3d d_ned = s1.velocity_ned_mps * dt;
  const GeographicLib::LocalCartesian local(s1.lat_deg, s1.lon_deg, s1.alt_m);
  local.Reverse(d_ned.y(), d_ned.x(), -d_ned.z(), s.lat_deg, s.lon_deg, s.alt_m);
  const Eigen::Vector3d turn = angular_rate_body_rps * dt;
  const double angle = turn.norm();
  Eigen::Quaterniond q = NedFromBody(s1);
  if (angle > 0) q = q * Eigen::Quaterniond(Eigen::AngleAxisd(angle, turn / angle));
  SetAttitude(s, q);
  return s;
}

}  // namespace

std::string_view GeoStatusName(GeoStatus status) {
  switch (status) {
    case GeoStatus::kOk: return "OK";
    case GeoStatus::kNoPose: return "NO_POSE";
    case GeoStatus::kPoseTooOld: return "POSE_TOO_OLD";
    case GeoStatus::kFrameTooOld: return "FRAME_TOO_OLD";
    case GeoStatus::kPoseGap: return "POSE_GAP";
  }
  return "UNKNOWN";
}

std::vector<std::string> PoseBufferOptions::Validate() const {
  std::vector<std::string> problems = fields::Check(*this);
  if (capacity < 2) problems.push_back("capacity: must be >= 2 states" + Got(capacity));
  return problems;
}

PoseBuffer::PoseBuffer(PoseBufferOptions options) : options_(Checked(options)) {}

Status PoseBuffer::Add(const VehicleState& state) {
  if (std::vector<std::string> problems = state.Validate(); !problems.empty()) {
    return InvalidArgument(problems);
  }
  std::lock_guard lock(mutex_);
  if (!states_.empty() && state.t_ns <= states_.back().t_ns) {
    char buf[160];
    std::snprintf(buf, sizeof buf,
                  "t_ns: out of order: %lld ns is not after the newest state (%lld ns)",
                  static_cast<long long>(state.t_ns), static_cast<long long>(states_.back().t_ns));
    return InvalidArgument(buf);
  }
  states_.push_back(state);
  while (states_.size() > static_cast<std::size_t>(options_.capacity)) states_.pop_front();
  return Status::Ok();
}

PoseLookup PoseBuffer::At(int64_t t_ns) const {
  Around around;
  {
    std::lock_guard lock(mutex_);
    if (std::optional<PoseLookup> refused = FindAround(states_, options_, t_ns, around)) {
      return std::move(*refused);
    }
  }

  VehiclePose pose;
  const auto& rate_pair = around.rate_pair;
  if (rate_pair &&
      SecondsBetween(rate_pair->second.t_ns, rate_pair->first.t_ns) <= options_.max_gap_s) {
    pose.angular_rate_body_rps = AngularRate(rate_pair->first, rate_pair->second);
  }

  switch (around.kind) {
    case Around::Case::kExact: pose.state = around.s0; break;
    case Around::Case::kInterpolate: pose.state = Interpolate(around.s0, around.s1, t_ns); break;
    case Around::Case::kExtrapolate:
      pose.state = Extrapolate(around.s1, t_ns, pose.angular_rate_body_rps);
      pose.extrapolated = true;
      break;
  }
  return PoseLookup{GeoStatus::kOk, "ok", std::move(pose)};
}

void PoseBuffer::Clear() {
  std::lock_guard lock(mutex_);
  states_.clear();
}

std::size_t PoseBuffer::size() const {
  std::lock_guard lock(mutex_);
  return states_.size();
}

std::optional<VehicleState> PoseBuffer::Newest() const {
  std::lock_guard lock(mutex_);
  if (states_.empty()) return std::nullopt;
  return states_.back();
}

}  // namespace stevi::geo
