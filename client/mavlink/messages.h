// The MAVLink messages the autopilot bridge sends and reads, as plain structs, and the enum values
// it needs (common.xml and minimal.xml). Fields are declared in the XML's order with its units;
// each struct's Fields lists them once more, in the wire order, and Pack and Unpack both work
// from that list: little-endian, byte by byte. The standard library only.
#pragma once

#include <array>
#include <bit>
#include <concepts>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

#include "client/mavlink/codec.h"

namespace stevi::client::mavlink {

// MAV_TYPE, MAV_AUTOPILOT, MAV_STATE (minimal.xml).
inline constexpr uint8_t kMavTypeOnboardController = 18;
inline constexpr uint8_t kMavAutopilotInvalid = 8;  // for components that are not autopilots
inline constexpr uint8_t kMavStateStandby = 3;
inline constexpr uint8_t kMavStateActive = 4;
inline constexpr uint8_t kMavStateCritical = 5;
// MAV_COMPONENT: the component id the bridge sends as.
inline constexpr uint8_t kMavCompIdObstacleAvoidance = 196;
// The HEARTBEAT's mavlink_version that MAVLink 2 senders put.
inline constexpr uint8_t kMavlinkVersion = 3;

// MAV_FRAME.
inline constexpr uint8_t kMavFrameGlobal = 0;    // north-aligned
inline constexpr uint8_t kMavFrameBodyFrd = 12;  // front-right-down, vehicle-aligned

// MAV_DISTANCE_SENSOR (there is no stereo camera type: UNKNOWN is the honest one).
inline constexpr uint8_t kMavDistanceSensorLaser = 0;
inline constexpr uint8_t kMavDistanceSensorUltrasound = 1;
inline constexpr uint8_t kMavDistanceSensorInfrared = 2;
inline constexpr uint8_t kMavDistanceSensorRadar = 3;
inline constexpr uint8_t kMavDistanceSensorUnknown = 4;

// MAV_CMD and MAV_RESULT.
inline constexpr uint16_t kMavCmdSetMessageInterval = 511;  // param1 message id, param2 us
inline constexpr uint8_t kMavResultAccepted = 0;
inline constexpr uint8_t kMavResultTemporarilyRejected = 1;
inline constexpr uint8_t kMavResultDenied = 2;
inline constexpr uint8_t kMavResultUnsupported = 3;
inline constexpr uint8_t kMavResultFailed = 4;
inline constexpr uint8_t kMavResultInProgress = 5;
inline constexpr uint8_t kMavResultCancelled = 6;

// GPS_FIX_TYPE.
inline constexpr uint8_t kGpsFixTypeNoGps = 0;
inline constexpr uint8_t kGpsFixTypeNoFix = 1;
inline constexpr uint8_t kGpsFixType2dFix = 2;
inline constexpr uint8_t kGpsFixType3dFix = 3;
inline constexpr uint8_t kGpsFixTypeDgps = 4;
inline constexpr uint8_t kGpsFixTypeRtkFloat = 5;
inline constexpr uint8_t kGpsFixTypeRtkFixed = 6;
inline constexpr uint8_t kGpsFixTypeStatic = 7;
inline constexpr uint8_t kGpsFixTypePpp = 8;

// ADSB_ALTITUDE_TYPE, ADSB_EMITTER_TYPE.
inline constexpr uint8_t kAdsbAltitudeTypePressureQnh = 0;  // barometric
inline constexpr uint8_t kAdsbAltitudeTypeGeometric = 1;    // GNSS
inline constexpr uint8_t kAdsbEmitterTypeNoInfo = 0;
inline constexpr uint8_t kAdsbEmitterTypeUav = 14;

// ADSB_FLAGS (a bitmask).
inline constexpr uint16_t kAdsbFlagsValidCoords = 1;
inline constexpr uint16_t kAdsbFlagsValidAltitude = 2;
inline constexpr uint16_t kAdsbFlagsValidHeading = 4;
inline constexpr uint16_t kAdsbFlagsValidVelocity = 8;
inline constexpr uint16_t kAdsbFlagsValidCallsign = 16;
inline constexpr uint16_t kAdsbFlagsValidSquawk = 32;
inline constexpr uint16_t kAdsbFlagsSimulated = 64;
inline constexpr uint16_t kAdsbFlagsVerticalVelocityValid = 128;

// OBSTACLE_DISTANCE.distances: a sector with no reading. max_distance + 1 means "nothing seen".
inline constexpr uint16_t kObstacleDistanceUnknown = 0xFFFF;
inline constexpr std::size_t kObstacleDistanceSectors = 72;

// Each message struct below has its field table, the one place that says how it goes on the wire:
//
//   template <class Self, class V>
//   static void Fields(Self& m, V& v) {
//     v.Field(m.custom_mode, "custom_mode");  // a member and its name in the XML
//     ...
//     v.Extensions();  // where the extension fields start (only in messages that have them)
//     ...
//   }
//
// Self is the struct or the const struct; V a visitor with Field(value, name) and Extensions().
// The table is in wire order: the base fields sorted by type size, largest first and stable within
// a size (arrays by their element size), then the extension fields in XML order. A field's wire
// type is its member's type (uint8_t ... uint64_t, int8_t ... int64_t, float, char, or a
// std::array of one of those). codec.h's table holds each message's CRC_EXTRA and lengths; the
// tests check them against these tables.

// HEARTBEAT (0).
struct Heartbeat {
  static constexpr uint32_t kId = 0;
  uint8_t type = 0;       // MAV_TYPE
  uint8_t autopilot = 0;  // MAV_AUTOPILOT
  uint8_t base_mode = 0;  // MAV_MODE_FLAG bits
  uint32_t custom_mode = 0;
  uint8_t system_status = 0;  // MAV_STATE
  uint8_t mavlink_version = kMavlinkVersion;

