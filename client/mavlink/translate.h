// The translation the autopilot bridge (bridge.h) does, apart from its threads and sockets: what
// stevi's frames become in MAVLink (OBSTACLE_DISTANCE, ADSB_VEHICLE), and how the autopilot's
// messages become the VehicleStates the server georeferences with. Plain functions and classes
// over the proto and the codec's message structs; no gRPC, no clock of its own (times are passed
// in), so tests drive them directly.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "client/mavlink/codec.h"
#include "client/mavlink/messages.h"
#include "stevi/v1/obstacle_service.pb.h"

namespace stevi::client::mavlink {

// OBSTACLE_DISTANCE as stevi sends it: 72 sectors of 5 degrees in the body frame (FRD), sector i
// centred on i * 5 degrees clockwise from forward (angle_offset 0), as PX4's collision prevention
// and ArduPilot's AP_Proximity_MAV both read it.
inline constexpr int kSectors = 72;
inline constexpr double kSectorDeg = 5.0;

// Distances in centimetres, as OBSTACLE_DISTANCE carries them.
struct SectorLimits {
  uint16_t min_cm = 0;  // the nearest measurable range; nearer obstacles are sent as this
  uint16_t max_cm = 0;  // the farthest trusted range; max_cm + 1 = seen and clear
};

// The limits of a frame's range scan: min_range_m rounded up, max_range_m down, max_cm kept below
// 65534 so that max_cm + 1 never reads as "unknown" (UINT16_MAX).
SectorLimits LimitsOf(const v1::RangeScan& scan);

// The obstacle distances of one frame, or nullopt (with `why`) when the frame has no range scan
// (PipelineConfig.range_scan.enabled false). Per sector: the nearest range in the range scan's
// bins that overlap it; else max_cm + 1 when the scan covers at least half of it (seen, clear);
// else UINT16_MAX (the camera does not look there). Then each CONFIRMED or COASTING track with a
// body position shortens the sector of its bearing to its horizontal range (a coasting track
// holds an obstacle the disparity lost for a moment). Obstacles nearer than min_cm are sent as
// min_cm, never as 0 (ArduPilot skips 0); obstacles beyond max_cm leave the sector clear.
// time_usec is the frame's capture time (Unix, microseconds).
std::optional<ObstacleDistance> ObstacleDistanceOf(const v1::TrackFrame& frame, std::string& why);

// The bearing (degrees clockwise from forward, [0, 360)) and horizontal range (metres) of a point
// in the body frame.
double BodyBearingDeg(const v1::PointBody& p);
double BodyHorizontalRangeM(const v1::PointBody& p);

// The sector that holds a body bearing: round(bearing / 5) mod 72.
int SectorOf(double bearing_deg);

struct AdsbOptions {
  // ICAO addresses are synthetic: base + (track id mod 2^20), stable for a track's life. Every
  // block of the 24-bit space belongs to some register, so pick a base that no aircraft near you
  // uses (--icao-base).
  uint32_t icao_base = 0xF00000;
  // The geoid undulation N at the site, metres (MSL = ellipsoid height - N), when known: from the
  // autopilot's GPS_RAW_INT (PoseJoiner::geoid_undulation_m) or --geoid-undulation. ADSB_VEHICLE
  // carries the altitude above MSL; without N the altitude is left out (flag not set).
  std::optional<double> geoid_undulation_m;
  // Sets ADSB_FLAGS_SIMULATED (the server runs on its synthetic rig).
  bool simulated = false;
};

// ADSB_VEHICLE for each CONFIRMED or COASTING track with a geodetic position (the frame's
// geo_status OK): a stable ICAO address and callsign per track id, position, altitude above MSL,
// course and speeds from velocity_ned, and the seconds since the track was last detected (0 while
// CONFIRMED; the tracker's last detection of a COASTING track, from `last_seen`, which this
// updates and prunes).
class AdsbTracks {
 public:
  explicit AdsbTracks(AdsbOptions options) : options_(options) {}
  std::vector<AdsbVehicle> Of(const v1::TrackFrame& frame);
  void set_geoid_undulation_m(std::optional<double> n) { options_.geoid_undulation_m = n; }
  void set_simulated(bool simulated) { options_.simulated = simulated; }

