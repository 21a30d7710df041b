// Collision advisories for an autopilot from obstacle tracks: closest point of approach against
// the vehicle's own velocity, a level (CLEAR, CAUTION, WARNING, AVOID), and a watchdog that says
// NO_DATA when the tracks stop. Plain structs only (no protobuf): the `stevi avoid` command maps
// the stream's messages onto them, so the logic is testable alone.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace stevi::client {

// A vector in a local north-east-down frame: metres for positions, m/s for velocities.
struct Ned {
  double n = 0;
  double e = 0;
  double d = 0;

  bool operator==(const Ned&) const = default;
};

// The vehicle's own state in the same local NED frame as the obstacles (the caller converts from
// WGS84, e.g. around the vehicle's current position).
struct OwnVehicle {
  Ned position_m;
  Ned velocity_mps;  // over the ground
};

enum class ObstacleState {
  kTentative,  // not yet confirmed by the tracker: may be clutter
  kConfirmed,  // detected in this frame
  kCoasting,   // confirmed, not detected in this frame: position predicted
};

struct Obstacle {
  std::uint64_t track_id = 0;
  Ned position_m;    // local NED
  Ned velocity_mps;  // over the ground
  // 1-sigma of the position, metres, >= 0: per horizontal axis (north and east each) and down.
  double sigma_horizontal_m = 0;
  double sigma_vertical_m = 0;
  // 1-sigma of the obstacle's speed along the line of sight, m/s, >= 0 (the track's
  // range_rate_sigma_mps). An approach slower than sigma_factor times this is velocity noise, not
  // closing: a young track's first velocity estimate must not raise an alarm.
  double range_rate_sigma_mps = 0;
  // Detections the track has had (Track.hits); 0 = unknown (then it counts as established).
  uint32_t hits = 0;
  ObstacleState state = ObstacleState::kConfirmed;
  double score = 1;  // 0..1, of the last detection
};

// Ordered by severity: a larger value is worse. kNoData is not a severity but the absence of one.
enum class AdvisoryLevel {
  kNoData,  // no fresh tracks: the obstacle picture is unknown, never read as clear
  kClear,
  kCaution,
  kWarning,
  kAvoid,
};

// "NO_DATA", "CLEAR", "CAUTION", "WARNING", "AVOID".
std::string_view AdvisoryLevelName(AdvisoryLevel level);

// The level rules. Each obstacle gets a protected radius
//   R = protected_radius_m + sigma_factor * max(sigma_horizontal_m, sigma_vertical_m)
// (a sphere: the position uncertainty widens it, whichever way the miss lies). With t_cpa and
// d_cpa the time and distance of the closest point of approach (see Encounter), the first rule
// that holds gives the level:
//   AVOID    d_cpa <  R                          and t_cpa <= avoid_time_s
//   WARNING  d_cpa <  warning_radius_factor * R  and t_cpa <= warning_time_s
//   CAUTION  d_cpa <  caution_radius_factor * R  and t_cpa <= caution_time_s,
//            or the distance now < caution_range_m
//   CLEAR    otherwise.
// t_cpa is clamped at 0, so an obstacle that is already inside R counts as being there now, even
// when it is receding (a separation lost is still lost). But an obstacle that is not closing
// and is outside R is CLEAR, unless the caution_range_m rule holds: it will never come nearer than
// it is, so it needs no warning. Closing means a speed along the line of sight towards the vehicle,
// -p.v / |p|, above sigma_factor * range_rate_sigma_mps: receding, at its closest now, or
// approaching within the velocity noise of a young track is not closing.
// The defaults suit a small UAV whose stereo rig sees obstacles out to 50-80 m.
struct AvoidOptions {
  // The separation to keep from any obstacle, metres, > 0.
  double protected_radius_m = 10;
  // Sigmas of the obstacle's position added to the radius, and of its range rate that an approach
  // must exceed, >= 0. 2 covers ~95 % of a 1-D error.
  double sigma_factor = 2;
  // Horizons, seconds: 0 < avoid_time_s <= warning_time_s <= caution_time_s.
  double avoid_time_s = 15;
  double warning_time_s = 30;
  double caution_time_s = 60;
  // Radii as multiples of R: 1 <= warning_radius_factor <= caution_radius_factor.
  double warning_radius_factor = 2;
  double caution_radius_factor = 4;
  // Any obstacle nearer than this now is at least CAUTION, metres, >= 0 (0, the default, disables
  // the rule).
  double caution_range_m = 0;
  // Tentative tracks are often clutter: ignored unless this is false. Coasting tracks always count
  // (an occluded obstacle is still there).
  bool ignore_tentative = true;
  // A track with fewer detections than this is judged by where it is, not by where its velocity
  // says it goes: its first velocity estimates come from a few noisy ranges (a departing drone's
  // first three gave a 0.6-1 m/s approach), too few to extrapolate 15 s ahead. >= 0 (0 or 1:
  // extrapolate every track). At 10 fps the default delays an approach alarm by 0.2 s.
  uint32_t min_hits_to_extrapolate = 5;
  // Obstacles scoring below this are ignored, in [0, 1] (0 takes all).
  double min_score = 0;