  bool operator==(const Heartbeat&) const = default;

  template <class Self, class V>
  static void Fields(Self& m, V& v) {
    v.Field(m.custom_mode, "custom_mode");
    v.Field(m.type, "type");
    v.Field(m.autopilot, "autopilot");
    v.Field(m.base_mode, "base_mode");
    v.Field(m.system_status, "system_status");
    v.Field(m.mavlink_version, "mavlink_version");
  }
};

// SYSTEM_TIME (2).
struct SystemTime {
  static constexpr uint32_t kId = 2;
  uint64_t time_unix_usec = 0;  // microseconds since the UNIX epoch
  uint32_t time_boot_ms = 0;

  bool operator==(const SystemTime&) const = default;

  template <class Self, class V>
  static void Fields(Self& m, V& v) {
    v.Field(m.time_unix_usec, "time_unix_usec");
    v.Field(m.time_boot_ms, "time_boot_ms");
  }
};

// GPS_RAW_INT (24).
struct GpsRawInt {
  static constexpr uint32_t kId = 24;
  uint64_t time_usec = 0;          // UNIX epoch or since boot
  uint8_t fix_type = 0;            // GPS_FIX_TYPE
  int32_t lat = 0;                 // degrees * 1e7
  int32_t lon = 0;                 // degrees * 1e7
  int32_t alt = 0;                 // mm above MSL
  uint16_t eph = 0;                // HDOP * 100; UINT16_MAX unknown
  uint16_t epv = 0;                // VDOP * 100; UINT16_MAX unknown
  uint16_t vel = 0;                // ground speed, cm/s; UINT16_MAX unknown
  uint16_t cog = 0;                // course over ground, centidegrees; UINT16_MAX unknown
  uint8_t satellites_visible = 0;  // UINT8_MAX unknown
  // Extensions.
  int32_t alt_ellipsoid = 0;  // mm above the WGS84 ellipsoid
  uint32_t h_acc = 0;         // mm
  uint32_t v_acc = 0;         // mm
  uint32_t vel_acc = 0;       // mm/s (the XML says "mm")
  uint32_t hdg_acc = 0;       // degrees * 1e5
  uint16_t yaw = 0;           // centidegrees from north; 0 none, 36000 north

  bool operator==(const GpsRawInt&) const = default;

