// The Foxglove WebSocket protocol's JSON messages (ws-protocol docs/spec.md) and subprotocol
// names, internal to FoxgloveServer: the server's messages built (serverInfo, advertise,
// unadvertise, status), the client's parsed and checked (subscribe, unsubscribe, and the ops that
// need a capability this server does not offer). No connection or channel state here.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "client/station/foxglove_server.h"

namespace stevi::station::internal {

using Json = nlohmann::json;

// The subprotocols accepted, in the server's order (civetweb takes the first one in the client's
// order that is in this list). civetweb keeps the pointer: static storage.
inline const char* kSubprotocolNames[] = {"foxglove.websocket.v1", "foxglove.sdk.v1"};

// Whether a Sec-WebSocket-Protocol header (a comma-separated list; nullptr: no header) offers one
// of kSubprotocolNames.
bool OffersOurSubprotocol(const char* header);

// JSON text; invalid UTF-8 (from a topic or a client's text) is replaced instead of throwing.
std::string Dump(const Json& json);

// Client-supplied text for a status message: quoted, escaped, at most 64 bytes of it.
std::string Quote(std::string_view text);

std::string Base64(std::string_view bytes);

// ---- the server's messages

Json ServerInfo(const std::string& name, const std::string& session_id);

// A channel's entry in advertise (a protobuf schema, a FileDescriptorSet, goes base64).
Json ChannelAdvert(uint32_t id, const ChannelSpec& spec);

// advertise of `channels`, an array of ChannelAdvert entries.
Json Advertise(Json channels);

Json Unadvertise(uint32_t channel);

// level: 0 info, 1 warning, 2 error; id: none when empty.
Json Status(int level, std::string_view message, std::string_view id);

// ---- the client's messages

// One entry of a subscribe's "subscriptions" (id and channel) or of an unsubscribe's
// "subscriptionIds" (id only), or what is wrong with it.
struct SubscriptionItem {
  uint32_t id = 0;
  uint32_t channel = 0;
  std::string problem;  // non-empty: the entry is not valid
};

struct ClientMessage {
  enum class Op { kNone, kSubscribe, kUnsubscribe };
  Op op = Op::kNone;
  std::string warning;                  // kNone: the status warning that answers the message
  std::vector<SubscriptionItem> items;  // kSubscribe, kUnsubscribe: in the message's order
};

// A client's text message. All but a subscribe or an unsubscribe with its array is kNone with a
// warning: malformed JSON, not an object, no string "op", an unsupported or unknown op.
ClientMessage ParseClientMessage(std::string_view text);

}  // namespace stevi::station::internal
