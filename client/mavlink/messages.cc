#include "client/mavlink/messages.h"

namespace stevi::client::mavlink::detail {

std::size_t MaxLength(uint32_t id) { return FindMessage(id)->max_length; }

Packer::Packer(uint32_t id) { bytes_.reserve(MaxLength(id)); }

void Packer::Put(uint64_t bits, std::size_t size) {
  for (std::size_t i = 0; i < size; ++i) {
    bytes_.push_back(static_cast<uint8_t>((bits >> (8 * i)) & 0xFFU));
  }
}

uint64_t Unpacker::Get(std::size_t size) {
  uint64_t bits = 0;
  for (std::size_t i = 0; i < size; ++i, ++at_) {
    if (at_ < payload_.size()) bits |= static_cast<uint64_t>(payload_[at_]) << (8 * i);
  }
  return bits;
}

}  // namespace stevi::client::mavlink::detail