  template <class Self, class V>
  static void Fields(Self& m, V& v) {
    v.Field(m.time_usec, "time_usec");
    v.Field(m.lat, "lat");
    v.Field(m.lon, "lon");
    v.Field(m.alt, "alt");
    v.Field(m.eph, "eph");
    v.Field(m.epv, "epv");
    v.Field(m.vel, "vel");
    v.Field(m.cog, "cog");
    v.Field(m.fix_type, "fix_type");
    v.Field(m.satellites_visible, "satellites_visible");
    v.Extensions();
    v.Field(m.alt_ellipsoid, "alt_ellipsoid");
    v.Field(m.h_acc, "h_acc");
    v.Field(m.v_acc, "v_acc");
    v.Field(m.vel_acc, "vel_acc");
    v.Field(m.hdg_acc, "hdg_acc");
    v.Field(m.yaw, "yaw");
  }
};

// ATTITUDE (30): body frame relative to NED, radians and rad/s.
struct Attitude {
  static constexpr uint32_t kId = 30;
  uint32_t time_boot_ms = 0;
  float roll = 0;
  float pitch = 0;
  float yaw = 0;
  float rollspeed = 0;
  float pitchspeed = 0;
  float yawspeed = 0;

  bool operator==(const Attitude&) const = default;

  template <class Self, class V>
  static void Fields(Self& m, V& v) {
    v.Field(m.time_boot_ms, "time_boot_ms");
    v.Field(m.roll, "roll");
    v.Field(m.pitch, "pitch");
    v.Field(m.yaw, "yaw");
    v.Field(m.rollspeed, "rollspeed");
    v.Field(m.pitchspeed, "pitchspeed");
    v.Field(m.yawspeed, "yawspeed");
  }
};

// ATTITUDE_QUATERNION (31): q1..q4 are w, x, y, z.
struct AttitudeQuaternion {
  static constexpr uint32_t kId = 31;
  uint32_t time_boot_ms = 0;
  float q1 = 0;
  float q2 = 0;
  float q3 = 0;
  float q4 = 0;
  float rollspeed = 0;  // rad/s
  float pitchspeed = 0;
  float yawspeed = 0;
  // Extension: a display offset (w, x, y, z); all zero when not supported.
  std::array<float, 4> repr_offset_q{};

  bool operator==(const AttitudeQuaternion&) const = default;

  template <class Self, class V>
  static void Fields(Self& m, V& v) {
    v.Field(m.time_boot_ms, "time_boot_ms");
    v.Field(m.q1, "q1");
    v.Field(m.q2, "q2");
    v.Field(m.q3, "q3");
    v.Field(m.q4, "q4");
    v.Field(m.rollspeed, "rollspeed");
    v.Field(m.pitchspeed, "pitchspeed");
    v.Field(m.yawspeed, "yawspeed");
    v.Extensions();
    v.Field(m.repr_offset_q, "repr_offset_q");
  }
};

// GLOBAL_POSITION_INT (33).
struct GlobalPositionInt {
  static constexpr uint32_t kId = 33;
  uint32_t time_boot_ms = 0;
  int32_t lat = 0;           // degrees * 1e7
  int32_t lon = 0;           // degrees * 1e7
  int32_t alt = 0;           // mm above MSL
  int32_t relative_alt = 0;  // mm above home
  int16_t vx = 0;            // cm/s north
  int16_t vy = 0;            // cm/s east
  int16_t vz = 0;            // cm/s down
  uint16_t hdg = 0;          // centidegrees; UINT16_MAX unknown

  bool operator==(const GlobalPositionInt&) const = default;

  template <class Self, class V>
  static void Fields(Self& m, V& v) {
    v.Field(m.time_boot_ms, "time_boot_ms");
    v.Field(m.lat, "lat");
    v.Field(m.lon, "lon");
    v.Field(m.alt, "alt");
    v.Field(m.relative_alt, "relative_alt");
    v.Field(m.vx, "vx");
    v.Field(m.vy, "vy");
    v.Field(m.vz, "vz");
    v.Field(m.hdg, "hdg");
  }
};

// COMMAND_LONG (76).
struct CommandLong {
  static constexpr uint32_t kId = 76;
  uint8_t target_system = 0;
  uint8_t target_component = 0;  // 0 for all
  uint16_t command = 0;          // MAV_CMD
  uint8_t confirmation = 0;      // 0 first transmission, then 1..255
  float param1 = 0;
  float param2 = 0;
  float param3 = 0;
  float param4 = 0;
  float param5 = 0;
  float param6 = 0;
  float param7 = 0;

