// The Foxglove WebSocket protocol's framing, internal to FoxgloveServer: the binary Message Data
// op the server sends, the Close frames of RFC 6455 it sends and answers with, and the reassembly
// of a client's fragmented messages. No JSON here (foxglove_protocol.h) and no connection state.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

namespace stevi::station::internal {

// RFC 6455 7.4.1 status codes the server closes with.
inline constexpr uint16_t kCloseProtocolError = 1002;
inline constexpr uint16_t kClosePolicyViolation = 1008;
inline constexpr uint16_t kCloseMessageTooBig = 1009;

// A Message Data op (server to client, binary): 0x01 | u32 subscription id | u64 log time ns |
// payload, little-endian.
std::string MessageData(uint32_t subscription, uint64_t log_time_ns, std::string_view payload);

// A Close frame's payload: the status code (big-endian) and at most 120 bytes of the reason.
std::string ClosePayload(uint16_t code, const std::string& reason);

// The body of the Close frame answering a client's Close with `body` (RFC 6455 5.5.1, 7.4): the
// client's status code echoed; none for none; 1002 (protocol error) for a body too short to hold a
// code, or a code that no endpoint may send (1005, 1006 and 1015 are for reporting only, 0..999
// and 1016..2999 are not defined, and 5000 and up do not exist).
std::string CloseAnswer(std::string_view body);

// A client's message being reassembled from its frames (RFC 6455 5.4).
struct Reassembly {
  std::string fragments;  // the payloads so far
  int opcode = 0;         // the message's opcode (text or binary); 0: no message under way
};

// What one frame from a client amounts to.
struct Received {
  enum class Kind {
    kClose,               // a Close: `data` is the payload of the Close that answers it
    kControl,             // a Ping or a Pong: nothing to do
    kOrphanContinuation,  // a continuation frame without a message to continue
    kUnknownOpcode,       // `opcode` is none of RFC 6455's
    kTooBig,              // the message would be larger than the limit
    kPartial,             // a fragment of the message under way, kept
    kMessage,             // a whole message: `opcode` text or binary, `data` its payload
  };
  Kind kind = Kind::kPartial;
  int opcode = 0;
  std::string data;
};

// One frame from a client: `bits` its first byte (FIN 0x80, the opcode in the low four bits),
// `payload` unmasked. A text or binary frame starts a new message; `max_message_bytes` bounds a
// message after reassembly.
Received Reassemble(Reassembly& reassembly, int bits, std::string_view payload,
                    size_t max_message_bytes);

}  // namespace stevi::station::internal
