// The MAVLink 2 frame codec for the autopilot bridge: the checksum (CRC-16/MCRF4XX with the
// message's CRC_EXTRA), the table of the messages this project knows, a frame encoder and a
// byte-stream parser. Written from the specification (mavlink.io/en/guide/serialization.html), as
// Debian packages no MAVLink library. The standard library only.
//
// What the parser does and does not do:
// - It reads MAVLink 2 (STX 0xFD) and MAVLink 1 (STX 0xFE) frames; the encoder writes MAVLink 2.
// - Message signing is NOT supported: a frame with any incompatibility flag set (0x01 = signed)
//   is dropped and counted, never delivered, and a signed frame's 13 signature bytes are skipped
//   so that the next frame is found.
// - A frame is delivered only when its message id is in the table (the CRC_EXTRA is needed to
//   check it) and its checksum holds.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <span>
#include <vector>

namespace stevi::client::mavlink {

inline constexpr uint8_t kStxV2 = 0xFD;
inline constexpr uint8_t kStxV1 = 0xFE;
// incompat_flags bit: a 13-byte signature follows the checksum.
inline constexpr uint8_t kIncompatSigned = 0x01;
inline constexpr std::size_t kHeaderLengthV2 = 10;  // STX to the message id's last byte
inline constexpr std::size_t kHeaderLengthV1 = 6;
inline constexpr std::size_t kChecksumLength = 2;
inline constexpr std::size_t kSignatureLength = 13;
// A signed MAVLink 2 frame with a 255-byte payload.
inline constexpr std::size_t kMaxFrameLength =
    kHeaderLengthV2 + 255 + kChecksumLength + kSignatureLength;

// CRC-16/MCRF4XX (polynomial 0x1021 reflected, no final XOR), which MAVLink calls the X.25
// checksum. `crc` continues a running value: Crc16(b, Crc16(a)) == Crc16(a then b).
uint16_t Crc16(std::span<const uint8_t> bytes, uint16_t crc = 0xFFFF);

// A message this project knows. Lengths in bytes of the payload as serialised (fields reordered).
struct MessageInfo {
  uint32_t id = 0;
  const char* name = "";
  uint8_t crc_extra = 0;   // from the message's base fields (see the spec's CRC_EXTRA)
  uint8_t min_length = 0;  // base fields
  uint8_t max_length = 0;  // base and extension fields
};

// The table, sorted by id.
std::span<const MessageInfo> KnownMessages();
// nullptr for ids this project does not know.
const MessageInfo* FindMessage(uint32_t id);

// A frame as read from the wire.
struct Frame {
  int version = 2;  // 1 or 2: the wire format it arrived in
  uint8_t incompat_flags = 0;
  uint8_t compat_flags = 0;  // ignored by this codec, as the spec allows
  uint8_t sequence = 0;
  uint8_t system_id = 0;
  uint8_t component_id = 0;
  uint32_t message_id = 0;
  // The payload restored to the message's max_length: the trailing zeros a MAVLink 2 sender trims
  // and the extension fields a MAVLink 1 frame cannot carry are put back as zeros.
  std::vector<uint8_t> payload;
};

// A MAVLink 2 frame's bytes: STX 0xFD, len, incompat 0, compat 0, seq, sysid, compid, the message
// id (3 bytes little-endian), the payload with its trailing zero bytes trimmed (its first byte is
// always kept), and the checksum over everything after STX followed by the CRC_EXTRA. A payload
// shorter than max_length is taken as zero-filled. Empty for an unknown message id or a payload
// longer than the message's max_length.
std::vector<uint8_t> EncodeFrame(uint8_t sequence, uint8_t system_id, uint8_t component_id,
                                 uint32_t message_id, std::span<const uint8_t> payload);

// A byte-stream decoder: feed it whatever chunks a link delivers (a UDP datagram, part of a
// serial read); frames may span chunks. It resynchronises on garbage: when a candidate frame fails
// (an unknown id, a length beyond the message's max_length, a bad checksum) it skips one byte from
// the candidate's start and searches for the next STX, so a frame inside garbage or right after a
// corrupt one is still found. The only guard against a false frame is the 16-bit checksum with
// the CRC_EXTRA. Memory is bounded: the buffer holds at most one frame (kMaxFrameLength bytes).
// A frame is delivered as soon as its last byte arrives, unless a candidate before it (an STX in
// noise) is still waiting for the bytes its header claims: then it comes once those have arrived
// and the candidate has failed, at most 267 bytes later.
// Thread-compatible: do not call Feed concurrently, nor from inside its callback.
class Parser {
 public:
  struct Stats {
    uint64_t frames = 0;     // delivered, both versions
    uint64_t v1_frames = 0;  // of those, MAVLink 1
    uint64_t crc_errors = 0;
    // Candidates (an STX and a header) with a message id not in the table: dropped unchecked. In
    // noise this also counts an STX followed by garbage.
    uint64_t unknown_messages = 0;
    // Frames with a good checksum and an incompatibility flag set (signed, or a flag this codec
    // does not know): dropped.
    uint64_t signed_or_unsupported = 0;
    // Bytes discarded while searching for an STX (each failed candidate also gives up its first
    // byte here).
    uint64_t bytes_skipped = 0;
    // Candidates whose payload length exceeds the message's max_length: dropped.
    uint64_t bad_length = 0;
  };

  // Calls on_frame for each valid frame of a known message id, in stream order.
  void Feed(std::span<const uint8_t> bytes, const std::function<void(const Frame&)>& on_frame);

  const Stats& stats() const { return stats_; }

 private:
  // What the buffer's front holds.
  enum class Step { kNeedMore, kSkipByte, kDropFrame, kDeliver };

  // Drops bytes up to the next STX; false when the buffer is empty then.
  bool SeekStx();
  // Judges the candidate frame at the buffer's front; frame_length is set for kDropFrame and
  // kDeliver.
  Step Judge(std::size_t& frame_length);
  void Consume(std::size_t n);
  Frame MakeFrame() const;

  std::array<uint8_t, kMaxFrameLength> buffer_{};
  std::size_t size_ = 0;
  // Signature bytes of a dropped signed frame still to come.
  std::size_t signature_to_skip_ = 0;
  Stats stats_;
};

}  // namespace stevi::client::mavlink
