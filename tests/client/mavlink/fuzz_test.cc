// The parser against a long stream of random frames, some left intact and some mutated (bits
// flipped, cut short, bytes inserted or deleted), with garbage between them, fed in random chunks.
// The test knows which frames it left intact, so it can require that exactly those come out, in
// order and unchanged: none lost, none made up.
#include "client/mavlink/codec.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <random>
#include <span>
#include <vector>

namespace stevi::client::mavlink {
namespace {

using Bytes = std::vector<uint8_t>;

constexpr uint64_t kSeed = 0x5EED2024;
constexpr int kFrames = 10000;

// What the parser must deliver for an intact frame.
struct Expected {
  int version = 2;
  uint8_t sequence = 0;
  uint8_t system_id = 0;
  uint8_t component_id = 0;
  uint32_t message_id = 0;
  Bytes payload;  // at max_length
  Bytes wire;     // the frame's bytes as put in the stream
};

class StreamMaker {
 public:
  explicit StreamMaker(uint64_t seed) : rng_(seed) {}

  // Appends one frame (intact or mutated) and perhaps garbage; records the intact ones.
  void AddItem() {
    if (Chance(0.15)) AddGarbage();
    const int kind = Uniform(0, 99);
    Expected frame = kind < 10 ? MakeV1() : MakeV2();
    const bool is_signed = kind >= 10 && kind < 16;
    Bytes wire = frame.wire;
    const std::size_t checked = wire.size();  // the bytes the checksum covers, with STX
    if (is_signed) {
      Sign(wire);
      for (int i = 0; i < 13; ++i) wire.push_back(RandomByte());
    }
    const bool mutate = Chance(0.3);
    if (mutate) {
      // A signed frame's signature is not checked: a shortened one would take bytes of the next
      // frame as its own. So mutations stay within the checked part.
      Mutate(wire, checked);
      ++mutated_;
    } else if (is_signed) {
      ++intact_signed_;
    } else {
      expected_.push_back(frame);
    }
    stream_.insert(stream_.end(), wire.begin(), wire.end());
  }

  const Bytes& stream() const { return stream_; }
  const std::vector<Expected>& expected() const { return expected_; }
  int mutated() const { return mutated_; }
  int intact_signed() const { return intact_signed_; }
  std::mt19937_64& rng() { return rng_; }

 private:
  int Uniform(int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(rng_); }
  bool Chance(double p) { return std::bernoulli_distribution(p)(rng_); }
  uint8_t RandomByte() { return static_cast<uint8_t>(Uniform(0, 255)); }

  const MessageInfo& RandomMessage(bool v1) {
    const std::span<const MessageInfo> all = KnownMessages();
    for (;;) {
      const MessageInfo& info =
          all[static_cast<std::size_t>(Uniform(0, static_cast<int>(all.size()) - 1))];
      if (!v1 || info.id <= 255) return info;
    }
  }

  // Random bytes up to a random length, zeros after (so trimming varies), some zeros inside.
  Bytes RandomPayload(std::size_t max_length) {
    Bytes payload(max_length, 0);
    const auto used = static_cast<std::size_t>(Uniform(0, static_cast<int>(max_length)));
    for (std::size_t i = 0; i < used; ++i) payload[i] = Chance(0.2) ? 0 : RandomByte();
    return payload;
  }

  Expected MakeV2() {
    const MessageInfo& info = RandomMessage(false);
    Expected e{2, RandomByte(), RandomByte(), RandomByte(), info.id, {}, {}};
    e.payload = RandomPayload(info.max_length);
    e.wire = EncodeFrame(e.sequence, e.system_id, e.component_id, e.message_id, e.payload);
    return e;
  }

  // MAVLink 1, as senders write it: the base fields, untrimmed.
  Expected MakeV1() {
    const MessageInfo& info = RandomMessage(true);
    Expected e{1, RandomByte(), RandomByte(), RandomByte(), info.id, {}, {}};
    Bytes base = RandomPayload(info.min_length);
    e.wire = {kStxV1,      info.min_length, e.sequence,
              e.system_id, e.component_id,  static_cast<uint8_t>(info.id)};
    e.wire.insert(e.wire.end(), base.begin(), base.end());
    AppendChecksum(e.wire, info.crc_extra);
    base.resize(info.max_length, 0);
    e.payload = base;
    return e;
  }

  static void AppendChecksum(Bytes& wire, uint8_t crc_extra) {
    const uint16_t crc = Crc16(std::span<const uint8_t>(&crc_extra, 1),
                               Crc16(std::span<const uint8_t>(wire).subspan(1)));
    wire.push_back(static_cast<uint8_t>(crc & 0xFF));
    wire.push_back(static_cast<uint8_t>(crc >> 8));
  }

  // Turns a MAVLink 2 frame into a signed one with a checksum that holds.
  static void Sign(Bytes& wire) {
    wire[2] = kIncompatSigned;
    const uint32_t id = wire[7] | (wire[8] << 8) | (wire[9] << 16);
    wire.resize(wire.size() - 2);
    AppendChecksum(wire, FindMessage(id)->crc_extra);
  }

