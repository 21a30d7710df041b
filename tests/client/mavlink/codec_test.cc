// The MAVLink codec against the specification: catalogue check values of the checksum, every
// CRC_EXTRA recomputed from the XML field lists, frames worked out by hand (and one captured from
// an autopilot), trimming, MAVLink 1, signing, unknown ids and resynchronisation.
#include "client/mavlink/codec.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <initializer_list>
#include <random>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace stevi::client::mavlink {
namespace {

using Bytes = std::vector<uint8_t>;

// The reference checksum: the byte-wise "X.25 accumulate" formula MAVLink's documentation gives,
// a different formulation from the codec's bit-by-bit loop.
uint16_t ReferenceCrc(std::span<const uint8_t> bytes, uint16_t crc = 0xFFFF) {
  for (const uint8_t byte : bytes) {
    uint8_t tmp = static_cast<uint8_t>(byte ^ (crc & 0xFF));
    tmp = static_cast<uint8_t>(tmp ^ (tmp << 4));
    crc = static_cast<uint16_t>((crc >> 8) ^ (tmp << 8) ^ (tmp << 3) ^ (tmp >> 4));
  }
  return crc;
}

uint16_t ReferenceCrc(std::string_view text, uint16_t crc = 0xFFFF) {
  const auto* data = reinterpret_cast<const uint8_t*>(text.data());
  return ReferenceCrc(std::span<const uint8_t>(data, text.size()), crc);
}

// Completes a frame whose header is in `out`: the payload, then the reference checksum of all but
// the magic byte and of the CRC_EXTRA, little-endian (the same in MAVLink 1 and 2).
void AppendPayloadAndChecksum(Bytes& out, const Bytes& payload, uint8_t crc_extra) {
  out.insert(out.end(), payload.begin(), payload.end());
  uint16_t crc = ReferenceCrc(std::span<const uint8_t>(out).subspan(1));
  crc = ReferenceCrc(std::span<const uint8_t>(&crc_extra, 1), crc);
  out.push_back(static_cast<uint8_t>(crc & 0xFF));
  out.push_back(static_cast<uint8_t>(crc >> 8));
}

// A frame built by the test alone (the reference checksum, the CRC_EXTRA given): for the cases
// the encoder does not write (MAVLink 1, flags, untrimmed or over-long payloads, unknown ids).
Bytes ReferenceFrameV2(uint8_t incompat, uint8_t compat, uint8_t seq, uint8_t sysid, uint8_t compid,
                       uint32_t msgid, const Bytes& payload, uint8_t crc_extra) {
  Bytes out = {0xFD,
               static_cast<uint8_t>(payload.size()),
               incompat,
               compat,
               seq,
               sysid,
               compid,
               static_cast<uint8_t>(msgid),
               static_cast<uint8_t>(msgid >> 8),
               static_cast<uint8_t>(msgid >> 16)};
  AppendPayloadAndChecksum(out, payload, crc_extra);
  return out;
}

Bytes ReferenceFrameV1(uint8_t seq, uint8_t sysid, uint8_t compid, uint8_t msgid,
                       const Bytes& payload, uint8_t crc_extra) {
  Bytes out = {0xFE, static_cast<uint8_t>(payload.size()), seq, sysid, compid, msgid};
  AppendPayloadAndChecksum(out, payload, crc_extra);
  return out;
}

Bytes Concat(std::initializer_list<Bytes> parts) {
  Bytes out;
  for (const Bytes& part : parts) out.insert(out.end(), part.begin(), part.end());
  return out;
}

// Feeds `bytes` in chunks of `chunk` bytes (0: all at once) and returns the frames delivered.
std::vector<Frame> FeedAll(Parser& parser, const Bytes& bytes, std::size_t chunk = 0) {
  std::vector<Frame> frames;
  const auto keep = [&frames](const Frame& frame) { frames.push_back(frame); };
  if (chunk == 0) chunk = std::max<std::size_t>(bytes.size(), 1);
  for (std::size_t at = 0; at < bytes.size(); at += chunk) {
    const std::size_t n = std::min(chunk, bytes.size() - at);
    parser.Feed(std::span<const uint8_t>(bytes).subspan(at, n), keep);
  }
  return frames;
}

// The bridge's HEARTBEAT, worked out by hand from the specification:
//   payload (wire order: uint32 custom_mode first, then the uint8 fields in XML order)
//     custom_mode 0 -> 00 00 00 00, type MAV_TYPE_ONBOARD_CONTROLLER 18 -> 12,
//     autopilot MAV_AUTOPILOT_INVALID 8 -> 08, base_mode 0 -> 00,
//     system_status MAV_STATE_ACTIVE 4 -> 04, mavlink_version 3 -> 03
//   (no trailing zero: len 9)
//   header FD, len 09, incompat 00, compat 00, seq 2A, sysid 01,
//     compid MAV_COMP_ID_OBSTACLE_AVOIDANCE 196 -> C4, msgid 0 -> 00 00 00
//   checksum: CRC-16/MCRF4XX over the 9 header bytes after FD and the 9 payload bytes, then
//     CRC_EXTRA 50 -> 0x9500, sent low byte first: 00 95.
const Bytes kHeartbeatV2 = {0xFD, 0x09, 0x00, 0x00, 0x2A, 0x01, 0xC4, 0x00, 0x00, 0x00, 0x00,
                            0x00, 0x00, 0x00, 0x12, 0x08, 0x00, 0x04, 0x03, 0x00, 0x95};
const Bytes kHeartbeatPayload = {0x00, 0x00, 0x00, 0x00, 0x12, 0x08, 0x00, 0x04, 0x03};

// The same message as MAVLink 1: FE, len 09, seq 2A, sysid 01, compid C4, msgid 00, the payload,
// and the checksum over the 5 header bytes after FE and the payload, then 50 -> 0xDF07.
const Bytes kHeartbeatV1 = {0xFE, 0x09, 0x2A, 0x01, 0xC4, 0x00, 0x00, 0x00, 0x00,
                            0x00, 0x12, 0x08, 0x00, 0x04, 0x03, 0x07, 0xDF};

// A MAVLink 1 HEARTBEAT captured from an ArduPilot quadrotor (published on brucebotstudio.com,
// "Mavlink", 2015): seq 0x4E, system 1, component 1, type 2 (quadrotor), autopilot 3 (ArduPilot),
// base_mode 0x51, system_status 4, version 3.
const Bytes kCapturedHeartbeatV1 = {0xFE, 0x09, 0x4E, 0x01, 0x01, 0x00, 0x00, 0x00, 0x00,
                                    0x00, 0x02, 0x03, 0x51, 0x04, 0x03, 0x1C, 0x7F};

// The same HEARTBEAT as kHeartbeatV2 but signed (incompat 0x01) and seq 2B; checksum 0xE3F7.
// The signature (link id, 6-byte timestamp, 6-byte signature) is arbitrary here: the parser does
// not check it. It is made of STX bytes so that scanning it instead of skipping it would show.
const Bytes kSignedHeartbeat = {0xFD, 0x09, 0x01, 0x00, 0x2B, 0x01, 0xC4, 0x00, 0x00, 0x00, 0x00,
                                0x00, 0x00, 0x00, 0x12, 0x08, 0x00, 0x04, 0x03, 0xF7, 0xE3};
const Bytes kSignature(13, 0xFD);

TEST(Crc16, CatalogueCheckValues) {
  const std::string_view check = "123456789";
  const auto* data = reinterpret_cast<const uint8_t*>(check.data());
  const std::span<const uint8_t> bytes(data, check.size());
  // CRC-16/MCRF4XX's check value; CRC-16/X-25 is the same CRC with a final XOR of 0xFFFF.
  EXPECT_EQ(Crc16(bytes), 0x6F91);
  EXPECT_EQ(Crc16(bytes) ^ 0xFFFF, 0x906E);
  EXPECT_EQ(Crc16({}), 0xFFFF);
}

TEST(Crc16, AgreesWithTheAccumulateFormulaAndContinues) {
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> byte(0, 255);
  for (std::size_t n : {1U, 2U, 17U, 255U, 1000U}) {
    Bytes bytes(n);
    for (uint8_t& b : bytes) b = static_cast<uint8_t>(byte(rng));
    EXPECT_EQ(Crc16(bytes), ReferenceCrc(bytes)) << n << " bytes";
    const std::span<const uint8_t> all(bytes);
    const std::size_t half = n / 2;
    EXPECT_EQ(Crc16(all.subspan(half), Crc16(all.first(half))), ReferenceCrc(bytes));
  }
}

// A field as the XML declares it: type ("uint16_t", "char" for char[9]), name, array length.
struct XmlField {
  std::string type;
  std::string name;
  int array_length = 0;
};

struct XmlMessage {
  uint32_t id;
  std::string name;
  std::vector<XmlField> base;        // XML order
  std::vector<XmlField> extensions;  // XML order, after <extensions/>
};

int TypeSize(const std::string& type) {
  if (type == "uint64_t" || type == "int64_t" || type == "double") return 8;
  if (type == "uint32_t" || type == "int32_t" || type == "float") return 4;
  if (type == "uint16_t" || type == "int16_t") return 2;
  return 1;  // (u)int8_t, char, uint8_t_mavlink_version
}

// The spec's algorithm: "NAME ", then for each base field in wire order "type " and "name " (and
// the array length as a byte); uint8_t_mavlink_version counts as uint8_t; extensions left out.
uint8_t ReferenceCrcExtra(const XmlMessage& message) {
  std::vector<XmlField> wire = message.base;
  std::stable_sort(wire.begin(), wire.end(), [](const XmlField& a, const XmlField& b) {
    return TypeSize(a.type) > TypeSize(b.type);
  });
  uint16_t crc = ReferenceCrc(message.name + " ");
  for (const XmlField& field : wire) {
    const std::string type = field.type == "uint8_t_mavlink_version" ? "uint8_t" : field.type;
    crc = ReferenceCrc(type + " ", crc);
    crc = ReferenceCrc(field.name + " ", crc);
    if (field.array_length > 0) {
      const auto length = static_cast<uint8_t>(field.array_length);
      crc = ReferenceCrc(std::span<const uint8_t>(&length, 1), crc);
    }
  }
  return static_cast<uint8_t>((crc & 0xFF) ^ (crc >> 8));
}

int PayloadLength(const std::vector<XmlField>& fields) {
  int length = 0;
  for (const XmlField& f : fields) length += TypeSize(f.type) * std::max(f.array_length, 1);
  return length;
}

// The messages' fields copied from minimal.xml (HEARTBEAT) and common.xml, in XML order.
std::vector<XmlMessage> XmlMessages() {
  const auto f = [](const char* type, const char* name, int n = 0) {
    return XmlField{type, name, n};
  };
  return {
      {0,
       "HEARTBEAT",
       {f("uint8_t", "type"), f("uint8_t", "autopilot"), f("uint8_t", "base_mode"),
        f("uint32_t", "custom_mode"), f("uint8_t", "system_status"),
        f("uint8_t_mavlink_version", "mavlink_version")},
       {}},
      {2, "SYSTEM_TIME", {f("uint64_t", "time_unix_usec"), f("uint32_t", "time_boot_ms")}, {}},
      {24,
       "GPS_RAW_INT",
       {f("uint64_t", "time_usec"), f("uint8_t", "fix_type"), f("int32_t", "lat"),
        f("int32_t", "lon"), f("int32_t", "alt"), f("uint16_t", "eph"), f("uint16_t", "epv"),
        f("uint16_t", "vel"), f("uint16_t", "cog"), f("uint8_t", "satellites_visible")},
       {f("int32_t", "alt_ellipsoid"), f("uint32_t", "h_acc"), f("uint32_t", "v_acc"),
        f("uint32_t", "vel_acc"), f("uint32_t", "hdg_acc"), f("uint16_t", "yaw")}},
      {30,
       "ATTITUDE",
       {f("uint32_t", "time_boot_ms"), f("float", "roll"), f("float", "pitch"), f("float", "yaw"),
        f("float", "rollspeed"), f("float", "pitchspeed"), f("float", "yawspeed")},
       {}},
      {31,
       "ATTITUDE_QUATERNION",
       {f("uint32_t", "time_boot_ms"), f("float", "q1"), f("float", "q2"), f("float", "q3"),
        f("float", "q4"), f("float", "rollspeed"), f("float", "pitchspeed"),
        f("float", "yawspeed")},
       {f("float", "repr_offset_q", 4)}},
      {33,
       "GLOBAL_POSITION_INT",
       {f("uint32_t", "time_boot_ms"), f("int32_t", "lat"), f("int32_t", "lon"),
        f("int32_t", "alt"), f("int32_t", "relative_alt"), f("int16_t", "vx"), f("int16_t", "vy"),
        f("int16_t", "vz"), f("uint16_t", "hdg")},
       {}},
      {76,
       "COMMAND_LONG",
       {f("uint8_t", "target_system"), f("uint8_t", "target_component"), f("uint16_t", "command"),
        f("uint8_t", "confirmation"), f("float", "param1"), f("float", "param2"),
        f("float", "param3"), f("float", "param4"), f("float", "param5"), f("float", "param6"),
        f("float", "param7")},
       {}},
      {77,
       "COMMAND_ACK",
       {f("uint16_t", "command"), f("uint8_t", "result")},
       {f("uint8_t", "progress"), f("int32_t", "result_param2"), f("uint8_t", "target_system"),
        f("uint8_t", "target_component")}},
      {246,
       "ADSB_VEHICLE",
       {f("uint32_t", "ICAO_address"), f("int32_t", "lat"), f("int32_t", "lon"),
        f("uint8_t", "altitude_type"), f("int32_t", "altitude"), f("uint16_t", "heading"),
        f("uint16_t", "hor_velocity"), f("int16_t", "ver_velocity"), f("char", "callsign", 9),
        f("uint8_t", "emitter_type"), f("uint8_t", "tslc"), f("uint16_t", "flags"),
        f("uint16_t", "squawk")},
       {}},
      {330,
       "OBSTACLE_DISTANCE",
       {f("uint64_t", "time_usec"), f("uint8_t", "sensor_type"), f("uint16_t", "distances", 72),
        f("uint8_t", "increment"), f("uint16_t", "min_distance"), f("uint16_t", "max_distance")},
       {f("float", "increment_f"), f("float", "angle_offset"), f("uint8_t", "frame")}},
  };
}

TEST(MessageTable, CrcExtraAndLengthsFollowFromTheXml) {
  const std::vector<XmlMessage> xml = XmlMessages();
  ASSERT_EQ(xml.size(), KnownMessages().size());
  for (const XmlMessage& message : xml) {
    SCOPED_TRACE(message.name);
    const MessageInfo* info = FindMessage(message.id);
    ASSERT_NE(info, nullptr);
    EXPECT_EQ(std::string(info->name), message.name);
    EXPECT_EQ(info->crc_extra, ReferenceCrcExtra(message));
    EXPECT_EQ(info->min_length, PayloadLength(message.base));
    EXPECT_EQ(info->max_length, PayloadLength(message.base) + PayloadLength(message.extensions));
  }
}

TEST(MessageTable, CrcExtraMatchesPublishedValues) {
  // The values generated C headers publish (MAVLINK_MESSAGE_CRCS), as a second reference.
  const std::vector<std::pair<uint32_t, uint8_t>> published = {
      {0, 50},   {2, 137},  {24, 24},  {30, 39},   {31, 246},
      {33, 104}, {76, 152}, {77, 143}, {246, 184}, {330, 23}};
  for (const auto& [id, extra] : published) {
    ASSERT_NE(FindMessage(id), nullptr) << id;
    EXPECT_EQ(FindMessage(id)->crc_extra, extra) << id;
  }
  EXPECT_EQ(FindMessage(1), nullptr);  // SYS_STATUS: not used by the bridge
  EXPECT_EQ(FindMessage(0xFFFFFF), nullptr);
}

TEST(EncodeFrame, HeartbeatMatchesHandWorkedBytes) {
  EXPECT_EQ(EncodeFrame(0x2A, 1, 196, 0, kHeartbeatPayload), kHeartbeatV2);
}

TEST(EncodeFrame, TrimsTrailingZerosOfCommandAck) {
  // COMMAND_ACK for MAV_CMD_SET_MESSAGE_INTERVAL (511 = 0x01FF), result ACCEPTED (0), the
  // extensions zero: of the 10 payload bytes FF 01 00 ... only FF 01 are sent, len 2.
  // seq 05, sysid 01, compid C4, msgid 77 = 0x4D; checksum with CRC_EXTRA 143 = 0xD48A.
  const Bytes expected = {0xFD, 0x02, 0x00, 0x00, 0x05, 0x01, 0xC4,
                          0x4D, 0x00, 0x00, 0xFF, 0x01, 0x8A, 0xD4};
  const Bytes payload = {0xFF, 0x01, 0, 0, 0, 0, 0, 0, 0, 0};
  const Bytes frame = EncodeFrame(5, 1, 196, 77, payload);
  EXPECT_EQ(frame, expected);

  Parser parser;
  const std::vector<Frame> frames = FeedAll(parser, frame);
  ASSERT_EQ(frames.size(), 1U);
  EXPECT_EQ(frames[0].message_id, 77U);
  EXPECT_EQ(frames[0].payload, payload);  // the zeros restored to max_length 10
}

TEST(EncodeFrame, KeepsTheFirstByteOfAnAllZeroPayload) {
  // An all-zero HEARTBEAT: one payload byte stays (len 1); CRC_EXTRA 50 gives 0x2CD5.
  const Bytes expected = {0xFD, 0x01, 0x00, 0x00, 0x00, 0x01, 0x01,
                          0x00, 0x00, 0x00, 0x00, 0xD5, 0x2C};
  EXPECT_EQ(EncodeFrame(0, 1, 1, 0, Bytes(9, 0)), expected);
  EXPECT_EQ(EncodeFrame(0, 1, 1, 0, Bytes{}), expected);  // empty = all zero
}

TEST(EncodeFrame, KeepsZerosInsideThePayload) {
  const Bytes payload = {0, 0, 0, 7, 0, 0, 0, 0, 0};
  const Bytes frame = EncodeFrame(0, 1, 1, 0, payload);
  ASSERT_GE(frame.size(), 2U);
  EXPECT_EQ(frame[1], 4);  // up to the 7
  EXPECT_EQ(frame, ReferenceFrameV2(0, 0, 0, 1, 1, 0, {0, 0, 0, 7}, 50));
}

TEST(EncodeFrame, RefusesUnknownIdsAndOverlongPayloads) {
  EXPECT_TRUE(EncodeFrame(0, 1, 1, 1, Bytes(5, 1)).empty());
  EXPECT_TRUE(EncodeFrame(0, 1, 1, 0, Bytes(10, 1)).empty());  // HEARTBEAT holds 9
  EXPECT_EQ(EncodeFrame(0, 1, 1, 330, Bytes(167, 1)).size(), 10U + 167U + 2U);
}

TEST(Parser, ReadsTheHandWorkedHeartbeat) {
  Parser parser;
  const std::vector<Frame> frames = FeedAll(parser, kHeartbeatV2);
  ASSERT_EQ(frames.size(), 1U);
  const Frame& f = frames[0];
  EXPECT_EQ(f.version, 2);
  EXPECT_EQ(f.incompat_flags, 0);
  EXPECT_EQ(f.compat_flags, 0);
  EXPECT_EQ(f.sequence, 0x2A);
  EXPECT_EQ(f.system_id, 1);
  EXPECT_EQ(f.component_id, 196);
  EXPECT_EQ(f.message_id, 0U);
  EXPECT_EQ(f.payload, kHeartbeatPayload);
  EXPECT_EQ(parser.stats().frames, 1U);
  EXPECT_EQ(parser.stats().bytes_skipped, 0U);
}

TEST(Parser, ReadsMavlink1Heartbeats) {
  Parser parser;
  const std::vector<Frame> frames = FeedAll(parser, Concat({kHeartbeatV1, kCapturedHeartbeatV1}));
  ASSERT_EQ(frames.size(), 2U);
  EXPECT_EQ(frames[0].version, 1);
  EXPECT_EQ(frames[0].sequence, 0x2A);
  EXPECT_EQ(frames[0].system_id, 1);
  EXPECT_EQ(frames[0].component_id, 196);
  EXPECT_EQ(frames[0].payload, kHeartbeatPayload);
  EXPECT_EQ(frames[1].version, 1);
  EXPECT_EQ(frames[1].sequence, 0x4E);
  EXPECT_EQ(frames[1].payload, (Bytes{0, 0, 0, 0, 0x02, 0x03, 0x51, 0x04, 0x03}));
  EXPECT_EQ(parser.stats().frames, 2U);
  EXPECT_EQ(parser.stats().v1_frames, 2U);
}

TEST(Parser, RestoresExtensionsAMavlink1FrameCannotCarry) {
  // GPS_RAW_INT (CRC_EXTRA 24) as MAVLink 1: the 30 base bytes; the payload comes back as 52.
  Bytes base(30);
  for (std::size_t i = 0; i < base.size(); ++i) base[i] = static_cast<uint8_t>(i + 1);
  Parser parser;
  const std::vector<Frame> frames = FeedAll(parser, ReferenceFrameV1(9, 1, 1, 24, base, 24));
  ASSERT_EQ(frames.size(), 1U);
  Bytes expected = base;
  expected.resize(52, 0);
  EXPECT_EQ(frames[0].payload, expected);
}

TEST(Parser, ReadsUntrimmedPayloadsAndIgnoresCompatFlags) {
  // The spec asks receivers to read a non-compliant frame with trailing zeros too.
  const Bytes payload = {0xFF, 0x01, 0, 0, 0, 0, 0, 0, 0, 0};
  const Bytes untrimmed = ReferenceFrameV2(0, 0, 1, 1, 1, 77, payload, 143);
  const Bytes compat = ReferenceFrameV2(0, 0x80, 2, 1, 1, 77, {0xFF, 0x01}, 143);
  Parser parser;
  const std::vector<Frame> frames = FeedAll(parser, Concat({untrimmed, compat}));
  ASSERT_EQ(frames.size(), 2U);
  EXPECT_EQ(frames[0].payload, payload);
  EXPECT_EQ(frames[1].compat_flags, 0x80);
  EXPECT_EQ(frames[1].payload, payload);
}

TEST(Parser, DropsASignedFrameAndFindsTheNextOne) {
  const Bytes stream = Concat({kSignedHeartbeat, kSignature, kHeartbeatV2});
  for (std::size_t chunk : {0U, 1U, 7U, 22U}) {
    SCOPED_TRACE(chunk);
    Parser parser;
    const std::vector<Frame> frames = FeedAll(parser, stream, chunk);
    ASSERT_EQ(frames.size(), 1U);
    EXPECT_EQ(frames[0].sequence, 0x2A);
    EXPECT_EQ(parser.stats().signed_or_unsupported, 1U);
    // The signature was skipped whole, not scanned: its STX bytes were never candidates.
    EXPECT_EQ(parser.stats().bytes_skipped, 0U);
    EXPECT_EQ(parser.stats().bad_length, 0U);
    EXPECT_EQ(parser.stats().crc_errors, 0U);
  }
}

TEST(Parser, DropsFramesWithAnUnknownIncompatFlag) {
  const Bytes flagged = ReferenceFrameV2(0x02, 0, 7, 1, 1, 0, kHeartbeatPayload, 50);
  Parser parser;
  const std::vector<Frame> frames = FeedAll(parser, Concat({flagged, kHeartbeatV2}));
  ASSERT_EQ(frames.size(), 1U);
  EXPECT_EQ(frames[0].sequence, 0x2A);
  EXPECT_EQ(parser.stats().signed_or_unsupported, 1U);
}

TEST(Parser, DropsUnknownMessages) {
  // SYS_STATUS (id 1, CRC_EXTRA 124) is valid MAVLink but not in the table.
  const Bytes sys_status = ReferenceFrameV2(0, 0, 3, 1, 1, 1, Bytes(31, 0x11), 124);
  const Bytes unknown_v1 = ReferenceFrameV1(4, 1, 1, 1, Bytes(31, 0x11), 124);
  Parser parser;
  const std::vector<Frame> frames = FeedAll(parser, Concat({sys_status, unknown_v1, kHeartbeatV2}));
  ASSERT_EQ(frames.size(), 1U);
  EXPECT_EQ(frames[0].message_id, 0U);
  EXPECT_GE(parser.stats().unknown_messages, 2U);
  EXPECT_EQ(parser.stats().frames, 1U);
}

TEST(Parser, DropsPayloadsLongerThanTheMessage) {
  // A HEARTBEAT with 10 payload bytes and a checksum that holds.
  Bytes payload = kHeartbeatPayload;
  payload.push_back(0x55);
  Parser parser;
  const std::vector<Frame> frames =
      FeedAll(parser, Concat({ReferenceFrameV2(0, 0, 1, 1, 1, 0, payload, 50), kHeartbeatV2}));
  ASSERT_EQ(frames.size(), 1U);
  EXPECT_EQ(frames[0].sequence, 0x2A);
  EXPECT_EQ(parser.stats().bad_length, 1U);
}

TEST(Parser, FindsAFrameAfterRandomGarbage) {
  std::mt19937 rng(11);
  std::uniform_int_distribution<int> byte(0, 255);
  Bytes garbage(500);
  for (uint8_t& b : garbage) b = static_cast<uint8_t>(byte(rng));
  // STX bytes with headers of known ids that cannot complete, as noise can hold.
  garbage[100] = 0xFD;
  garbage[300] = 0xFE;
  garbage[301] = 9;
  garbage[305] = 0;
  Parser parser;
  const std::vector<Frame> frames = FeedAll(parser, Concat({garbage, kHeartbeatV2}));
  ASSERT_EQ(frames.size(), 1U);
  EXPECT_EQ(frames[0].sequence, 0x2A);
  EXPECT_EQ(frames[0].payload, kHeartbeatPayload);
  // Every garbage byte is given up: as a non-STX byte, or as the start of a failed candidate.
  EXPECT_EQ(parser.stats().bytes_skipped, garbage.size());
}

TEST(Parser, FindsFramesSplitByteByByte) {
  const Bytes stream = Concat(
      {kHeartbeatV2, kHeartbeatV1, EncodeFrame(9, 2, 3, 330, Bytes(167, 0xA5)), kHeartbeatV2});
  Parser parser;
  const std::vector<Frame> frames = FeedAll(parser, stream, 1);
  ASSERT_EQ(frames.size(), 4U);
  EXPECT_EQ(frames[0].version, 2);
  EXPECT_EQ(frames[1].version, 1);
  EXPECT_EQ(frames[2].message_id, 330U);
  EXPECT_EQ(frames[2].payload, Bytes(167, 0xA5));
  EXPECT_EQ(frames[3].payload, kHeartbeatPayload);
  EXPECT_EQ(parser.stats().bytes_skipped, 0U);
}

TEST(Parser, FindsAGoodFrameRightAfterACorruptOne) {
  Bytes flipped = kHeartbeatV2;
  flipped[14] ^= 0x10;  // the payload's type byte
  Bytes truncated(kHeartbeatV2.begin(), kHeartbeatV2.begin() + 15);
  for (std::size_t chunk : {0U, 1U, 5U}) {
    SCOPED_TRACE(chunk);
    Parser parser;
    const std::vector<Frame> frames =
        FeedAll(parser, Concat({flipped, kHeartbeatV1, truncated, kHeartbeatV2}), chunk);
    ASSERT_EQ(frames.size(), 2U);
    EXPECT_EQ(frames[0].version, 1);
    EXPECT_EQ(frames[1].version, 2);
    EXPECT_EQ(frames[1].payload, kHeartbeatPayload);
    EXPECT_EQ(parser.stats().crc_errors, 2U);
  }
}

TEST(Parser, FindsAFrameHiddenInACorruptFramesPayload) {
  // A corrupt OBSTACLE_DISTANCE whose payload carries a whole HEARTBEAT: after the bad checksum
  // the parser goes back to one byte past the candidate's start and finds it.
  Bytes payload(167, 0x33);
  std::copy(kHeartbeatV2.begin(), kHeartbeatV2.end(), payload.begin() + 40);
  Bytes outer = EncodeFrame(1, 1, 1, 330, payload);
  outer[outer.size() - 1] ^= 0xFF;
  Parser parser;
  const std::vector<Frame> frames = FeedAll(parser, outer);
  ASSERT_EQ(frames.size(), 1U);
  EXPECT_EQ(frames[0].sequence, 0x2A);
  EXPECT_EQ(parser.stats().crc_errors, 1U);
}

TEST(Parser, WaitsForTheRestOfAFrame) {
  Parser parser;
  const std::span<const uint8_t> bytes(kHeartbeatV2);
  EXPECT_TRUE(FeedAll(parser, Bytes(bytes.begin(), bytes.end() - 1)).empty());
  EXPECT_EQ(FeedAll(parser, Bytes{bytes.back()}).size(), 1U);
  parser.Feed({}, [](const Frame&) { ADD_FAILURE() << "no frame in an empty chunk"; });
}

}  // namespace
}  // namespace stevi::client::mavlink
