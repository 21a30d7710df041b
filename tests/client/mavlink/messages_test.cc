// The MAVLink messages: every field placed at the byte offset the specification's ordering gives
// (worked out by hand from common.xml: base fields sorted by type size, stable; extensions after,
// in XML order), round trips with distinct non-zero values, and trimmed or short payloads.
#include "client/mavlink/messages.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

namespace stevi::client::mavlink {
namespace {

using Bytes = std::vector<uint8_t>;

// The little-endian value of sizeof(T) bytes at `offset`, read by the test itself.
template <class T>
T ReadLe(const Bytes& bytes, std::size_t offset) {
  uint64_t bits = 0;
  for (std::size_t i = 0; i < sizeof(T); ++i) {
    bits |= static_cast<uint64_t>(bytes.at(offset + i)) << (8 * i);
  }
  if constexpr (std::is_same_v<T, float>) {
    const auto word = static_cast<uint32_t>(bits);
    float value = 0;
    std::memcpy(&value, &word, sizeof(value));
    return value;
  } else {
    return static_cast<T>(bits);
  }
}

// A field's value at its wire offset.
#define EXPECT_AT(bytes, offset, field) \
  EXPECT_EQ(ReadLe<std::decay_t<decltype(field)>>(bytes, offset), field) << "offset " << offset

// Packs, checks the length, unpacks, and sends through a frame and the parser.
template <class T>
void ExpectRoundTrip(const T& m, std::size_t max_length) {
  const Bytes payload = Pack(m);
  EXPECT_EQ(payload.size(), max_length);
  EXPECT_EQ(Unpack<T>(payload), m);

  Parser parser;
  std::vector<Frame> frames;
  parser.Feed(Encode(m, 200, 1, 196), [&frames](const Frame& f) { frames.push_back(f); });
  ASSERT_EQ(frames.size(), 1U);
  EXPECT_EQ(frames[0].message_id, T::kId);
  EXPECT_EQ(frames[0].sequence, 200);
  EXPECT_EQ(Decode<T>(frames[0]), m);
}

TEST(Heartbeat, LayoutAndRoundTrip) {
  const Heartbeat m{.type = 18,
                    .autopilot = 8,
                    .base_mode = 0x51,
                    .custom_mode = 0xA1B2C3D4,
                    .system_status = 4,
                    .mavlink_version = 3};
  const Bytes p = Pack(m);
  EXPECT_AT(p, 0, m.custom_mode);
  EXPECT_AT(p, 4, m.type);
  EXPECT_AT(p, 5, m.autopilot);
  EXPECT_AT(p, 6, m.base_mode);
  EXPECT_AT(p, 7, m.system_status);
  EXPECT_AT(p, 8, m.mavlink_version);
  // custom_mode little-endian, byte by byte.
  EXPECT_EQ(Bytes(p.begin(), p.begin() + 4), (Bytes{0xD4, 0xC3, 0xB2, 0xA1}));
  ExpectRoundTrip(m, 9);
}

TEST(Heartbeat, TheBridgesHeartbeatIsTheHandWorkedFrame) {
  // The frame of codec_test's HeartbeatMatchesHandWorkedBytes.
  const Heartbeat m{.type = kMavTypeOnboardController,
                    .autopilot = kMavAutopilotInvalid,
                    .system_status = kMavStateActive};
  const Bytes expected = {0xFD, 0x09, 0x00, 0x00, 0x2A, 0x01, 0xC4, 0x00, 0x00, 0x00, 0x00,
                          0x00, 0x00, 0x00, 0x12, 0x08, 0x00, 0x04, 0x03, 0x00, 0x95};
  EXPECT_EQ(Encode(m, 0x2A, 1, kMavCompIdObstacleAvoidance), expected);
}

TEST(SystemTime, LayoutAndRoundTrip) {
  const SystemTime m{.time_unix_usec = 0x0102030405060708, .time_boot_ms = 0x11223344};
  const Bytes p = Pack(m);
  EXPECT_AT(p, 0, m.time_unix_usec);
  EXPECT_AT(p, 8, m.time_boot_ms);
  ExpectRoundTrip(m, 12);
}

GpsRawInt DistinctGps() {
  return GpsRawInt{.time_usec = 0x1122334455667788,
                   .fix_type = kGpsFixTypeRtkFixed,
                   .lat = -353632620,
                   .lon = 1491652300,
                   .alt = 584000,
                   .eph = 121,
                   .epv = 202,
                   .vel = 303,
                   .cog = 35999,
                   .satellites_visible = 17,
                   .alt_ellipsoid = -23456,
                   .h_acc = 1500,
                   .v_acc = 2500,
                   .vel_acc = 350,
                   .hdg_acc = 4500000,
                   .yaw = 36000};
}

TEST(GpsRawInt, BaseFieldsThenExtensions) {
  const GpsRawInt m = DistinctGps();
  const Bytes p = Pack(m);
  EXPECT_AT(p, 0, m.time_usec);
  EXPECT_AT(p, 8, m.lat);
  EXPECT_AT(p, 12, m.lon);
  EXPECT_AT(p, 16, m.alt);
  EXPECT_AT(p, 20, m.eph);
  EXPECT_AT(p, 22, m.epv);
  EXPECT_AT(p, 24, m.vel);
  EXPECT_AT(p, 26, m.cog);
  EXPECT_AT(p, 28, m.fix_type);
  EXPECT_AT(p, 29, m.satellites_visible);
  // The extensions follow the 30 base bytes in XML order, not sorted by size.
  EXPECT_AT(p, 30, m.alt_ellipsoid);
  EXPECT_AT(p, 34, m.h_acc);
  EXPECT_AT(p, 38, m.v_acc);
  EXPECT_AT(p, 42, m.vel_acc);
  EXPECT_AT(p, 46, m.hdg_acc);
  EXPECT_AT(p, 50, m.yaw);
  // A negative latitude in two's complement: 2^32 - 353632620 = 3941334676 = 0xEAEBFE94.
  EXPECT_EQ(Bytes(p.begin() + 8, p.begin() + 12), (Bytes{0x94, 0xFE, 0xEB, 0xEA}));
  ExpectRoundTrip(m, 52);
}

TEST(GpsRawInt, AMavlink1PayloadLeavesTheExtensionsZero) {
  const GpsRawInt m = DistinctGps();
  const Bytes p = Pack(m);
  const auto base = Unpack<GpsRawInt>(std::span<const uint8_t>(p).first(30));
  ASSERT_TRUE(base.has_value());
  EXPECT_EQ(base->satellites_visible, m.satellites_visible);
  EXPECT_EQ(base->alt_ellipsoid, 0);
  EXPECT_EQ(base->yaw, 0);
}

TEST(Attitude, LayoutAndRoundTrip) {
  const Attitude m{.time_boot_ms = 123456,
                   .roll = 0.1F,
                   .pitch = -0.2F,
                   .yaw = 3.0F,
                   .rollspeed = 0.01F,
                   .pitchspeed = -0.02F,
                   .yawspeed = 0.5F};
  const Bytes p = Pack(m);
  EXPECT_AT(p, 0, m.time_boot_ms);
  EXPECT_AT(p, 4, m.roll);
  EXPECT_AT(p, 8, m.pitch);
  EXPECT_AT(p, 12, m.yaw);
  EXPECT_AT(p, 16, m.rollspeed);
  EXPECT_AT(p, 20, m.pitchspeed);
  EXPECT_AT(p, 24, m.yawspeed);
  // IEEE-754 single, little-endian: 3.0 = 0x40400000.
  EXPECT_EQ(Bytes(p.begin() + 12, p.begin() + 16), (Bytes{0x00, 0x00, 0x40, 0x40}));
  ExpectRoundTrip(m, 28);
}

TEST(AttitudeQuaternion, LayoutAndRoundTrip) {
  const AttitudeQuaternion m{.time_boot_ms = 99,
                             .q1 = 0.5F,
                             .q2 = -0.5F,
                             .q3 = 0.25F,
                             .q4 = -0.75F,
                             .rollspeed = 1.5F,
                             .pitchspeed = -2.5F,
                             .yawspeed = 3.5F,
                             .repr_offset_q = {1.0F, 2.0F, 4.0F, 8.0F}};
  const Bytes p = Pack(m);
  EXPECT_AT(p, 0, m.time_boot_ms);
  EXPECT_AT(p, 4, m.q1);
  EXPECT_AT(p, 8, m.q2);
  EXPECT_AT(p, 12, m.q3);
  EXPECT_AT(p, 16, m.q4);
  EXPECT_AT(p, 20, m.rollspeed);
  EXPECT_AT(p, 24, m.pitchspeed);
  EXPECT_AT(p, 28, m.yawspeed);
  for (std::size_t i = 0; i < 4; ++i) EXPECT_AT(p, 32 + 4 * i, m.repr_offset_q[i]);
  ExpectRoundTrip(m, 48);
}

TEST(GlobalPositionInt, LayoutAndRoundTrip) {
  const GlobalPositionInt m{.time_boot_ms = 7777,
                            .lat = 473977420,
                            .lon = -85455940,
                            .alt = 488000,
                            .relative_alt = 12000,
                            .vx = -150,
                            .vy = 260,
                            .vz = -37,
                            .hdg = 27000};
  const Bytes p = Pack(m);
  EXPECT_AT(p, 0, m.time_boot_ms);
  EXPECT_AT(p, 4, m.lat);
  EXPECT_AT(p, 8, m.lon);
  EXPECT_AT(p, 12, m.alt);
  EXPECT_AT(p, 16, m.relative_alt);
  EXPECT_AT(p, 20, m.vx);
  EXPECT_AT(p, 22, m.vy);
  EXPECT_AT(p, 24, m.vz);
  EXPECT_AT(p, 26, m.hdg);
  ExpectRoundTrip(m, 28);
}

TEST(CommandLong, LayoutAndRoundTrip) {
  const CommandLong m{.target_system = 1,
                      .target_component = 2,
                      .command = kMavCmdSetMessageInterval,
                      .confirmation = 3,
                      .param1 = 330.0F,
                      .param2 = 100000.0F,
                      .param3 = 3.0F,
                      .param4 = 4.0F,
                      .param5 = 5.0F,
                      .param6 = 6.0F,
                      .param7 = 7.0F};
  const Bytes p = Pack(m);
  EXPECT_AT(p, 0, m.param1);
  EXPECT_AT(p, 4, m.param2);
  EXPECT_AT(p, 8, m.param3);
  EXPECT_AT(p, 12, m.param4);
  EXPECT_AT(p, 16, m.param5);
  EXPECT_AT(p, 20, m.param6);
  EXPECT_AT(p, 24, m.param7);
  EXPECT_AT(p, 28, m.command);
  EXPECT_AT(p, 30, m.target_system);
  EXPECT_AT(p, 31, m.target_component);
  EXPECT_AT(p, 32, m.confirmation);
  ExpectRoundTrip(m, 33);
}

TEST(CommandAck, LayoutAndRoundTrip) {
  const CommandAck m{.command = kMavCmdSetMessageInterval,
                     .result = kMavResultInProgress,
                     .progress = 42,
                     .result_param2 = -70000,
                     .target_system = 255,
                     .target_component = 190};
  const Bytes p = Pack(m);
  EXPECT_AT(p, 0, m.command);
  EXPECT_AT(p, 2, m.result);
  EXPECT_AT(p, 3, m.progress);
  EXPECT_AT(p, 4, m.result_param2);
  EXPECT_AT(p, 8, m.target_system);
  EXPECT_AT(p, 9, m.target_component);
  ExpectRoundTrip(m, 10);
}

TEST(CommandAck, TrimmedAndShortPayloadsReadAsZeroExtensions) {
  // What an autopilot without the extensions sends: command and result only.
  const auto ack = Unpack<CommandAck>(Bytes{0xFF, 0x01, 0x00});
  ASSERT_TRUE(ack.has_value());
  EXPECT_EQ(*ack, (CommandAck{.command = 511, .result = kMavResultAccepted}));
  // The frame carries two payload bytes; the parser restores the other eight.
  const Bytes frame = Encode(*ack, 0, 1, 1);
  ASSERT_GE(frame.size(), 2U);
  EXPECT_EQ(frame[1], 2);
  EXPECT_FALSE(Unpack<CommandAck>(Bytes(11, 1)).has_value());
}

AdsbVehicle DistinctAdsb() {
  return AdsbVehicle{.icao_address = 0x00ABCDEF,
                     .lat = 473977420,
                     .lon = 85455940,
                     .altitude_type = kAdsbAltitudeTypeGeometric,
                     .altitude = 600000,
                     .heading = 9000,
                     .hor_velocity = 1200,
                     .ver_velocity = -300,
                     .callsign = {'S', 'T', 'E', 'V', 'I', '0', '0', '1', '\0'},
                     .emitter_type = kAdsbEmitterTypeUav,
                     .tslc = 2,
                     .flags = kAdsbFlagsValidCoords | kAdsbFlagsValidAltitude |
                              kAdsbFlagsValidHeading | kAdsbFlagsValidVelocity |
                              kAdsbFlagsValidCallsign | kAdsbFlagsVerticalVelocityValid,
                     .squawk = 7000};
}

TEST(AdsbVehicle, LayoutAndRoundTrip) {
  const AdsbVehicle m = DistinctAdsb();
  const Bytes p = Pack(m);
  EXPECT_AT(p, 0, m.icao_address);
  EXPECT_AT(p, 4, m.lat);
  EXPECT_AT(p, 8, m.lon);
  EXPECT_AT(p, 12, m.altitude);
  EXPECT_AT(p, 16, m.heading);
  EXPECT_AT(p, 18, m.hor_velocity);
  EXPECT_AT(p, 20, m.ver_velocity);
  EXPECT_AT(p, 22, m.flags);
  EXPECT_AT(p, 24, m.squawk);
  EXPECT_AT(p, 26, m.altitude_type);
  // char[9] sorts with the one-byte fields, in XML order: after altitude_type.
  EXPECT_EQ(std::string(p.begin() + 27, p.begin() + 35), "STEVI001");
  EXPECT_EQ(p[35], 0);
  EXPECT_AT(p, 36, m.emitter_type);
  EXPECT_AT(p, 37, m.tslc);
  EXPECT_EQ(m.flags, 0x9F);
  ExpectRoundTrip(m, 38);
}

ObstacleDistance DistinctObstacles() {
  ObstacleDistance m{.time_usec = 0x0A0B0C0D0E0F1011,
                     .sensor_type = kMavDistanceSensorUnknown,
                     .increment = 5,
                     .min_distance = 20,
                     .max_distance = 8000,
                     .increment_f = 2.5F,
                     .angle_offset = -90.0F,
                     .frame = kMavFrameBodyFrd};
  for (std::size_t i = 0; i < m.distances.size(); ++i) {
    m.distances[i] = static_cast<uint16_t>(1000 + 37 * i);
  }
  return m;
}

TEST(ObstacleDistance, LayoutAndRoundTrip) {
  const ObstacleDistance m = DistinctObstacles();
  const Bytes p = Pack(m);
  EXPECT_AT(p, 0, m.time_usec);
  for (std::size_t i = 0; i < 72; ++i) EXPECT_AT(p, 8 + 2 * i, m.distances[i]);
  // In the XML min_distance comes before max_distance; both are uint16_t, so they keep that order.
  EXPECT_AT(p, 152, m.min_distance);
  EXPECT_AT(p, 154, m.max_distance);
  EXPECT_AT(p, 156, m.sensor_type);
  EXPECT_AT(p, 157, m.increment);
  // The extensions: a float at 158, not aligned, as they are never reordered.
  EXPECT_AT(p, 158, m.increment_f);
  EXPECT_AT(p, 162, m.angle_offset);
  EXPECT_AT(p, 166, m.frame);
  ExpectRoundTrip(m, 167);
}

TEST(ObstacleDistance, WithoutExtensionsTheFrameStopsAfterTheBaseFields) {
  ObstacleDistance m = DistinctObstacles();
  m.increment_f = 0;
  m.angle_offset = 0;
  m.frame = 0;
  const Bytes frame = Encode(m, 0, 1, 1);
  ASSERT_GE(frame.size(), 2U);
  EXPECT_EQ(frame[1], 158);
}

TEST(Decode, RefusesAnotherMessagesFrame) {
  Frame frame;
  frame.message_id = Heartbeat::kId;
  frame.payload = Pack(Heartbeat{});
  EXPECT_FALSE(Decode<SystemTime>(frame).has_value());
  EXPECT_TRUE(Decode<Heartbeat>(frame).has_value());
}

TEST(Unpack, RefusesPayloadsLongerThanTheMessage) {
  EXPECT_FALSE(Unpack<Heartbeat>(Bytes(10, 0)).has_value());
  EXPECT_FALSE(Unpack<ObstacleDistance>(Bytes(168, 0)).has_value());
  EXPECT_TRUE(Unpack<ObstacleDistance>(Bytes(1, 0)).has_value());
}

TEST(Pack, EveryMessageFillsItsMaxLength) {
  EXPECT_EQ(Pack(Heartbeat{}).size(), FindMessage(Heartbeat::kId)->max_length);
  EXPECT_EQ(Pack(SystemTime{}).size(), FindMessage(SystemTime::kId)->max_length);
  EXPECT_EQ(Pack(GpsRawInt{}).size(), FindMessage(GpsRawInt::kId)->max_length);
  EXPECT_EQ(Pack(Attitude{}).size(), FindMessage(Attitude::kId)->max_length);
  EXPECT_EQ(Pack(AttitudeQuaternion{}).size(), FindMessage(AttitudeQuaternion::kId)->max_length);
  EXPECT_EQ(Pack(GlobalPositionInt{}).size(), FindMessage(GlobalPositionInt::kId)->max_length);
  EXPECT_EQ(Pack(CommandLong{}).size(), FindMessage(CommandLong::kId)->max_length);
  EXPECT_EQ(Pack(CommandAck{}).size(), FindMessage(CommandAck::kId)->max_length);
  EXPECT_EQ(Pack(AdsbVehicle{}).size(), FindMessage(AdsbVehicle::kId)->max_length);
  EXPECT_EQ(Pack(ObstacleDistance{}).size(), FindMessage(ObstacleDistance::kId)->max_length);
}

}  // namespace
}  // namespace stevi::client::mavlink
