#include "client/mavlink/messages.h"

#include <algorithm>
#include <bit>
#include <type_traits>
#include <utility>

namespace stevi::client::mavlink {
namespace {

// The length of a message's payload with its extensions.
std::size_t MaxLength(uint32_t id) { return FindMessage(id)->max_length; }

// Writes little-endian values, byte by byte, into a payload.
class Writer {
 public:
  explicit Writer(uint32_t id) { bytes_.reserve(MaxLength(id)); }

  template <class T>
  void Put(T value) {
    if constexpr (std::is_same_v<T, float>) {
      Put(std::bit_cast<uint32_t>(value));
    } else {
      const auto bits = static_cast<std::make_unsigned_t<T>>(value);
      for (std::size_t i = 0; i < sizeof(T); ++i) {
        bytes_.push_back(static_cast<uint8_t>((bits >> (8 * i)) & 0xFFU));
      }
    }
  }

  template <class T, std::size_t N>
  void Put(const std::array<T, N>& values) {
    for (const T& value : values) Put(value);
  }

  std::vector<uint8_t> Take() { return std::move(bytes_); }

 private:
  std::vector<uint8_t> bytes_;
};

// Reads little-endian values from a payload zero-filled to the message's max_length.
class Reader {
 public:
  Reader(std::span<const uint8_t> payload, uint32_t id) : bytes_(payload.begin(), payload.end()) {
    bytes_.resize(std::max(bytes_.size(), MaxLength(id)), 0);
  }

  template <class T>
  void Get(T& value) {
    if constexpr (std::is_same_v<T, float>) {
      uint32_t bits = 0;
      Get(bits);
      value = std::bit_cast<float>(bits);
    } else {
      std::make_unsigned_t<T> bits = 0;
      for (std::size_t i = 0; i < sizeof(T); ++i) {
        bits |= static_cast<std::make_unsigned_t<T>>(
            static_cast<std::make_unsigned_t<T>>(bytes_[at_ + i]) << (8 * i));
      }
      at_ += sizeof(T);
      value = static_cast<T>(bits);
    }
  }

  template <class T, std::size_t N>
  void Get(std::array<T, N>& values) {
    for (T& value : values) Get(value);
  }

