// The Foxglove WebSocket protocol's framing (foxglove_framing.h): Message Data, Close payloads,
// the reassembly of a client's fragmented messages.
#include "client/station/foxglove_framing.h"

#include <cstring>
#include <utility>

#include <civetweb.h>

namespace stevi::station::internal {
namespace {

constexpr uint8_t kMessageDataOpcode = 0x01;
constexpr size_t kMessageDataHeaderBytes = 13;

}  // namespace

std::string MessageData(uint32_t subscription, uint64_t log_time_ns, std::string_view payload) {
  std::string data;
  data.resize(kMessageDataHeaderBytes + payload.size());
  char* out = data.data();
  out[0] = char(kMessageDataOpcode);
  for (int i = 0; i < 4; ++i) out[1 + i] = char((subscription >> (8 * i)) & 0xff);
  for (int i = 0; i < 8; ++i) out[5 + i] = char((log_time_ns >> (8 * i)) & 0xff);
  if (!payload.empty()) {
    std::memcpy(out + kMessageDataHeaderBytes, payload.data(), payload.size());
  }
  return data;
}

std::string ClosePayload(uint16_t code, const std::string& reason) {
  std::string payload;
  payload += char(code >> 8);
  payload += char(code & 0xff);
  payload += reason.substr(0, 120);
  return payload;
}

std::string CloseAnswer(std::string_view body) {
  if (body.empty()) return "";
  if (body.size() >= 2) {
    const unsigned code = (unsigned(uint8_t(body[0])) << 8) | uint8_t(body[1]);
    const bool sendable = (code >= 1000 && code <= 1003) || (code >= 1007 && code <= 1014) ||
                          (code >= 3000 && code <= 4999);
    if (sendable) return std::string(body.substr(0, 2));
  }
  return std::string{char(kCloseProtocolError >> 8), char(kCloseProtocolError & 0xff)};
}

Received Reassemble(Reassembly& reassembly, int bits, std::string_view payload,
                    size_t max_message_bytes) {
  using Kind = Received::Kind;
  const int opcode = bits & 0x0f;
  const bool fin = (bits & 0x80) != 0;
  Received received;
  switch (opcode) {
    case MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE:
      received.kind = Kind::kClose;
      received.data = CloseAnswer(payload);
      return received;
    case MG_WEBSOCKET_OPCODE_PING:
    case MG_WEBSOCKET_OPCODE_PONG: received.kind = Kind::kControl; return received;
    case MG_WEBSOCKET_OPCODE_TEXT:
    case MG_WEBSOCKET_OPCODE_BINARY:
      reassembly.fragments.clear();
      reassembly.opcode = opcode;
      break;
    case MG_WEBSOCKET_OPCODE_CONTINUATION:
      if (reassembly.opcode == 0) {
        received.kind = Kind::kOrphanContinuation;
        return received;
      }
      break;
    default:
      received.kind = Kind::kUnknownOpcode;
      received.opcode = opcode;
      return received;
  }
  if (reassembly.fragments.size() + payload.size() > max_message_bytes) {
    received.kind = Kind::kTooBig;
    return received;
  }
  reassembly.fragments.append(payload);
  if (!fin) return received;  // kPartial
  received.kind = Kind::kMessage;
  received.opcode = reassembly.opcode;
  reassembly.opcode = 0;
  received.data = std::move(reassembly.fragments);
  reassembly.fragments.clear();
  return received;
}

}  // namespace stevi::station::internal
