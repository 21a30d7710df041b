#include "client/mavlink/codec.h"

#include <algorithm>

namespace stevi::client::mavlink {
namespace {

// The messages of messages.h. CRC_EXTRA and lengths from common.xml and minimal.xml; the tests
// recompute every CRC_EXTRA from the XML field lists.
constexpr std::array<MessageInfo, 10> kMessages = {{
    {0, "HEARTBEAT", 50, 9, 9},
    {2, "SYSTEM_TIME", 137, 12, 12},
    {24, "GPS_RAW_INT", 24, 30, 52},
    {30, "ATTITUDE", 39, 28, 28},
    {31, "ATTITUDE_QUATERNION", 246, 32, 48},
    {33, "GLOBAL_POSITION_INT", 104, 28, 28},
    {76, "COMMAND_LONG", 152, 33, 33},
    {77, "COMMAND_ACK", 143, 3, 10},
    {246, "ADSB_VEHICLE", 184, 38, 38},
    {330, "OBSTACLE_DISTANCE", 23, 158, 167},
}};

// The checksum of a frame: over the bytes after STX up to the payload's end, then the CRC_EXTRA.
uint16_t FrameChecksum(std::span<const uint8_t> after_stx, uint8_t crc_extra) {
  const uint16_t crc = Crc16(after_stx);
  return Crc16(std::span<const uint8_t>(&crc_extra, 1), crc);
}

}  // namespace

uint16_t Crc16(std::span<const uint8_t> bytes, uint16_t crc) {
  // Bit by bit, least significant bit first (the input is reflected).
  for (const uint8_t byte : bytes) {
    crc ^= byte;
    for (int bit = 0; bit < 8; ++bit) {
      crc = (crc & 1U) != 0 ? static_cast<uint16_t>((crc >> 1) ^ 0x8408U)
                            : static_cast<uint16_t>(crc >> 1);
    }
  }
  return crc;
}

std::span<const MessageInfo> KnownMessages() { return kMessages; }

const MessageInfo* FindMessage(uint32_t id) {
  for (const MessageInfo& info : kMessages) {
    if (info.id == id) return &info;
  }
  return nullptr;
}

std::vector<uint8_t> EncodeFrame(uint8_t sequence, uint8_t system_id, uint8_t component_id,
                                 uint32_t message_id, std::span<const uint8_t> payload) {
  const MessageInfo* info = FindMessage(message_id);
  if (info == nullptr || payload.size() > info->max_length) return {};
  // Trailing zeros are trimmed; the first byte stays even when it is zero.
  std::size_t length = payload.size();
  while (length > 1 && payload[length - 1] == 0) --length;
  const uint8_t first = payload.empty() ? 0 : payload[0];

  std::vector<uint8_t> out = {kStxV2,
                              static_cast<uint8_t>(std::max<std::size_t>(length, 1)),
                              0,
                              0,
                              sequence,
                              system_id,
                              component_id,
                              static_cast<uint8_t>(message_id & 0xFFU),
                              static_cast<uint8_t>((message_id >> 8) & 0xFFU),
                              static_cast<uint8_t>((message_id >> 16) & 0xFFU)};
  if (payload.empty()) {
    out.push_back(first);
  } else {
    out.insert(out.end(), payload.begin(), payload.begin() + static_cast<std::ptrdiff_t>(length));
  }
  const uint16_t crc = FrameChecksum(std::span<const uint8_t>(out).subspan(1), info->crc_extra);
  out.push_back(static_cast<uint8_t>(crc & 0xFFU));
  out.push_back(static_cast<uint8_t>(crc >> 8));
  return out;
}

void Parser::Feed(std::span<const uint8_t> bytes,
                  const std::function<void(const Frame&)>& on_frame) {
  std::size_t at = 0;
  for (;;) {
    // What remains of a dropped frame's signature (the buffer is empty when this is set).
    const std::size_t skip = std::min(signature_to_skip_, bytes.size() - at);
    signature_to_skip_ -= skip;
    at += skip;

    const std::size_t take = std::min(buffer_.size() - size_, bytes.size() - at);
    std::copy_n(bytes.begin() + static_cast<std::ptrdiff_t>(at), take, buffer_.begin() + size_);
    size_ += take;
    at += take;

    // Everything the buffer holds, until a candidate waits for more bytes.
    while (SeekStx()) {
      std::size_t frame_length = 0;
      const Step step = Judge(frame_length);
      if (step == Step::kNeedMore) break;
      if (step == Step::kSkipByte) {
        ++stats_.bytes_skipped;
        Consume(1);
        continue;
      }
      if (step == Step::kDeliver) {
        ++stats_.frames;
        if (buffer_[0] == kStxV1) ++stats_.v1_frames;
        on_frame(MakeFrame());
      }
      Consume(frame_length);
      const std::size_t signature = std::min(signature_to_skip_, size_);
      signature_to_skip_ -= signature;
      Consume(signature);
    }
    if (at == bytes.size()) return;
  }
}

bool Parser::SeekStx() {
  const auto begin = buffer_.begin();
  const auto end = begin + static_cast<std::ptrdiff_t>(size_);
  const auto stx = std::find_if(begin, end, [](uint8_t b) { return b == kStxV2 || b == kStxV1; });
  const auto skipped = static_cast<std::size_t>(stx - begin);
  stats_.bytes_skipped += skipped;
  Consume(skipped);
  return size_ > 0;
}

Parser::Step Parser::Judge(std::size_t& frame_length) {
  const bool v2 = buffer_[0] == kStxV2;
  const std::size_t header = v2 ? kHeaderLengthV2 : kHeaderLengthV1;
  if (size_ < header) return Step::kNeedMore;
  const std::size_t length = buffer_[1];
  const uint32_t id = v2 ? static_cast<uint32_t>(buffer_[7]) |
                               (static_cast<uint32_t>(buffer_[8]) << 8) |
                               (static_cast<uint32_t>(buffer_[9]) << 16)
                         : buffer_[5];
  const MessageInfo* info = FindMessage(id);
  if (info == nullptr) {
    ++stats_.unknown_messages;
    return Step::kSkipByte;
  }
  if (length > info->max_length) {
    ++stats_.bad_length;
    return Step::kSkipByte;
  }
  // At most 10 + 255 + 2 bytes, which the buffer holds.
  frame_length = header + length + kChecksumLength;
  if (size_ < frame_length) return Step::kNeedMore;

  const std::span<const uint8_t> after_stx(buffer_.data() + 1, header - 1 + length);
  const uint16_t sent =
      static_cast<uint16_t>(buffer_[header + length] | (buffer_[header + length + 1] << 8));
  if (FrameChecksum(after_stx, info->crc_extra) != sent) {
    ++stats_.crc_errors;
    return Step::kSkipByte;
  }
  const uint8_t incompat = v2 ? buffer_[2] : 0;
  if (incompat != 0) {
    ++stats_.signed_or_unsupported;
    signature_to_skip_ = (incompat & kIncompatSigned) != 0 ? kSignatureLength : 0;
    return Step::kDropFrame;
  }
  return Step::kDeliver;
}

void Parser::Consume(std::size_t n) {
  std::copy(buffer_.begin() + static_cast<std::ptrdiff_t>(n),
            buffer_.begin() + static_cast<std::ptrdiff_t>(size_), buffer_.begin());
  size_ -= n;
}

Frame Parser::MakeFrame() const {
  Frame frame;
  const bool v2 = buffer_[0] == kStxV2;
  const std::size_t header = v2 ? kHeaderLengthV2 : kHeaderLengthV1;
  const std::size_t length = buffer_[1];
  frame.version = v2 ? 2 : 1;
  if (v2) {
    frame.incompat_flags = buffer_[2];
    frame.compat_flags = buffer_[3];
    frame.sequence = buffer_[4];
    frame.system_id = buffer_[5];
    frame.component_id = buffer_[6];
    frame.message_id = static_cast<uint32_t>(buffer_[7]) |
                       (static_cast<uint32_t>(buffer_[8]) << 8) |
                       (static_cast<uint32_t>(buffer_[9]) << 16);
  } else {
    frame.sequence = buffer_[2];
    frame.system_id = buffer_[3];
    frame.component_id = buffer_[4];
    frame.message_id = buffer_[5];
  }
  const auto payload = buffer_.begin() + static_cast<std::ptrdiff_t>(header);
  frame.payload.assign(payload, payload + static_cast<std::ptrdiff_t>(length));
  // Judge has found the id in the table.
  frame.payload.resize(FindMessage(frame.message_id)->max_length, 0);
  return frame;
}

}  // namespace stevi::client::mavlink