 private:
  AdsbOptions options_;
  std::unordered_map<uint64_t, int64_t> last_detected_ns_;  // by track id: capture time
};

// "STV" and the track id in base 36, 5 digits (wrapping after 36^5 ids): 8 characters and the NUL.
std::array<char, 9> CallsignOf(uint64_t track_id);
uint32_t IcaoAddressOf(uint64_t track_id, uint32_t icao_base);

struct PoseJoinerOptions {
  // The geoid undulation N (metres) to use when the autopilot's GPS_RAW_INT gives no ellipsoid
  // height: the state's height above the ellipsoid is GLOBAL_POSITION_INT.alt (MSL) + N.
  std::optional<double> geoid_undulation_m;
  // A GLOBAL_POSITION_INT joins the latest attitude only when that is at most this old (autopilot
  // boot time).
  int64_t max_attitude_age_ms = 500;
  // 1-sigma accuracies when the autopilot gives none (GPS_RAW_INT h_acc / v_acc 0), and of the
  // attitude, which MAVLink's position messages do not carry.
  double default_sigma_horizontal_m = 2.0;
  double default_sigma_vertical_m = 3.0;
  double sigma_tilt_deg = 0.5;
  double sigma_yaw_deg = 2.0;
};

// Joins the autopilot's GLOBAL_POSITION_INT (position, velocity), ATTITUDE or ATTITUDE_QUATERNION,
// GPS_RAW_INT (ellipsoid height, accuracies) and SYSTEM_TIME (Unix time) into VehicleStates: one
// for each GLOBAL_POSITION_INT once the others needed are there. It takes whatever it is given:
// the caller passes the messages of one system only (the first autopilot heard; `stevi mavlink`'s
// Bridge filters them, bridge.h).
class PoseJoiner {
 public:
  explicit PoseJoiner(PoseJoinerOptions options) : options_(options) {}

  // Takes one message that arrived at host Unix time `host_unix_ns`; a VehicleState when it
  // completed one, else nullopt (waiting() then says for what).
  std::optional<v1::VehicleState> OnMessage(const Frame& frame, int64_t host_unix_ns);

  // Why no state came of the last GLOBAL_POSITION_INT ("" once states flow): "no attitude",
  // "no ellipsoid height: ...", "no position fix".
  const std::string& waiting() const { return waiting_; }
  // The last message dropped as impossible ("" when none yet): an ATTITUDE with a non-finite
  // angle, a position outside the Earth. Such a message changes nothing.
  const std::string& rejected() const { return rejected_; }
  // N from GPS_RAW_INT (alt_ellipsoid - alt) when the autopilot gives both, else the option's.
  std::optional<double> geoid_undulation_m() const;
  // "autopilot" when the states' times come from SYSTEM_TIME, "host" when from this computer's
  // clock at arrival (no SYSTEM_TIME with a Unix time yet).
  const char* time_source() const { return boot_to_unix_us_ ? "autopilot" : "host"; }
  // Host Unix time of the last GLOBAL_POSITION_INT, 0 before the first.
  int64_t last_position_ns() const { return last_position_ns_; }

 private:
  std::optional<v1::VehicleState> OnPosition(const GlobalPositionInt& m, int64_t host_unix_ns);
  void TakeAttitude(const std::array<double, 3>& roll_pitch_yaw_deg, uint32_t time_boot_ms,
                    int64_t host_unix_ns, const char* message);

  PoseJoinerOptions options_;
  std::string waiting_ = "no GLOBAL_POSITION_INT yet";
  std::string rejected_;
  struct Attitude {
    double roll_deg = 0, pitch_deg = 0, yaw_deg = 0;
    uint32_t time_boot_ms = 0;
    int64_t host_unix_ns = 0;
  };
  std::optional<Attitude> attitude_;
  std::optional<GpsRawInt> gps_;
  std::optional<int64_t> boot_to_unix_us_;  // SYSTEM_TIME: unix_us - boot_ms * 1000
  int64_t last_position_ns_ = 0;
};

// ATTITUDE_QUATERNION's q (w, x, y, z: the body's attitude in NED) as Z-Y-X Euler angles,
// degrees: roll, pitch, yaw.
std::array<double, 3> EulerDegOfQuaternion(double w, double x, double y, double z);

// An autopilot's heartbeat: not a ground station (MAV_TYPE_GCS), not a component that is no
// autopilot (MAV_AUTOPILOT_INVALID), not another onboard controller.
bool IsAutopilotHeartbeat(const Heartbeat& heartbeat);

// COMMAND_LONG MAV_CMD_SET_MESSAGE_INTERVAL asking `target` for `message_id` every `interval_us`.
CommandLong SetMessageInterval(uint8_t target_system, uint8_t target_component, uint32_t message_id,
                               int32_t interval_us);

}  // namespace stevi::client::mavlink
