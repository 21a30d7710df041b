// The MAVLink messages: every field placed at the byte offset the specification's ordering gives
// (worked out by hand from common.xml: base fields sorted by type size, stable; extensions after,
// in XML order), round trips with distinct non-zero values, and trimmed or short payloads.
#include "client/mavlink/messages.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <functional>
#include <span>
#include <string>
#include <tuple>
#include <type_traits>
#include <vector>

#include "tests/client/mavlink/round_trip.h"

namespace stevi::client::mavlink {
namespace {

using Bytes = std::vector<uint8_t>;
using testing::ExpectRoundTrip;

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

// One field's place on the wire, worked out by hand: its offset and size, and the check that the
// payload's bytes there hold the member's value (each element's, for an array).
template <class M>
struct Place {
  std::size_t offset = 0;
  std::size_t size = 0;
  std::function<void(const Bytes&, const M&)> expect;
};

template <class M, class F>
Place<M> At(std::size_t offset, F M::*member) {
  if constexpr (requires { std::tuple_size<F>::value; }) {
    using Element = typename F::value_type;
    return {offset, sizeof(F), [offset, member](const Bytes& p, const M& m) {
              for (std::size_t i = 0; i < (m.*member).size(); ++i) {
                EXPECT_AT(p, offset + sizeof(Element) * i, (m.*member)[i]);
              }
            }};
  } else {
    return {offset, sizeof(F),
            [offset, member](const Bytes& p, const M& m) { EXPECT_AT(p, offset, m.*member); }};
  }
}

// What the specification gives for message M, worked out by hand from common.xml: the payload's
// length with the extensions and every field's place, in wire order; with a message of distinct
// non-zero values to check them on.
template <class M>
struct Reference {
  M sample;
  std::size_t max_length = 0;
  std::vector<Place<M>> places;
};

template <class M>
Reference<M> ReferenceOf();

template <>
Reference<Heartbeat> ReferenceOf() {
  using M = Heartbeat;
  return {.sample = {.type = 18,
                     .autopilot = 8,
                     .base_mode = 0x51,
                     .custom_mode = 0xA1B2C3D4,
                     .system_status = 4,
                     .mavlink_version = 3},
          .max_length = 9,
          .places = {At(0, &M::custom_mode), At(4, &M::type), At(5, &M::autopilot),
                     At(6, &M::base_mode), At(7, &M::system_status), At(8, &M::mavlink_version)}};
}

template <>
Reference<SystemTime> ReferenceOf() {
  using M = SystemTime;
  return {.sample = {.time_unix_usec = 0x0102030405060708, .time_boot_ms = 0x11223344},
          .max_length = 12,
          .places = {At(0, &M::time_unix_usec), At(8, &M::time_boot_ms)}};
}

template <>
Reference<GpsRawInt> ReferenceOf() {
  using M = GpsRawInt;
  return {.sample = {.time_usec = 0x1122334455667788,
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
                     .yaw = 36000},
          .max_length = 52,
          .places = {At(0, &M::time_usec), At(8, &M::lat), At(12, &M::lon), At(16, &M::alt),
                     At(20, &M::eph), At(22, &M::epv), At(24, &M::vel), At(26, &M::cog),
                     At(28, &M::fix_type), At(29, &M::satellites_visible),
                     // The extensions follow the 30 base bytes in XML order, not sorted by size.
                     At(30, &M::alt_ellipsoid), At(34, &M::h_acc), At(38, &M::v_acc),
                     At(42, &M::vel_acc), At(46, &M::hdg_acc), At(50, &M::yaw)}};
}

template <>
Reference<Attitude> ReferenceOf() {
  using M = Attitude;
  return {.sample = {.time_boot_ms = 123456,
                     .roll = 0.1F,
                     .pitch = -0.2F,
                     .yaw = 3.0F,
                     .rollspeed = 0.01F,
                     .pitchspeed = -0.02F,
                     .yawspeed = 0.5F},
          .max_length = 28,
          .places = {At(0, &M::time_boot_ms), At(4, &M::roll), At(8, &M::pitch), At(12, &M::yaw),
                     At(16, &M::rollspeed), At(20, &M::pitchspeed), At(24, &M::yawspeed)}};
}

template <>
Reference<AttitudeQuaternion> ReferenceOf() {
  using M = AttitudeQuaternion;
  return {.sample = {.time_boot_ms = 99,
                     .q1 = 0.5F,
                     .q2 = -0.5F,
                     .q3 = 0.25F,
                     .q4 = -0.75F,
                     .rollspeed = 1.5F,
                     .pitchspeed = -2.5F,
                     .yawspeed = 3.5F,
                     .repr_offset_q = {1.0F, 2.0F, 4.0F, 8.0F}},
          .max_length = 48,
          .places = {At(0, &M::time_boot_ms), At(4, &M::q1), At(8, &M::q2), At(12, &M::q3),
                     At(16, &M::q4), At(20, &M::rollspeed), At(24, &M::pitchspeed),
                     At(28, &M::yawspeed), At(32, &M::repr_offset_q)}};
}

template <>
Reference<GlobalPositionInt> ReferenceOf() {
  using M = GlobalPositionInt;
  return {.sample = {.time_boot_ms = 7777,
                     .lat = 473977420,
                     .lon = -85455940,
                     .alt = 488000,
                     .relative_alt = 12000,
                     .vx = -150,
                     .vy = 260,
                     .vz = -37,
                     .hdg = 27000},
          .max_length = 28,
          .places = {At(0, &M::time_boot_ms), At(4, &M::lat), At(8, &M::lon), At(12, &M::alt),
                     At(16, &M::relative_alt), At(20, &M::vx), At(22, &M::vy), At(24, &M::vz),
                     At(26, &M::hdg)}};
}

template <>
Reference<CommandLong> ReferenceOf() {
  using M = CommandLong;
  return {.sample = {.target_system = 1,
                     .target_component = 2,
                     .command = kMavCmdSetMessageInterval,
                     .confirmation = 3,
                     .param1 = 330.0F,
                     .param2 = 100000.0F,
                     .param3 = 3.0F,
                     .param4 = 4.0F,
                     .param5 = 5.0F,
                     .param6 = 6.0F,
                     .param7 = 7.0F},
          .max_length = 33,
          .places = {At(0, &M::param1), At(4, &M::param2), At(8, &M::param3), At(12, &M::param4),
                     At(16, &M::param5), At(20, &M::param6), At(24, &M::param7),
                     At(28, &M::command), At(30, &M::target_system), At(31, &M::target_component),
                     At(32, &M::confirmation)}};
}

template <>
Reference<CommandAck> ReferenceOf() {
  using M = CommandAck;
  return {
      .sample = {.command = kMavCmdSetMessageInterval,
                 .result = kMavResultInProgress,
                 .progress = 42,
                 .result_param2 = -70000,
                 .target_system = 255,
                 .target_component = 190},
      .max_length = 10,
      .places = {At(0, &M::command), At(2, &M::result), At(3, &M::progress),
                 At(4, &M::result_param2), At(8, &M::target_system), At(9, &M::target_component)}};
}

template <>
Reference<AdsbVehicle> ReferenceOf() {
  using M = AdsbVehicle;
  return {.sample = {.icao_address = 0x00ABCDEF,
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
                     .squawk = 7000},
          .max_length = 38,
          .places = {At(0, &M::icao_address), At(4, &M::lat), At(8, &M::lon), At(12, &M::altitude),
                     At(16, &M::heading), At(18, &M::hor_velocity), At(20, &M::ver_velocity),
                     At(22, &M::flags), At(24, &M::squawk), At(26, &M::altitude_type),
                     // char[9] sorts with the one-byte fields, in XML order: after altitude_type.
                     At(27, &M::callsign), At(36, &M::emitter_type), At(37, &M::tslc)}};
}

template <>
Reference<ObstacleDistance> ReferenceOf() {
  using M = ObstacleDistance;
  Reference<M> reference{
      .sample = {.time_usec = 0x0A0B0C0D0E0F1011,
                 .sensor_type = kMavDistanceSensorUnknown,
                 .increment = 5,
                 .min_distance = 20,
                 .max_distance = 8000,
                 .increment_f = 2.5F,
                 .angle_offset = -90.0F,
                 .frame = kMavFrameBodyFrd},
      .max_length = 167,
      // In the XML min_distance comes before max_distance; both are uint16_t, so they keep that
      // order. The extensions: a float at 158, not aligned, as they are never reordered.
      .places = {At(0, &M::time_usec), At(8, &M::distances), At(152, &M::min_distance),
                 At(154, &M::max_distance), At(156, &M::sensor_type), At(157, &M::increment),
                 At(158, &M::increment_f), At(162, &M::angle_offset), At(166, &M::frame)}};
  for (std::size_t i = 0; i < reference.sample.distances.size(); ++i) {
    reference.sample.distances[i] = static_cast<uint16_t>(1000 + 37 * i);
  }
  return reference;
}

// Expects each of the reference's places to hold its field of the sample, and the places to cover
// the payload end to end: no field missed, none overlapping.
template <class M>
void ExpectLayout(const Reference<M>& reference) {
  const Bytes p = Pack(reference.sample);
  std::size_t end = 0;
  for (const Place<M>& place : reference.places) {
    EXPECT_EQ(place.offset, end) << "a gap or an overlap before offset " << place.offset;
    place.expect(p, reference.sample);
    end = place.offset + place.size;
  }
  EXPECT_EQ(end, reference.max_length);
}

template <class M>
class Messages : public ::testing::Test {};
using AllMessages =
    ::testing::Types<Heartbeat, SystemTime, GpsRawInt, Attitude, AttitudeQuaternion,
                     GlobalPositionInt, CommandLong, CommandAck, AdsbVehicle, ObstacleDistance>;
TYPED_TEST_SUITE(Messages, AllMessages);

TYPED_TEST(Messages, LayoutAndRoundTrip) {
  const Reference<TypeParam> reference = ReferenceOf<TypeParam>();
  ExpectLayout(reference);
  ExpectRoundTrip(reference.sample, reference.max_length);
}

TYPED_TEST(Messages, PackFillsTheCodecTablesMaxLength) {
  EXPECT_EQ(Pack(TypeParam{}).size(), FindMessage(TypeParam::kId)->max_length);
}

TEST(Heartbeat, CustomModeIsLittleEndianByteByByte) {
  const Bytes p = Pack(ReferenceOf<Heartbeat>().sample);
  EXPECT_EQ(Bytes(p.begin(), p.begin() + 4), (Bytes{0xD4, 0xC3, 0xB2, 0xA1}));
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

TEST(GpsRawInt, ANegativeLatitudeIsTwosComplement) {
  const Bytes p = Pack(ReferenceOf<GpsRawInt>().sample);
  // 2^32 - 353632620 = 3941334676 = 0xEAEBFE94.
  EXPECT_EQ(Bytes(p.begin() + 8, p.begin() + 12), (Bytes{0x94, 0xFE, 0xEB, 0xEA}));
}

TEST(GpsRawInt, AMavlink1PayloadLeavesTheExtensionsZero) {
  const GpsRawInt m = ReferenceOf<GpsRawInt>().sample;
  const Bytes p = Pack(m);
  const auto base = Unpack<GpsRawInt>(std::span<const uint8_t>(p).first(30));
  ASSERT_TRUE(base.has_value());
  EXPECT_EQ(base->satellites_visible, m.satellites_visible);
  EXPECT_EQ(base->alt_ellipsoid, 0);
  EXPECT_EQ(base->yaw, 0);
}

TEST(Attitude, FloatsAreIeee754LittleEndian) {
  const Bytes p = Pack(ReferenceOf<Attitude>().sample);
  // yaw: 3.0 = 0x40400000.
  EXPECT_EQ(Bytes(p.begin() + 12, p.begin() + 16), (Bytes{0x00, 0x00, 0x40, 0x40}));
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

TEST(AdsbVehicle, TheCallsignIsItsCharactersAndANul) {
  const AdsbVehicle m = ReferenceOf<AdsbVehicle>().sample;
  const Bytes p = Pack(m);
  EXPECT_EQ(std::string(p.begin() + 27, p.begin() + 35), "STEVI001");
  EXPECT_EQ(p[35], 0);
  EXPECT_EQ(m.flags, 0x9F);
}

TEST(ObstacleDistance, WithoutExtensionsTheFrameStopsAfterTheBaseFields) {
  ObstacleDistance m = ReferenceOf<ObstacleDistance>().sample;
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

}  // namespace
}  // namespace stevi::client::mavlink