  bool operator==(const CommandLong&) const = default;

  template <class Self, class V>
  static void Fields(Self& m, V& v) {
    v.Field(m.param1, "param1");
    v.Field(m.param2, "param2");
    v.Field(m.param3, "param3");
    v.Field(m.param4, "param4");
    v.Field(m.param5, "param5");
    v.Field(m.param6, "param6");
    v.Field(m.param7, "param7");
    v.Field(m.command, "command");
    v.Field(m.target_system, "target_system");
    v.Field(m.target_component, "target_component");
    v.Field(m.confirmation, "confirmation");
  }
};

// COMMAND_ACK (77).
struct CommandAck {
  static constexpr uint32_t kId = 77;
  uint16_t command = 0;  // MAV_CMD
  uint8_t result = 0;    // MAV_RESULT
  // Extensions.
  uint8_t progress = 0;  // percent for IN_PROGRESS, else a reason; UINT8_MAX unknown
  int32_t result_param2 = 0;
  uint8_t target_system = 0;  // who sent the command
  uint8_t target_component = 0;

  bool operator==(const CommandAck&) const = default;

  template <class Self, class V>
  static void Fields(Self& m, V& v) {
    v.Field(m.command, "command");
    v.Field(m.result, "result");
    v.Extensions();
    v.Field(m.progress, "progress");
    v.Field(m.result_param2, "result_param2");
    v.Field(m.target_system, "target_system");
    v.Field(m.target_component, "target_component");
  }
};

// ADSB_VEHICLE (246). The bridge reports obstacles as traffic with it.
struct AdsbVehicle {
  static constexpr uint32_t kId = 246;
  uint32_t icao_address = 0;       // ICAO_address in the XML
  int32_t lat = 0;                 // degrees * 1e7
  int32_t lon = 0;                 // degrees * 1e7
  uint8_t altitude_type = 0;       // ADSB_ALTITUDE_TYPE
  int32_t altitude = 0;            // mm above MSL
  uint16_t heading = 0;            // course over ground, centidegrees
  uint16_t hor_velocity = 0;       // cm/s
  int16_t ver_velocity = 0;        // cm/s, positive up
  std::array<char, 9> callsign{};  // 8 characters and a NUL
  uint8_t emitter_type = 0;        // ADSB_EMITTER_TYPE
  uint8_t tslc = 0;                // seconds since the last communication
  uint16_t flags = 0;              // ADSB_FLAGS
  uint16_t squawk = 0;

  bool operator==(const AdsbVehicle&) const = default;

  template <class Self, class V>
  static void Fields(Self& m, V& v) {
    v.Field(m.icao_address, "ICAO_address");
    v.Field(m.lat, "lat");
    v.Field(m.lon, "lon");
    v.Field(m.altitude, "altitude");
    v.Field(m.heading, "heading");
    v.Field(m.hor_velocity, "hor_velocity");
    v.Field(m.ver_velocity, "ver_velocity");
    v.Field(m.flags, "flags");
    v.Field(m.squawk, "squawk");
    v.Field(m.altitude_type, "altitude_type");
    v.Field(m.callsign, "callsign");
    v.Field(m.emitter_type, "emitter_type");
    v.Field(m.tslc, "tslc");
  }
};

// OBSTACLE_DISTANCE (330).
struct ObstacleDistance {
  static constexpr uint32_t kId = 330;
  uint64_t time_usec = 0;   // UNIX epoch or since boot
  uint8_t sensor_type = 0;  // MAV_DISTANCE_SENSOR
  // cm per sector, sector 0 at angle_offset; kObstacleDistanceUnknown for none.
  std::array<uint16_t, kObstacleDistanceSectors> distances{};
  uint8_t increment = 0;      // degrees per sector, clockwise; ignored when increment_f != 0
  uint16_t min_distance = 0;  // cm
  uint16_t max_distance = 0;  // cm
  // Extensions.
  float increment_f = 0;   // degrees per sector; negative counter-clockwise
  float angle_offset = 0;  // degrees of sector 0 from forward (or north), clockwise
  uint8_t frame = 0;       // MAV_FRAME: kMavFrameGlobal or kMavFrameBodyFrd

