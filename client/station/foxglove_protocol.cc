// The Foxglove WebSocket protocol's JSON messages (foxglove_protocol.h): built for the server,
// parsed and checked for the client.
#include "client/station/foxglove_protocol.h"

#include <algorithm>
#include <iterator>
#include <optional>
#include <string>
#include <string_view>
#include <utility>

namespace stevi::station::internal {
namespace {

// Client ops the protocol defines that need a capability we do not offer.
constexpr std::string_view kUnsupportedOps[] = {"advertise",
                                                "unadvertise",
                                                "getParameters",
                                                "setParameters",
                                                "subscribeParameterUpdates",
                                                "unsubscribeParameterUpdates",
                                                "subscribeConnectionGraph",
                                                "unsubscribeConnectionGraph",
                                                "fetchAsset",
                                                "callService"};

// A u32 from a JSON number, or nullopt.
std::optional<uint32_t> U32(const Json& json) {
  if (!json.is_number_integer()) return std::nullopt;
  if (json.is_number_unsigned()) {
    const uint64_t v = json.get<uint64_t>();
    if (v > UINT32_MAX) return std::nullopt;
    return uint32_t(v);
  }
  const int64_t v = json.get<int64_t>();
  if (v < 0 || v > int64_t(UINT32_MAX)) return std::nullopt;
  return uint32_t(v);
}

ClientMessage Warning(std::string warning) {
  ClientMessage message;
  message.warning = std::move(warning);
  return message;
}

// One entry of a subscribe's "subscriptions".
SubscriptionItem ParseSubscription(const Json& item) {
  SubscriptionItem parsed;
  const auto id_field = item.is_object() ? item.find("id") : item.end();
  const auto channel_field = item.is_object() ? item.find("channelId") : item.end();
  if (!item.is_object() || id_field == item.end() || channel_field == item.end()) {
    parsed.problem = "each subscription needs \"id\" and \"channelId\"";
    return parsed;
  }
  const std::optional<uint32_t> id = U32(*id_field);
  const std::optional<uint32_t> channel_id = U32(*channel_field);
  if (!id || !channel_id) {
    parsed.problem = "subscription \"id\" and \"channelId\" must be integers 0..2^32-1";
    return parsed;
  }
  parsed.id = *id;
  parsed.channel = *channel_id;
  return parsed;
}

// One entry of an unsubscribe's "subscriptionIds".
SubscriptionItem ParseUnsubscription(const Json& item) {
  SubscriptionItem parsed;
  const std::optional<uint32_t> id = U32(item);
  if (!id) {
    parsed.problem = "subscription ids must be integers 0..2^32-1";
  } else {
    parsed.id = *id;
  }
  return parsed;
}

// A subscribe or an unsubscribe (`op`, named `op_name`): its `key` must be an array, each entry of
// which parse_item reads.
ClientMessage ParseItems(const Json& message, ClientMessage::Op op, std::string_view op_name,
                         const std::string& key, SubscriptionItem (*parse_item)(const Json&)) {
  const auto list = message.find(key);
  if (list == message.end() || !list->is_array()) {
    return Warning(std::string(op_name) + ": \"" + key + "\" must be an array");
  }
  ClientMessage parsed;
  parsed.op = op;
  for (const Json& item : *list) parsed.items.push_back(parse_item(item));
  return parsed;
}

ClientMessage ParseSubscribe(const Json& message) {
  return ParseItems(message, ClientMessage::Op::kSubscribe, "subscribe", "subscriptions",
                    ParseSubscription);
}

ClientMessage ParseUnsubscribe(const Json& message) {
  return ParseItems(message, ClientMessage::Op::kUnsubscribe, "unsubscribe", "subscriptionIds",
                    ParseUnsubscription);
}

}  // namespace

bool OffersOurSubprotocol(const char* header) {
  if (header == nullptr) return false;
  std::string_view list(header);
  while (!list.empty()) {
    const size_t comma = list.find(',');
    std::string_view item = list.substr(0, comma);
    while (!item.empty() && (item.front() == ' ' || item.front() == '\t')) item.remove_prefix(1);
    while (!item.empty() && (item.back() == ' ' || item.back() == '\t')) item.remove_suffix(1);
    for (const char* name : kSubprotocolNames) {
      if (item == name) return true;
    }
    if (comma == std::string_view::npos) break;
    list.remove_prefix(comma + 1);
  }
  return false;
}

std::string Dump(const Json& json) {
  return json.dump(-1, ' ', false, Json::error_handler_t::replace);
}

std::string Quote(std::string_view text) {
  constexpr size_t kMax = 64;
  std::string cut(text.substr(0, kMax));
  std::string quoted = Dump(Json(cut));
  if (text.size() > kMax) quoted += "...";
  return quoted;
}

std::string Base64(std::string_view bytes) {
  static constexpr char kAlphabet[] =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const uint32_t v =
        (uint8_t(bytes[i]) << 16) | (uint8_t(bytes[i + 1]) << 8) | uint8_t(bytes[i + 2]);
    out += kAlphabet[v >> 18];
    out += kAlphabet[(v >> 12) & 63];
    out += kAlphabet[(v >> 6) & 63];
    out += kAlphabet[v & 63];
  }
  if (i + 1 == bytes.size()) {
    const uint32_t v = uint8_t(bytes[i]) << 16;
    out += kAlphabet[v >> 18];
    out += kAlphabet[(v >> 12) & 63];
    out += "==";
  } else if (i + 2 == bytes.size()) {
    const uint32_t v = (uint8_t(bytes[i]) << 16) | (uint8_t(bytes[i + 1]) << 8);
    out += kAlphabet[v >> 18];
    out += kAlphabet[(v >> 12) & 63];
    out += kAlphabet[(v >> 6) & 63];
    out += '=';
  }
  return out;
}

