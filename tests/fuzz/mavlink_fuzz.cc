// Fuzz target: the MAVLink byte stream as it arrives from an autopilot link (UDP datagrams or a
// serial port's reads), through the frame parser, every message decoder and the bridge's
// PoseJoiner, which turns the autopilot's messages into vehicle states.
//
// Input: byte 0's low 7 bits pick the chunk sizes the stream is fed in (a serial read's arbitrary
// cuts). With its top bit clear the rest is the stream as it is. With it set the rest is a list of
// messages, each [index into the known messages][payload length][payload], which the target
// encodes as MAVLink 2 frames with good checksums: so the fuzzer reaches the decoders and the
// PoseJoiner with any payload, not only the few whose 16-bit checksum it happens to get right.
// Checked besides the sanitizers:
//   - every delivered frame has a known id and its payload restored to that message's max_length;
//   - a decoded message packs back to the same payload bytes (decoders and encoders agree);
//   - the same stream fed in one piece delivers the same frames (chunking changes nothing);
//   - a vehicle state the PoseJoiner makes is finite and on the Earth.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "client/mavlink/translate.h"
#include "client/mavlink/codec.h"
#include "client/mavlink/messages.h"
#include "tests/fuzz/require.h"

namespace mav = stevi::client::mavlink;

namespace {

using stevi::fuzz::Require;

template <class T>
void RoundTrip(const mav::Frame& frame) {
  const std::optional<T> m = mav::Decode<T>(frame);
  if (!m) return;
  std::vector<uint8_t> packed = mav::Pack(*m);
  packed.resize(frame.payload.size(), 0);
  Require(packed == frame.payload);
}

std::vector<mav::Frame> Parse(std::span<const uint8_t> stream, uint8_t chunking) {
  mav::Parser parser;
  std::vector<mav::Frame> frames;
  const auto take = [&](const mav::Frame& f) { frames.push_back(f); };
  if (chunking == 0) {
    parser.Feed(stream, take);
    return frames;
  }
  std::size_t at = 0;
  std::size_t step = chunking;
  while (at < stream.size()) {
    const std::size_t n = std::min(step, stream.size() - at);
    parser.Feed(stream.subspan(at, n), take);
    at += n;
    step = step * 7 % 300 + 1;  // cuts of many sizes, from the one byte
  }
  return frames;
}

// The messages of `spec` as frames, back to back.
std::vector<uint8_t> EncodeMessages(std::span<const uint8_t> spec) {
  const std::span<const mav::MessageInfo> known = mav::KnownMessages();
  std::vector<uint8_t> stream;
  uint8_t sequence = 0;
  std::size_t at = 0;
  while (at + 2 <= spec.size()) {
    const mav::MessageInfo& info = known[spec[at] % known.size()];
    const std::size_t n =
        std::min<std::size_t>({spec[at + 1], info.max_length, spec.size() - at - 2});
    const std::vector<uint8_t> frame =
        mav::EncodeFrame(sequence++, 1, 1, info.id, spec.subspan(at + 2, n));
    stream.insert(stream.end(), frame.begin(), frame.end());
    at += 2 + n;
  }
  return stream;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  std::span<const uint8_t> stream(data + 1, size - 1);
  std::vector<uint8_t> encoded;
  if (data[0] & 0x80) {
    encoded = EncodeMessages(stream);
    stream = encoded;
  }
  const std::vector<mav::Frame> frames = Parse(stream, data[0] & 0x7F);
  const std::vector<mav::Frame> whole = Parse(stream, 0);
  Require(frames.size() == whole.size());

  mav::PoseJoiner joiner({});
  int64_t host_ns = 1'700'000'000'000'000'000;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const mav::Frame& f = frames[i];
    Require(f.payload == whole[i].payload && f.message_id == whole[i].message_id);
    const mav::MessageInfo* info = mav::FindMessage(f.message_id);
    Require(info != nullptr && f.payload.size() == info->max_length);
    RoundTrip<mav::Heartbeat>(f);
    RoundTrip<mav::SystemTime>(f);
    RoundTrip<mav::GpsRawInt>(f);
    RoundTrip<mav::Attitude>(f);
    RoundTrip<mav::AttitudeQuaternion>(f);
    RoundTrip<mav::GlobalPositionInt>(f);
    RoundTrip<mav::CommandLong>(f);
    RoundTrip<mav::CommandAck>(f);
    RoundTrip<mav::AdsbVehicle>(f);
    RoundTrip<mav::ObstacleDistance>(f);
    host_ns += 20'000'000;
    if (const auto state = joiner.OnMessage(f, host_ns)) {
      const auto& p = state->position();
      Require(std::abs(p.lat_deg()) <= 90 && std::abs(p.lon_deg()) <= 180);
      Require(std::isfinite(p.alt_m()) && std::isfinite(state->roll_deg()) &&
              std::isfinite(state->pitch_deg()) && std::isfinite(state->yaw_deg()));
    }
    (void)joiner.geoid_undulation_m();
  }
  return 0;
}