  bool operator==(const ObstacleDistance&) const = default;

  template <class Self, class V>
  static void Fields(Self& m, V& v) {
    v.Field(m.time_usec, "time_usec");
    v.Field(m.distances, "distances");
    v.Field(m.min_distance, "min_distance");
    v.Field(m.max_distance, "max_distance");
    v.Field(m.sensor_type, "sensor_type");
    v.Field(m.increment, "increment");
    v.Extensions();
    v.Field(m.increment_f, "increment_f");
    v.Field(m.angle_offset, "angle_offset");
    v.Field(m.frame, "frame");
  }
};

namespace detail {

// The length of the payload of message `id` with its extensions (codec.h's table).
std::size_t MaxLength(uint32_t id);

// The unsigned word of a field's wire type, the bits that go on the wire.
template <class T>
struct Word {
  using type = std::make_unsigned_t<T>;
};
template <>
struct Word<float> {
  using type = uint32_t;
};

// A field table's visitor that writes each field little-endian, byte by byte.
class Packer {
 public:
  explicit Packer(uint32_t id);

  template <class T>
  void Field(const T& value, std::string_view /*name*/) {
    Put(std::bit_cast<typename Word<T>::type>(value), sizeof(T));
  }
  template <class T, std::size_t N>
  void Field(const std::array<T, N>& values, std::string_view name) {
    for (const T& value : values) Field(value, name);
  }
  void Extensions() {}

  std::vector<uint8_t> Take() { return std::move(bytes_); }

 private:
  void Put(uint64_t bits, std::size_t size);

  std::vector<uint8_t> bytes_;
};

// A field table's visitor that reads each field; the bytes past the payload's end read as zero.
class Unpacker {
 public:
  explicit Unpacker(std::span<const uint8_t> payload) : payload_(payload) {}

  template <class T>
  void Field(T& value, std::string_view /*name*/) {
    value = std::bit_cast<T>(static_cast<typename Word<T>::type>(Get(sizeof(T))));
  }
  template <class T, std::size_t N>
  void Field(std::array<T, N>& values, std::string_view name) {
    for (T& value : values) Field(value, name);
  }
  void Extensions() {}

 private:
  uint64_t Get(std::size_t size);

  std::span<const uint8_t> payload_;
  std::size_t at_ = 0;
};

}  // namespace detail

// A struct above: an id and a field table.
template <class T>
concept Message = requires(const T& in, T& out, detail::Packer& packer,
                           detail::Unpacker& unpacker) {
  { T::kId } -> std::convertible_to<uint32_t>;
  T::Fields(in, packer);
  T::Fields(out, unpacker);
};

// A message's payload in wire order, max_length bytes (EncodeFrame trims it).
template <Message T>
std::vector<uint8_t> Pack(const T& m) {
  detail::Packer packer(T::kId);
  T::Fields(m, packer);
  return packer.Take();
}

// A message from its payload. A shorter payload is zero-filled (a trimmed MAVLink 2 payload, or a
// MAVLink 1 one without the extensions); nullopt when it is longer than the message's max_length.
template <Message T>
std::optional<T> Unpack(std::span<const uint8_t> payload) {
  if (payload.size() > detail::MaxLength(T::kId)) return std::nullopt;
  T m;
  detail::Unpacker unpacker(payload);
  T::Fields(m, unpacker);
  return m;
}

// A message as a MAVLink 2 frame's bytes.
template <Message T>
std::vector<uint8_t> Encode(const T& m, uint8_t sequence, uint8_t system_id, uint8_t component_id) {
  return EncodeFrame(sequence, system_id, component_id, T::kId, Pack(m));
}

// The message a parsed frame carries; nullopt when the frame holds another message.
template <Message T>
std::optional<T> Decode(const Frame& frame) {
  if (frame.message_id != T::kId) return std::nullopt;
  return Unpack<T>(frame.payload);
}

}  // namespace stevi::client::mavlink