Json ServerInfo(const std::string& name, const std::string& session_id) {
  return Json{{"op", "serverInfo"},
              {"name", name},
              {"capabilities", Json::array()},
              {"metadata", Json::object()},
              {"sessionId", session_id}};
}

Json ChannelAdvert(uint32_t id, const ChannelSpec& spec) {
  const bool protobuf = spec.encoding == "protobuf";
  Json advert{{"id", id},
              {"topic", spec.topic},
              {"encoding", spec.encoding},
              {"schemaName", spec.schema_name},
              {"schema", protobuf ? Base64(spec.schema) : spec.schema}};
  if (protobuf) advert["schemaEncoding"] = "protobuf";
  return advert;
}

Json Advertise(Json channels) {
  return Json{{"op", "advertise"}, {"channels", std::move(channels)}};
}

Json Unadvertise(uint32_t channel) {
  return Json{{"op", "unadvertise"}, {"channelIds", Json::array({channel})}};
}

Json Status(int level, std::string_view message, std::string_view id) {
  Json json{{"op", "status"}, {"level", level}, {"message", message}};
  if (!id.empty()) json["id"] = id;
  return json;
}

ClientMessage ParseClientMessage(std::string_view text) {
  const Json message = Json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (message.is_discarded()) return Warning("malformed JSON message " + Quote(text));
  if (!message.is_object()) {
    return Warning("a message must be a JSON object, got " + Quote(Dump(message)));
  }
  const auto op = message.find("op");
  if (op == message.end() || !op->is_string()) return Warning("a message needs a string \"op\"");
  const std::string& name = op->get_ref<const std::string&>();
  if (name == "subscribe") return ParseSubscribe(message);
  if (name == "unsubscribe") return ParseUnsubscribe(message);
  if (std::find(std::begin(kUnsupportedOps), std::end(kUnsupportedOps), name) !=
      std::end(kUnsupportedOps)) {
    return Warning("unsupported op " + Quote(name) + ": this server offers no capabilities");
  }
  return Warning("unknown op " + Quote(name));
}

}  // namespace stevi::station::internal
