// The round trip every MAVLink message must survive, shared by the message tests: packed to its
// full length, unpacked, and sent through a frame and the parser.
#pragma once

#include <gtest/gtest.h>

#include <cstddef>
#include <vector>

#include "client/mavlink/codec.h"
#include "client/mavlink/messages.h"

namespace stevi::client::mavlink::testing {

// Packs `m`, checks the payload is `max_length` bytes, unpacks it, and sends it through a frame
// (trimmed, checksummed with the CRC_EXTRA) and the parser.
template <class T>
void ExpectRoundTrip(const T& m, std::size_t max_length) {
  const std::vector<uint8_t> payload = Pack(m);
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

}  // namespace stevi::client::mavlink::testing