 private:
  std::vector<uint8_t> bytes_;
  std::size_t at_ = 0;
};

// True when a payload fits the message.
bool Fits(std::span<const uint8_t> payload, uint32_t id) { return payload.size() <= MaxLength(id); }

}  // namespace

// Each Pack and Unpack lists the fields in wire order; the offsets are in the comments.

std::vector<uint8_t> Pack(const Heartbeat& m) {
  Writer w(Heartbeat::kId);
  w.Put(m.custom_mode);      // 0
  w.Put(m.type);             // 4
  w.Put(m.autopilot);        // 5
  w.Put(m.base_mode);        // 6
  w.Put(m.system_status);    // 7
  w.Put(m.mavlink_version);  // 8
  return w.Take();
}

template <>
std::optional<Heartbeat> Unpack<Heartbeat>(std::span<const uint8_t> payload) {
  if (!Fits(payload, Heartbeat::kId)) return std::nullopt;
  Heartbeat m;
  Reader r(payload, Heartbeat::kId);
  r.Get(m.custom_mode);
  r.Get(m.type);
  r.Get(m.autopilot);
  r.Get(m.base_mode);
  r.Get(m.system_status);
  r.Get(m.mavlink_version);
  return m;
}

std::vector<uint8_t> Pack(const SystemTime& m) {
  Writer w(SystemTime::kId);
  w.Put(m.time_unix_usec);  // 0
  w.Put(m.time_boot_ms);    // 8
  return w.Take();
}

template <>
std::optional<SystemTime> Unpack<SystemTime>(std::span<const uint8_t> payload) {
  if (!Fits(payload, SystemTime::kId)) return std::nullopt;
  SystemTime m;
  Reader r(payload, SystemTime::kId);
  r.Get(m.time_unix_usec);
  r.Get(m.time_boot_ms);
  return m;
}

std::vector<uint8_t> Pack(const GpsRawInt& m) {
  Writer w(GpsRawInt::kId);
  w.Put(m.time_usec);           // 0
  w.Put(m.lat);                 // 8
  w.Put(m.lon);                 // 12
  w.Put(m.alt);                 // 16
  w.Put(m.eph);                 // 20
  w.Put(m.epv);                 // 22
  w.Put(m.vel);                 // 24
  w.Put(m.cog);                 // 26
  w.Put(m.fix_type);            // 28
  w.Put(m.satellites_visible);  // 29
  w.Put(m.alt_ellipsoid);       // 30, the extensions
  w.Put(m.h_acc);               // 34
  w.Put(m.v_acc);               // 38
  w.Put(m.vel_acc);             // 42
  w.Put(m.hdg_acc);             // 46
  w.Put(m.yaw);                 // 50
  return w.Take();
}

template <>
std::optional<GpsRawInt> Unpack<GpsRawInt>(std::span<const uint8_t> payload) {
  if (!Fits(payload, GpsRawInt::kId)) return std::nullopt;
  GpsRawInt m;
  Reader r(payload, GpsRawInt::kId);
  r.Get(m.time_usec);
  r.Get(m.lat);
  r.Get(m.lon);
  r.Get(m.alt);
  r.Get(m.eph);
  r.Get(m.epv);
  r.Get(m.vel);
  r.Get(m.cog);
  r.Get(m.fix_type);
  r.Get(m.satellites_visible);
  r.Get(m.alt_ellipsoid);
  r.Get(m.h_acc);
  r.Get(m.v_acc);
  r.Get(m.vel_acc);
  r.Get(m.hdg_acc);
  r.Get(m.yaw);
  return m;
}

std::vector<uint8_t> Pack(const Attitude& m) {
  Writer w(Attitude::kId);
  w.Put(m.time_boot_ms);  // 0
  w.Put(m.roll);          // 4
  w.Put(m.pitch);         // 8
  w.Put(m.yaw);           // 12
  w.Put(m.rollspeed);     // 16
  w.Put(m.pitchspeed);    // 20
  w.Put(m.yawspeed);      // 24
  return w.Take();
}

template <>
std::optional<Attitude> Unpack<Attitude>(std::span<const uint8_t> payload) {
  if (!Fits(payload, Attitude::kId)) return std::nullopt;
  Attitude m;
  Reader r(payload, Attitude::kId);
  r.Get(m.time_boot_ms);
  r.Get(m.roll);
  r.Get(m.pitch);
  r.Get(m.yaw);
  r.Get(m.rollspeed);
  r.Get(m.pitchspeed);
  r.Get(m.yawspeed);
  return m;
}

std::vector<uint8_t> Pack(const AttitudeQuaternion& m) {
  Writer w(AttitudeQuaternion::kId);
  w.Put(m.time_boot_ms);   // 0
  w.Put(m.q1);             // 4
  w.Put(m.q2);             // 8
  w.Put(m.q3);             // 12
  w.Put(m.q4);             // 16
  w.Put(m.rollspeed);      // 20
  w.Put(m.pitchspeed);     // 24
  w.Put(m.yawspeed);       // 28
  w.Put(m.repr_offset_q);  // 32..47, the extension
  return w.Take();
}

template <>
std::optional<AttitudeQuaternion> Unpack<AttitudeQuaternion>(std::span<const uint8_t> payload) {
  if (!Fits(payload, AttitudeQuaternion::kId)) return std::nullopt;
  AttitudeQuaternion m;
  Reader r(payload, AttitudeQuaternion::kId);
  r.Get(m.time_boot_ms);
  r.Get(m.q1);
  r.Get(m.q2);
  r.Get(m.q3);
  r.Get(m.q4);
  r.Get(m.rollspeed);
  r.Get(m.pitchspeed);
  r.Get(m.yawspeed);
  r.Get(m.repr_offset_q);
  return m;
}

std::vector<uint8_t> Pack(const GlobalPositionInt& m) {
  Writer w(GlobalPositionInt::kId);
  w.Put(m.time_boot_ms);  // 0
  w.Put(m.lat);           // 4
  w.Put(m.lon);           // 8
  w.Put(m.alt);           // 12
  w.Put(m.relative_alt);  // 16
  w.Put(m.vx);            // 20
  w.Put(m.vy);            // 22
  w.Put(m.vz);            // 24
  w.Put(m.hdg);           // 26
  return w.Take();
}

template <>
std::optional<GlobalPositionInt> Unpack<GlobalPositionInt>(std::span<const uint8_t> payload) {
  if (!Fits(payload, GlobalPositionInt::kId)) return std::nullopt;
  GlobalPositionInt m;
  Reader r(payload, GlobalPositionInt::kId);
  r.Get(m.time_boot_ms);
  r.Get(m.lat);
  r.Get(m.lon);
  r.Get(m.alt);
  r.Get(m.relative_alt);
  r.Get(m.vx);
  r.Get(m.vy);
  r.Get(m.vz);
  r.Get(m.hdg);
  return m;
}

std::vector<uint8_t> Pack(const CommandLong& m) {
  Writer w(CommandLong::kId);
  w.Put(m.param1);            // 0
  w.Put(m.param2);            // 4
  w.Put(m.param3);            // 8
  w.Put(m.param4);            // 12
  w.Put(m.param5);            // 16
  w.Put(m.param6);            // 20
  w.Put(m.param7);            // 24
  w.Put(m.command);           // 28
  w.Put(m.target_system);     // 30
  w.Put(m.target_component);  // 31
  w.Put(m.confirmation);      // 32
  return w.Take();
}

template <>
std::optional<CommandLong> Unpack<CommandLong>(std::span<const uint8_t> payload) {
  if (!Fits(payload, CommandLong::kId)) return std::nullopt;
  CommandLong m;
  Reader r(payload, CommandLong::kId);
  r.Get(m.param1);
  r.Get(m.param2);
  r.Get(m.param3);
  r.Get(m.param4);
  r.Get(m.param5);
  r.Get(m.param6);
  r.Get(m.param7);
  r.Get(m.command);
  r.Get(m.target_system);
  r.Get(m.target_component);
  r.Get(m.confirmation);
  return m;
}

std::vector<uint8_t> Pack(const CommandAck& m) {
  Writer w(CommandAck::kId);
  w.Put(m.command);           // 0
  w.Put(m.result);            // 2
  w.Put(m.progress);          // 3, the extensions
  w.Put(m.result_param2);     // 4
  w.Put(m.target_system);     // 8
  w.Put(m.target_component);  // 9
  return w.Take();
}

template <>
std::optional<CommandAck> Unpack<CommandAck>(std::span<const uint8_t> payload) {
  if (!Fits(payload, CommandAck::kId)) return std::nullopt;
  CommandAck m;
  Reader r(payload, CommandAck::kId);
  r.Get(m.command);
  r.Get(m.result);
  r.Get(m.progress);
  r.Get(m.result_param2);
  r.Get(m.target_system);
  r.Get(m.target_component);
  return m;
}

std::vector<uint8_t> Pack(const AdsbVehicle& m) {
  Writer w(AdsbVehicle::kId);
  w.Put(m.icao_address);   // 0
  w.Put(m.lat);            // 4
  w.Put(m.lon);            // 8
  w.Put(m.altitude);       // 12
  w.Put(m.heading);        // 16
  w.Put(m.hor_velocity);   // 18
  w.Put(m.ver_velocity);   // 20
  w.Put(m.flags);          // 22
  w.Put(m.squawk);         // 24
  w.Put(m.altitude_type);  // 26
  w.Put(m.callsign);       // 27..35
  w.Put(m.emitter_type);   // 36
  w.Put(m.tslc);           // 37
  return w.Take();
}

template <>
std::optional<AdsbVehicle> Unpack<AdsbVehicle>(std::span<const uint8_t> payload) {
  if (!Fits(payload, AdsbVehicle::kId)) return std::nullopt;
  AdsbVehicle m;
  Reader r(payload, AdsbVehicle::kId);
  r.Get(m.icao_address);
  r.Get(m.lat);
  r.Get(m.lon);
  r.Get(m.altitude);
  r.Get(m.heading);
  r.Get(m.hor_velocity);
  r.Get(m.ver_velocity);
  r.Get(m.flags);
  r.Get(m.squawk);
  r.Get(m.altitude_type);
  r.Get(m.callsign);
  r.Get(m.emitter_type);
  r.Get(m.tslc);
  return m;
}

std::vector<uint8_t> Pack(const ObstacleDistance& m) {
  Writer w(ObstacleDistance::kId);
  w.Put(m.time_usec);     // 0
  w.Put(m.distances);     // 8..151
  w.Put(m.min_distance);  // 152
  w.Put(m.max_distance);  // 154
  w.Put(m.sensor_type);   // 156
  w.Put(m.increment);     // 157
  w.Put(m.increment_f);   // 158, the extensions
  w.Put(m.angle_offset);  // 162
  w.Put(m.frame);         // 166
  return w.Take();
}

template <>
std::optional<ObstacleDistance> Unpack<ObstacleDistance>(std::span<const uint8_t> payload) {
  if (!Fits(payload, ObstacleDistance::kId)) return std::nullopt;
  ObstacleDistance m;
  Reader r(payload, ObstacleDistance::kId);
  r.Get(m.time_usec);
  r.Get(m.distances);
  r.Get(m.min_distance);
  r.Get(m.max_distance);
  r.Get(m.sensor_type);
  r.Get(m.increment);
  r.Get(m.increment_f);
  r.Get(m.angle_offset);
  r.Get(m.frame);
  return m;
}

}  // namespace stevi::client::mavlink