  // Every problem, as "field: problem (got X)".
  std::vector<std::string> Validate() const;
  bool operator==(const AvoidOptions&) const = default;
};

// One obstacle against the vehicle, extrapolated in straight lines: p = obstacle - own position,
// v = obstacle - own velocity, t_cpa = max(0, -p.v / |v|^2) (0 when v = 0), d_cpa = |p + v t_cpa|.
struct Encounter {
  std::uint64_t track_id = 0;
  // Of the obstacle from the vehicle now, degrees clockwise from north, [0, 360). 0 when the
  // obstacle is straight above or below.
  double bearing_deg = 0;
  double distance_m = 0;          // 3-D, now
  double t_cpa_s = 0;             // seconds from now, >= 0
  double d_cpa_m = 0;             // 3-D, metres
  double protected_radius_m = 0;  // R of the rules above, with the sigma inflation
  AdvisoryLevel level = AdvisoryLevel::kClear;
};

// The encounter of one obstacle (whether or not the options would ignore it); a young track
// (hits below min_hits_to_extrapolate) is taken as not closing. Inputs must be
// finite (ObstacleIsValid).
Encounter Assess(const OwnVehicle& own, const Obstacle& obstacle, const AvoidOptions& options);

// True when the obstacle's positions, velocities and sigmas (position and range rate) are finite
// and the sigmas >= 0.
bool ObstacleIsValid(const Obstacle& obstacle);

struct Advisory {
  // When the advisory was made: the caller's steady clock, nanoseconds.
  std::int64_t t_ns = 0;
  AdvisoryLevel level = AdvisoryLevel::kNoData;
  // The worst encounter: set for CAUTION, WARNING and AVOID, unset for CLEAR and NO_DATA.
  std::optional<Encounter> worst;
  // For NO_DATA: why ("no frame yet", "no frame for 612 ms", "vehicle state not finite").
  std::string reason;
  // Obstacles left out because a value was not finite or a sigma negative. They cannot be
  // assessed, so the caller should report them.
  int invalid_obstacles = 0;
};

// The advisory for one frame of tracks: the worst encounter over the obstacles the options do not
// ignore. Among equal levels the soonest closest approach wins, then the smaller miss distance,
// then the lower track id. NO_DATA when the vehicle's state is not finite. `options` must be valid.
Advisory AssessFrame(std::int64_t t_ns, const OwnVehicle& own,
                     const std::vector<Obstacle>& obstacles, const AvoidOptions& options);

struct AdvisorOptions {
  AvoidOptions avoid;
  // With no frame for longer than this the advisory is NO_DATA, nanoseconds, > 0.
  std::int64_t no_data_after_ns = 500'000'000;

  // Every problem, as "field: problem (got X)" ("avoid.protected_radius_m: ...").
  std::vector<std::string> Validate() const;
  bool operator==(const AdvisorOptions&) const = default;
};

// AssessFrame plus a watchdog. Time is the caller's steady clock in nanoseconds (a frame's arrival
// time, not its capture time, which is on the server's clock), so tests need no sleeping.
// Thread-compatible: do not call OnFrame and OnTick concurrently.
class Advisor {
 public:
  // Throws std::invalid_argument when the options are invalid (a programming error: validate
  // configuration first).
  explicit Advisor(AdvisorOptions options = {});

  // Assesses a frame that arrived at `now_ns` and remembers the advisory for OnTick.
  Advisory OnFrame(std::int64_t now_ns, const OwnVehicle& own,
                   const std::vector<Obstacle>& obstacles);

  // The advisory at `now_ns`, to be called periodically (e.g. every 100 ms): the last frame's
  // advisory while it is fresh (age <= no_data_after_ns), else NO_DATA stamped `now_ns`. Also
  // NO_DATA before the first frame and when `now_ns` is before the last frame (a clock fault).
  Advisory OnTick(std::int64_t now_ns) const;

  const AdvisorOptions& options() const { return options_; }

 private:
  AdvisorOptions options_;
  std::optional<std::int64_t> last_frame_ns_;
  Advisory last_;
};

// One JSON object, no newline (the caller writes one per line), e.g.
//   {"t_ns":5,"level":"WARNING","track_id":7,"bearing_deg":45.0,"distance_m":141.42,
//    "t_cpa_s":10.00,"d_cpa_m":12.50}
// The obstacle fields are present when `worst` is set. NO_DATA adds "reason"; a frame with
// invalid obstacles adds "invalid_obstacles". Bearing to 0.1 degree, metres and seconds to 0.01;
// every number is finite (a non-finite one would be written as null).
std::string AdvisoryJson(const Advisory& advisory);

}  // namespace stevi::client