  // A change that always alters the frame's first `checked` bytes.
  void Mutate(Bytes& wire, std::size_t checked) {
    const auto at = [&](std::size_t lo) {
      return static_cast<std::size_t>(Uniform(static_cast<int>(lo), static_cast<int>(checked) - 1));
    };
    switch (Uniform(0, 3)) {
      case 0: {  // 1 to 3 bit flips, at distinct bits (two flips of one bit would undo)
        const auto flips = static_cast<std::size_t>(Uniform(1, 3));
        std::vector<int> bits;
        while (bits.size() < flips) {
          const int bit = Uniform(0, static_cast<int>(checked) * 8 - 1);
          if (std::find(bits.begin(), bits.end(), bit) == bits.end()) bits.push_back(bit);
        }
        for (const int bit : bits)
          wire[static_cast<std::size_t>(bit / 8)] ^= static_cast<uint8_t>(1U << (bit % 8));
        break;
      }
      case 1:  // cut short (the signature goes with it)
        wire.resize(at(0));
        break;
      case 2: {  // bytes inserted inside
        const std::size_t where = at(1);
        Bytes extra(static_cast<std::size_t>(Uniform(1, 5)));
        for (uint8_t& b : extra) b = Chance(0.3) ? kStxV2 : RandomByte();
        // Right after the STX, bytes ending in that STX would give the frame back whole.
        if (where == 1 && extra.back() == wire[0]) extra.back() ^= 0x01;
        wire.insert(wire.begin() + static_cast<std::ptrdiff_t>(where), extra.begin(), extra.end());
        break;
      }
      default:  // a byte deleted, not the STX: garbage ending in an STX would give it back
        wire.erase(wire.begin() + static_cast<std::ptrdiff_t>(at(1)));
        break;
    }
  }

  // Noise, rich in STX bytes and in headers of known ids.
  void AddGarbage() {
    const int n = Uniform(1, 300);
    for (int i = 0; i < n; ++i) {
      const int pick = Uniform(0, 9);
      stream_.push_back(pick == 0 ? kStxV2 : pick == 1 ? kStxV1 : RandomByte());
    }
  }

  std::mt19937_64 rng_;
  Bytes stream_;
  std::vector<Expected> expected_;
  int mutated_ = 0;
  int intact_signed_ = 0;
};

TEST(ParserFuzz, DeliversExactlyTheIntactFrames) {
  std::printf("fuzz seed: 0x%llx, %d frames\n", static_cast<unsigned long long>(kSeed), kFrames);
  StreamMaker maker(kSeed);
  for (int i = 0; i < kFrames; ++i) maker.AddItem();
  Bytes stream = maker.stream();
  // The link goes on after the last frame: enough zeros to reject any candidate left waiting.
  stream.resize(stream.size() + kMaxFrameLength, 0);

  Parser parser;
  std::vector<Frame> delivered;
  std::uniform_int_distribution<int> chunk_size(0, 600);
  std::size_t at = 0;
  while (at < stream.size()) {
    // Mostly small chunks, as a serial port gives; sometimes empty, sometimes over the buffer.
    const int pick = chunk_size(maker.rng());
    const std::size_t n = std::min<std::size_t>(pick < 300 ? pick % 24 : pick, stream.size() - at);
    parser.Feed(std::span<const uint8_t>(stream).subspan(at, n),
                [&delivered](const Frame& f) { delivered.push_back(f); });
    at += n;
  }

  const std::vector<Expected>& expected = maker.expected();
  const Parser::Stats& stats = parser.stats();
  std::printf(
      "%zu bytes, %zu intact frames, %d mutated, %d intact signed; delivered %zu; crc errors "
      "%llu, unknown %llu, bad length %llu, signed %llu, skipped %llu bytes\n",
      stream.size(), expected.size(), maker.mutated(), maker.intact_signed(), delivered.size(),
      static_cast<unsigned long long>(stats.crc_errors),
      static_cast<unsigned long long>(stats.unknown_messages),
      static_cast<unsigned long long>(stats.bad_length),
      static_cast<unsigned long long>(stats.signed_or_unsupported),
      static_cast<unsigned long long>(stats.bytes_skipped));

  // In order, one for one: a missing frame or a made-up one shifts everything after it.
  const std::size_t common = std::min(delivered.size(), expected.size());
  for (std::size_t i = 0; i < common; ++i) {
    const Frame& got = delivered[i];
    const Expected& want = expected[i];
    ASSERT_EQ(got.version, want.version) << "frame " << i;
    ASSERT_EQ(got.sequence, want.sequence) << "frame " << i;
    ASSERT_EQ(got.system_id, want.system_id) << "frame " << i;
    ASSERT_EQ(got.component_id, want.component_id) << "frame " << i;
    ASSERT_EQ(got.message_id, want.message_id) << "frame " << i;
    ASSERT_EQ(got.payload, want.payload) << "frame " << i;
    ASSERT_EQ(got.incompat_flags, 0) << "frame " << i;
    if (got.version == 2) {
      // Byte-identical: the delivered frame encodes back to the bytes that were sent.
      ASSERT_EQ(
          EncodeFrame(got.sequence, got.system_id, got.component_id, got.message_id, got.payload),
          want.wire)
          << "frame " << i;
    }
  }
  EXPECT_EQ(delivered.size(), expected.size());
  EXPECT_EQ(stats.frames, expected.size());
  EXPECT_GE(stats.signed_or_unsupported, static_cast<uint64_t>(maker.intact_signed()));
  EXPECT_GT(maker.mutated(), kFrames / 5);
  EXPECT_GT(maker.intact_signed(), 0);
}

}  // namespace
}  // namespace stevi::client::mavlink
