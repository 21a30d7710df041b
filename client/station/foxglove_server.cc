#include "client/station/foxglove_server.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>
#include <strings.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <exception>
#include <mutex>
#include <optional>
#include <thread>
#include <unordered_map>

#include <civetweb.h>
#include <nlohmann/json.hpp>

#include "client/thread_name.h"

namespace stevi::station {
namespace {

using Json = nlohmann::json;

// The subprotocols accepted, in the server's order (civetweb takes the first one in the client's
// order that is in this list). civetweb keeps the pointer: static storage.
const char* kSubprotocolNames[] = {"foxglove.websocket.v1", "foxglove.sdk.v1"};
mg_websocket_subprotocols kSubprotocols = {2, kSubprotocolNames};

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

constexpr uint8_t kMessageDataOpcode = 0x01;
constexpr size_t kMessageDataHeaderBytes = 13;
constexpr uint16_t kCloseProtocolError = 1002;
constexpr uint16_t kClosePolicyViolation = 1008;
constexpr uint16_t kCloseMessageTooBig = 1009;

std::string Dump(const Json& json) {
  // Replace invalid UTF-8 (from a topic or a client's text) instead of throwing.
  return json.dump(-1, ' ', false, Json::error_handler_t::replace);
}

// Client-supplied text for a status message: quoted, escaped, at most 64 bytes of it.
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

// Compares in time independent of where the strings differ.
bool SameSecret(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  unsigned char diff = 0;
  for (size_t i = 0; i < a.size(); ++i) diff |= uint8_t(a[i]) ^ uint8_t(b[i]);
  return diff == 0;
}

bool IsWebSocketUpgrade(const mg_connection* conn) {
  const char* upgrade = mg_get_header(conn, "Upgrade");
  return upgrade != nullptr && strcasecmp(upgrade, "websocket") == 0;
}

// The token of an "Authorization: Bearer T" header's value, or nullopt.
std::optional<std::string> BearerToken(const char* auth) {
  if (auth == nullptr) return std::nullopt;
  std::string_view value(auth);
  constexpr std::string_view kBearer = "Bearer ";
  if (value.size() < kBearer.size() || strncasecmp(value.data(), kBearer.data(), 7) != 0) {
    return std::nullopt;
  }
  return std::string(value.substr(kBearer.size()));
}

// Whether the comma-separated Sec-WebSocket-Protocol header offers one of ours.
bool OffersOurSubprotocol(const mg_connection* conn) {
  const char* header = mg_get_header(conn, "Sec-WebSocket-Protocol");
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

int SendHttp(mg_connection* conn, const HttpResponse& response) {
  mg_response_header_start(conn, response.status);
  mg_response_header_add(conn, "Content-Type", response.content_type.c_str(), -1);
  mg_response_header_add(conn, "Content-Length", std::to_string(response.body.size()).c_str(), -1);
  mg_response_header_add(conn, "Cache-Control", "no-store", -1);
  for (const auto& [name, value] : response.headers) {
    // A handler's header with a line break would split the response: dropped.
    if (name.find_first_of("\r\n:") != std::string::npos ||
        value.find_first_of("\r\n") != std::string::npos) {
      continue;
    }
    mg_response_header_add(conn, name.c_str(), value.c_str(), -1);
  }
  mg_response_header_send(conn);
  const mg_request_info* info = mg_get_request_info(conn);
  if (!response.body.empty() && strcmp(info->request_method, "HEAD") != 0) {
    mg_write(conn, response.body.data(), response.body.size());
  }
  return response.status;
}

// A refusal of a WebSocket upgrade, written raw: civetweb's response-header functions refuse a
// connection it has marked as WebSocket (1.15). The connection closes after it.
int RefuseUpgrade(mg_connection* conn, const HttpResponse& response) {
  std::string text = "HTTP/1.1 " + std::to_string(response.status) + " " +
                     mg_get_response_code_text(conn, response.status) +
                     "\r\nContent-Type: " + response.content_type +
                     "\r\nContent-Length: " + std::to_string(response.body.size()) +
                     "\r\nConnection: close\r\n";
  for (const auto& [name, value] : response.headers) text += name + ": " + value + "\r\n";
  text += "\r\n" + response.body;
  mg_write(conn, text.data(), text.size());
  return response.status;
}

// The body of the Close frame answering a client's Close with `body` (RFC 6455 5.5.1, 7.4): the
// client's status code echoed; none for none; 1002 (protocol error) for a body too short to hold a
// code, or a code that no endpoint may send (1005, 1006 and 1015 are for reporting only, 0..999
// and 1016..2999 are not defined, and 5000 and up do not exist).
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

HttpResponse JsonError(int status, std::string_view code, std::string_view message) {
  HttpResponse response;
  response.status = status;
  response.body = Dump(Json{{"code", code}, {"message", message}});
  return response;
}

// HOST:PORT to civetweb's listening_ports form; "" and `error` set when malformed.
std::string ListeningPorts(const std::string& listen, std::string& error) {
  std::string host;
  std::string port;
  bool ipv6 = false;
  if (!listen.empty() && listen.front() == '[') {
    const size_t close = listen.find(']');
    if (close == std::string::npos || close + 1 >= listen.size() || listen[close + 1] != ':') {
      error = "expected [IPV6]:PORT";
      return "";
    }
    host = listen.substr(1, close - 1);
    port = listen.substr(close + 2);
    ipv6 = true;
  } else {
    const size_t colon = listen.rfind(':');
    if (colon == std::string::npos) {
      error = "expected HOST:PORT";
      return "";
    }
    host = listen.substr(0, colon);
    port = listen.substr(colon + 1);
  }
  if (port.empty() || port.size() > 5 ||
      !std::all_of(port.begin(), port.end(), [](char c) { return c >= '0' && c <= '9'; }) ||
      std::stoi(port) > 65535) {
    error = "the port must be 0..65535";
    return "";
  }
  if (host == "localhost") host = "127.0.0.1";
  unsigned char address[16];
  if (ipv6) {
    if (inet_pton(AF_INET6, host.c_str(), address) != 1) {
      error = "not an IPv6 address";
      return "";
    }
    if (mg_check_feature(MG_FEATURES_IPV6) == 0) {
      error = "this civetweb has no IPv6";
      return "";
    }
    return "[" + host + "]:" + std::to_string(std::stoi(port));
  }
  if (inet_pton(AF_INET, host.c_str(), address) != 1) {
    error = "the host must be an IPv4 address, [IPv6] or localhost";
    return "";
  }
  return host + ":" + std::to_string(std::stoi(port));
}

// Opens and at once closes a TCP connection to HOST:PORT (HOST "1.2.3.4" or "[::1]").
void PokeListener(const std::string& host, int port) {
  sockaddr_storage address{};
  socklen_t length = 0;
  if (!host.empty() && host.front() == '[') {
    auto* v6 = reinterpret_cast<sockaddr_in6*>(&address);
    v6->sin6_family = AF_INET6;
    v6->sin6_port = htons(uint16_t(port));
    if (inet_pton(AF_INET6, host.substr(1, host.size() - 2).c_str(), &v6->sin6_addr) != 1) return;
    length = sizeof(sockaddr_in6);
  } else {
    auto* v4 = reinterpret_cast<sockaddr_in*>(&address);
    v4->sin_family = AF_INET;
    v4->sin_port = htons(uint16_t(port));
    if (inet_pton(AF_INET, host.c_str(), &v4->sin_addr) != 1) return;
    length = sizeof(sockaddr_in);
  }
  const int fd = socket(address.ss_family, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return;
  connect(fd, reinterpret_cast<const sockaddr*>(&address), length);
  close(fd);
}

}  // namespace

struct FoxgloveServer::Impl {
  struct Outgoing {
    int opcode = MG_WEBSOCKET_OPCODE_TEXT;  // TEXT: a JSON control message, never dropped
    std::string data;
    bool lossy = false;
  };

  // One WebSocket connection.
  struct Client {
    const mg_connection* conn_id = nullptr;  // from the connect handler
    mg_connection* conn = nullptr;           // from the ready handler: for writing
    std::string remote;

    // Guarded by Impl::mutex_.
    bool ready = false;
    std::map<uint32_t, uint32_t> subscriptions;  // subscription id -> channel id

    // The send queue, guarded by queue_mutex.
    std::mutex queue_mutex;
    std::condition_variable queue_cv;
    std::deque<Outgoing> queue;
    size_t queued_bytes = 0;
    size_t queued_control = 0;
    bool closing = false;
    uint16_t close_code = 0;  // non-zero: the sender sends a close frame with it
    std::string close_reason;
    std::thread sender;

    // The message being reassembled from fragments: the worker thread only.
    std::string fragments;
    int fragments_opcode = 0;

    // A LocalClient: no connection and no sender; the queue waits for TakeSent, and `written`
    // holds the frames written at once (guarded by queue_mutex).
    bool local = false;
    std::vector<LocalClient::Frame> written;
  };

  struct Channel {
    ChannelSpec spec;
    Json advert;                                            // the advertise entry
    std::vector<std::pair<Client*, uint32_t>> subscribers;  // (client, its subscription id)
  };

  // A subscription change to tell the listener about.
  using Changes = std::vector<std::pair<uint32_t, bool>>;

  FoxgloveServerOptions options;
  mg_context* ctx = nullptr;
  int port = 0;
  std::string session_id;
  std::string wake_host;  // a numeric address that reaches the listening socket (Stop's pokes)

  mutable std::mutex mutex_;  // guards what follows
  std::unordered_map<const Client*, std::unique_ptr<Client>> clients_;
  std::map<uint32_t, Channel> channels_;
  uint32_t next_channel_ = 1;
  std::map<std::string, HttpHandler, std::greater<>> handlers_;  // longest prefix first
  bool stopped_ = false;

  // Taken before mutex_ around every subscription change, so that listener calls are in order.
  std::mutex listener_mutex_;
  std::function<void(uint32_t, bool)> listener_;

  std::atomic<uint64_t> messages_sent{0};
  std::atomic<uint64_t> messages_dropped{0};
  std::atomic<uint64_t> bytes_sent{0};

  // ---- queues

  // Queues `message` for `client`; drops binary messages when the queue is over its limits.
  void Enqueue(Client& client, Outgoing message) {
    std::lock_guard lock(client.queue_mutex);
    if (client.closing) return;
    const bool control = message.opcode == MG_WEBSOCKET_OPCODE_TEXT;
    client.queued_bytes += message.data.size();
    client.queue.push_back(std::move(message));
    if (control && ++client.queued_control > kMaxQueuedControlMessages) {
      CloseLocked(client, kClosePolicyViolation, "not reading");
      return;
    }
    while (client.queue.size() > options.queue_messages ||
           client.queued_bytes > options.queue_bytes) {
      auto victim = std::find_if(client.queue.begin(), client.queue.end(),
                                 [](const Outgoing& m) { return m.lossy; });
      if (victim == client.queue.end()) {
        victim = std::find_if(client.queue.begin(), client.queue.end(), [](const Outgoing& m) {
          return m.opcode != MG_WEBSOCKET_OPCODE_TEXT;
        });
      }
      if (victim == client.queue.end()) break;  // JSON only: kept
      client.queued_bytes -= victim->data.size();
      client.queue.erase(victim);
      messages_dropped.fetch_add(1, std::memory_order_relaxed);
    }
    client.queue_cv.notify_one();
  }

  void EnqueueJson(Client& client, const Json& json) {
    Enqueue(client, Outgoing{MG_WEBSOCKET_OPCODE_TEXT, Dump(json), false});
  }

  // Ends the client's sending: the queue is dropped and, with a code, a close frame is sent.
  static void CloseLocked(Client& client, uint16_t code, std::string reason) {
    if (client.closing) return;
    client.closing = true;
    client.close_code = code;
    client.close_reason = std::move(reason);
    client.queue.clear();
    client.queued_bytes = 0;
    client.queued_control = 0;
    client.queue_cv.notify_one();
  }
  static void Close(Client& client, uint16_t code, std::string reason) {
    std::lock_guard lock(client.queue_mutex);
    CloseLocked(client, code, std::move(reason));
  }

  void SenderLoop(Client& client) {
    for (;;) {
      Outgoing message;
      {
        std::unique_lock lock(client.queue_mutex);
        client.queue_cv.wait(lock, [&] { return client.closing || !client.queue.empty(); });
        if (client.closing) break;
        message = std::move(client.queue.front());
        client.queue.pop_front();
        client.queued_bytes -= message.data.size();
        if (message.opcode == MG_WEBSOCKET_OPCODE_TEXT) --client.queued_control;
      }
      // Blocks until the kernel takes the bytes (at most io_timeout_ms, less when stopping).
      const int written =
          mg_websocket_write(client.conn, message.opcode, message.data.data(), message.data.size());
      if (written < 0 || size_t(written) < message.data.size()) {  // the connection is broken
        Close(client, 0, "");
        return;
      }
      messages_sent.fetch_add(1, std::memory_order_relaxed);
      bytes_sent.fetch_add(message.data.size(), std::memory_order_relaxed);
    }
    uint16_t code = 0;
    std::string reason;
    {
      std::lock_guard lock(client.queue_mutex);
      code = client.close_code;
      reason = client.close_reason;
    }
    if (code != 0) {
      const std::string payload = ClosePayload(code, reason);
      mg_websocket_write(client.conn, MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE, payload.data(),
                         payload.size());
    }
  }

  // A Close frame's payload: the status code (big-endian) and at most 120 bytes of the reason.
  static std::string ClosePayload(uint16_t code, const std::string& reason) {
    std::string payload;
    payload += char(code >> 8);
    payload += char(code & 0xff);
    payload += reason.substr(0, 120);
    return payload;
  }

  // Writes one frame at once, beside the sender (local clients: kept for TakeSent).
  static void WriteNow(Client& client, int opcode, std::string_view payload) {
    if (client.local) {
      std::lock_guard lock(client.queue_mutex);
      client.written.push_back({opcode, std::string(payload)});
      return;
    }
    mg_websocket_write(client.conn, opcode, payload.data(), payload.size());
  }

  // ---- protocol messages

  Json ServerInfo() const {
    return Json{{"op", "serverInfo"},
                {"name", options.name},
                {"capabilities", Json::array()},
                {"metadata", Json::object()},
                {"sessionId", session_id}};
  }

  static Json Status(int level, std::string_view message, std::string_view id) {
    Json json{{"op", "status"}, {"level", level}, {"message", message}};
    if (!id.empty()) json["id"] = id;
    return json;
  }

  void Warn(Client& client, std::string_view message) {
    EnqueueJson(client, Status(1, message, ""));
  }

  // Runs `change` (which fills Changes) under both locks, then tells the listener.
  template <typename F>
  void ChangeSubscriptions(F&& change) {
    std::lock_guard listener_lock(listener_mutex_);
    Changes changes;
    std::function<void(uint32_t, bool)> listener;
    {
      std::lock_guard lock(mutex_);
      change(changes);
      listener = listener_;
    }
    if (listener) {
      for (const auto& [channel, subscribed] : changes) listener(channel, subscribed);
    }
  }

  // Removes one of `client`'s subscriptions (mutex_ held).
  void UnsubscribeLocked(Client& client, uint32_t subscription, Changes& changes) {
    auto it = client.subscriptions.find(subscription);
    if (it == client.subscriptions.end()) return;
    auto channel = channels_.find(it->second);
    if (channel != channels_.end()) {
      auto& subscribers = channel->second.subscribers;
      std::erase_if(subscribers,
                    [&](const auto& s) { return s.first == &client && s.second == subscription; });
      if (subscribers.empty()) changes.emplace_back(channel->first, false);
    }
    client.subscriptions.erase(it);
  }

  // A u32 from a JSON number, or nullopt.
  static std::optional<uint32_t> U32(const Json& json) {
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

  void HandleSubscribe(Client& client, const Json& message) {
    const auto list = message.find("subscriptions");
    if (list == message.end() || !list->is_array()) {
      Warn(client, "subscribe: \"subscriptions\" must be an array");
      return;
    }
    std::vector<std::string> problems;
    ChangeSubscriptions([&](Changes& changes) {
      for (const Json& item : *list) {
        const auto id_field = item.is_object() ? item.find("id") : item.end();
        const auto channel_field = item.is_object() ? item.find("channelId") : item.end();
        if (!item.is_object() || id_field == item.end() || channel_field == item.end()) {
          problems.push_back("each subscription needs \"id\" and \"channelId\"");
          continue;
        }
        const std::optional<uint32_t> id = U32(*id_field);
        const std::optional<uint32_t> channel_id = U32(*channel_field);
        if (!id || !channel_id) {
          problems.push_back("subscription \"id\" and \"channelId\" must be integers 0..2^32-1");
          continue;
        }
        if (client.subscriptions.contains(*id)) {
          problems.push_back("subscription id " + std::to_string(*id) + " is already in use");
          continue;
        }
        auto channel = channels_.find(*channel_id);
        if (channel == channels_.end()) {
          problems.push_back("unknown channel " + std::to_string(*channel_id));
          continue;
        }
        auto& subscribers = channel->second.subscribers;
        if (std::any_of(subscribers.begin(), subscribers.end(),
                        [&](const auto& s) { return s.first == &client; })) {
          problems.push_back("already subscribed to channel " + std::to_string(*channel_id));
          continue;
        }
        if (subscribers.empty()) changes.emplace_back(*channel_id, true);
        subscribers.emplace_back(&client, *id);
        client.subscriptions[*id] = *channel_id;
      }
    });
    for (const std::string& problem : problems) Warn(client, "subscribe: " + problem);
  }

  void HandleUnsubscribe(Client& client, const Json& message) {
    const auto list = message.find("subscriptionIds");
    if (list == message.end() || !list->is_array()) {
      Warn(client, "unsubscribe: \"subscriptionIds\" must be an array");
      return;
    }
    std::vector<std::string> problems;
    ChangeSubscriptions([&](Changes& changes) {
      for (const Json& item : *list) {
        const std::optional<uint32_t> id = U32(item);
        if (!id) {
          problems.push_back("subscription ids must be integers 0..2^32-1");
        } else if (!client.subscriptions.contains(*id)) {
          problems.push_back("unknown subscription id " + std::to_string(*id));
        } else {
          UnsubscribeLocked(client, *id, changes);
        }
      }
    });
    for (const std::string& problem : problems) Warn(client, "unsubscribe: " + problem);
  }

  void HandleText(Client& client, std::string_view text) {
    Json message = Json::parse(text, nullptr, /*allow_exceptions=*/false);
    if (message.is_discarded()) {
      Warn(client, "malformed JSON message " + Quote(text));
      return;
    }
    if (!message.is_object()) {
      Warn(client, "a message must be a JSON object, got " + Quote(Dump(message)));
      return;
    }
    const auto op = message.find("op");
    if (op == message.end() || !op->is_string()) {
      Warn(client, "a message needs a string \"op\"");
      return;
    }
    const std::string& name = op->get_ref<const std::string&>();
    if (name == "subscribe") {
      HandleSubscribe(client, message);
    } else if (name == "unsubscribe") {
      HandleUnsubscribe(client, message);
    } else if (std::find(std::begin(kUnsupportedOps), std::end(kUnsupportedOps), name) !=
               std::end(kUnsupportedOps)) {
      Warn(client, "unsupported op " + Quote(name) + ": this server offers no capabilities");
    } else {
      Warn(client, "unknown op " + Quote(name));
    }
  }

  // ---- civetweb callbacks (C linkage through these static members)

  static int OnAuthorize(mg_connection* conn, void* data) {
    return static_cast<Impl*>(data)->Authorize(conn);
  }
  static int OnConnect(const mg_connection* conn, void* data) {
    return static_cast<Impl*>(data)->Connect(conn);
  }
  static void OnReady(mg_connection* conn, void* data) { static_cast<Impl*>(data)->Ready(conn); }
  static int OnData(mg_connection* conn, int bits, char* bytes, size_t size, void* data) {
    return static_cast<Impl*>(data)->Data(conn, bits, bytes, size);
  }
  static void OnClose(const mg_connection* conn, void* data) {
    static_cast<Impl*>(data)->Closed(conn);
  }
  static int OnHttp(mg_connection* conn, void* data) {
    return static_cast<Impl*>(data)->Http(conn);
  }
  static int OnLog(const mg_connection*, const char*) { return 1; }  // civetweb stays quiet

  // The WebSocket admission checks, answered in HTTP before the handshake. civetweb calls the
  // authorization handler for every request it matches (HTTP too: passed through).
  int Authorize(mg_connection* conn) {
    if (!IsWebSocketUpgrade(conn)) return 1;
    if (!options.access_token.empty()) {
      std::optional<std::string> token = BearerToken(mg_get_header(conn, "Authorization"));
      if (!token) {
        const char* query = mg_get_request_info(conn)->query_string;
        if (query != nullptr) {
          std::string value(1024, '\0');
          const int n = mg_get_var(query, strlen(query), "token", value.data(), value.size());
          if (n >= 0) token = value.substr(0, size_t(n));
          if (n == -2) token = std::string();  // too long to be ours
        }
      }
      if (!token) {
        RefuseUpgrade(conn, JsonError(401, "UNAUTHENTICATED",
                                      "this station needs its access token (?token=T)"));
        return 0;
      }
      if (!SameSecret(*token, options.access_token)) {
        RefuseUpgrade(conn, JsonError(403, "PERMISSION_DENIED", "wrong access token"));
        return 0;
      }
    }
    if (!OffersOurSubprotocol(conn)) {
      RefuseUpgrade(conn, JsonError(400, "INVALID_ARGUMENT",
                                    "Sec-WebSocket-Protocol must offer foxglove.websocket.v1 or "
                                    "foxglove.sdk.v1"));
      return 0;
    }
    {
      std::lock_guard lock(mutex_);
      if (clients_.size() >= options.max_clients) {
        RefuseUpgrade(conn, JsonError(503, "UNAVAILABLE",
                                      "too many WebSocket clients (" +
                                          std::to_string(options.max_clients) + ")"));
        return 0;
      }
    }
    return 1;
  }

  int Connect(const mg_connection* conn) {
    // Checked again under the lock: two clients may have passed Authorize together. This one is
    // then closed without an HTTP answer.
    if (!OffersOurSubprotocol(conn)) return 1;
    std::lock_guard lock(mutex_);
    if (stopped_ || clients_.size() >= options.max_clients) return 1;
    auto client = std::make_unique<Client>();
    client->conn_id = conn;
    const mg_request_info* info = mg_get_request_info(conn);
    const std::string address(info->remote_addr);
    client->remote = (address.find(':') != std::string::npos ? "[" + address + "]" : address) +
                     ":" + std::to_string(info->remote_port);
    mg_set_user_connection_data(conn, client.get());
    const Client* key = client.get();
    clients_.emplace(key, std::move(client));
    return 0;
  }

  void Ready(mg_connection* conn) {
    auto* client = static_cast<Client*>(mg_get_user_connection_data(conn));
    if (client == nullptr) return;
    client->conn = conn;
    client->sender = std::thread([this, client] {
      client::NameThisThread("stevi-ws-send");
      SenderLoop(*client);
    });
    std::lock_guard lock(mutex_);
    Greet(*client);
  }

  // Marks the client ready and queues serverInfo and every channel (mutex_ held).
  void Greet(Client& client) {
    client.ready = true;
    EnqueueJson(client, ServerInfo());
    if (!channels_.empty()) {
      Json advertise{{"op", "advertise"}, {"channels", Json::array()}};
      for (const auto& [id, channel] : channels_) advertise["channels"].push_back(channel.advert);
      EnqueueJson(client, advertise);
    }
  }

  int Data(mg_connection* conn, int bits, char* bytes, size_t size) {
    auto* client = static_cast<Client*>(mg_get_user_connection_data(conn));
    if (client == nullptr) return 0;
    return Receive(*client, bits, bytes, size);
  }

  // One frame from the client (civetweb's data handler): 0 ends the connection.
  int Receive(Client& client, int bits, const char* bytes, size_t size) {
    {
      std::lock_guard lock(client.queue_mutex);
      if (client.closing) return 0;
    }
    const int opcode = bits & 0x0f;
    const bool fin = (bits & 0x80) != 0;
    switch (opcode) {
      case MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE: {
        // The closing handshake (RFC 6455 5.5.1): answer with a Close frame (CloseAnswer), then
        // let civetweb close the connection. The sender stops first; a write in flight finishes
        // before ours (civetweb locks the connection for each frame).
        Close(client, 0, "");
        WriteNow(client, MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE,
                 CloseAnswer(std::string_view(bytes, size)));
        return 0;
      }
      case MG_WEBSOCKET_OPCODE_PING:
      case MG_WEBSOCKET_OPCODE_PONG: return 1;
      case MG_WEBSOCKET_OPCODE_TEXT:
      case MG_WEBSOCKET_OPCODE_BINARY:
        client.fragments.clear();
        client.fragments_opcode = opcode;
        break;
      case MG_WEBSOCKET_OPCODE_CONTINUATION:
        if (client.fragments_opcode == 0) {
          Warn(client, "a continuation frame without a message to continue");
          return 1;
        }
        break;
      default: Warn(client, "unknown WebSocket opcode " + std::to_string(opcode)); return 1;
    }
    if (client.fragments.size() + size > options.max_incoming_message_bytes) {
      Close(client, kCloseMessageTooBig,
            "message larger than " + std::to_string(options.max_incoming_message_bytes) + " bytes");
      return 0;
    }
    client.fragments.append(bytes, size);
    if (!fin) return 1;
    const int message_opcode = client.fragments_opcode;
    client.fragments_opcode = 0;
    std::string message = std::move(client.fragments);
    client.fragments.clear();
    if (message_opcode == MG_WEBSOCKET_OPCODE_BINARY) {
      Warn(client, "binary client messages are not accepted: this server offers no clientPublish");
    } else {
      HandleText(client, message);
    }
    return 1;
  }

  void Closed(const mg_connection* conn) {
    auto* client = static_cast<Client*>(mg_get_user_connection_data(conn));
    if (client == nullptr) return;
    Disconnect(*client);
    mg_set_user_connection_data(conn, nullptr);
  }

  // Stops the client's sender, ends its subscriptions and forgets it (it is destroyed).
  void Disconnect(Client& client) {
    Close(client, 0, "");
    if (client.sender.joinable()) client.sender.join();
    std::unique_ptr<Client> owned;
    ChangeSubscriptions([&](Changes& changes) {
      std::vector<uint32_t> ids;
      for (const auto& [id, channel] : client.subscriptions) ids.push_back(id);
      for (uint32_t id : ids) UnsubscribeLocked(client, id, changes);
      auto it = clients_.find(&client);
      if (it != clients_.end()) {
        owned = std::move(it->second);
        clients_.erase(it);
      }
    });
  }

  int Http(mg_connection* conn) {
    const mg_request_info* info = mg_get_request_info(conn);
    HttpRequest request;
    request.method = info->request_method != nullptr ? info->request_method : "";
    request.path = info->local_uri != nullptr ? info->local_uri : "";
    request.query = info->query_string != nullptr ? info->query_string : "";
    const std::string address(info->remote_addr);
    request.remote = (address.find(':') != std::string::npos ? "[" + address + "]" : address) +
                     ":" + std::to_string(info->remote_port);
    for (int i = 0; i < info->num_headers; ++i) {
      std::string name(info->http_headers[i].name);
      std::transform(name.begin(), name.end(), name.begin(),
                     [](unsigned char c) { return char(std::tolower(c)); });
      const std::string value(info->http_headers[i].value);
      auto [it, inserted] = request.headers.emplace(name, value);
      if (!inserted) it->second += ", " + value;
    }

    if (std::optional<HttpResponse> refusal = RefuseAccess(request)) {
      return SendHttp(conn, *refusal);
    }

    // The body: refused unread when its declared length is too large; otherwise read up to one
    // byte past the limit (a chunked body declares nothing).
    const auto transfer = request.headers.find("transfer-encoding");
    const bool chunked = transfer != request.headers.end() && transfer->second != "identity";
    const HttpResponse too_large = JsonError(
        413, "RESOURCE_EXHAUSTED",
        "request body larger than " + std::to_string(options.max_request_body_bytes) + " bytes");
    if (info->content_length > 0 &&
        uint64_t(info->content_length) > options.max_request_body_bytes) {
      mg_disable_connection_keep_alive(conn);
      return SendHttp(conn, too_large);
    }
    if (info->content_length > 0 || chunked) {
      char buffer[16384];
      for (;;) {
        const int n = mg_read(conn, buffer, sizeof buffer);
        if (n <= 0) break;
        request.body.append(buffer, size_t(n));
        if (request.body.size() > options.max_request_body_bytes) {
          mg_disable_connection_keep_alive(conn);
          return SendHttp(conn, too_large);
        }
      }
    }

    return SendHttp(conn, Route(request));
  }

  // Without the access token a path under /api/ gets 401 (no token) or 403 (a wrong one).
  std::optional<HttpResponse> RefuseAccess(const HttpRequest& request) const {
    if (options.access_token.empty() || !request.path.starts_with("/api/")) return std::nullopt;
    const auto auth = request.headers.find("authorization");
    std::optional<std::string> token;
    if (auth != request.headers.end()) token = BearerToken(auth->second.c_str());
    if (!token) {
      HttpResponse response = JsonError(401, "UNAUTHENTICATED",
                                        "this station needs its access token "
                                        "(Authorization: Bearer T)");
      response.headers.emplace_back("WWW-Authenticate", "Bearer");
      return response;
    }
    if (!SameSecret(*token, options.access_token)) {
      return JsonError(403, "PERMISSION_DENIED", "wrong access token");
    }
    return std::nullopt;
  }

  // The handler of the longest prefix of the path; its exceptions become 500.
  HttpResponse Route(const HttpRequest& request) const {
    HttpHandler handler;
    {
      std::lock_guard lock(mutex_);
      // Keys in descending order: a longer prefix comes before its own prefixes.
      for (const auto& [prefix, candidate] : handlers_) {
        if (request.path.starts_with(prefix)) {
          handler = candidate;
          break;
        }
      }
    }
    if (!handler) return JsonError(404, "NOT_FOUND", "nothing at " + Quote(request.path));
    try {
      return handler(request);
    } catch (const std::exception& e) {
      return JsonError(500, "INTERNAL", e.what());
    } catch (...) {
      return JsonError(500, "INTERNAL", "unknown exception");
    }
  }
};

FoxgloveServer::FoxgloveServer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

FoxgloveServer::~FoxgloveServer() { Stop(); }

std::unique_ptr<FoxgloveServer> FoxgloveServer::Start(FoxgloveServerOptions options,
                                                      std::string& error) {
  const std::string where = "station listen address \"" + options.listen + "\": ";
  std::string problem;
  const std::string ports = ListeningPorts(options.listen, problem);
  if (ports.empty()) {
    error = where + problem;
    return nullptr;
  }
  if (options.max_clients == 0 || options.queue_messages == 0 || options.queue_bytes == 0 ||
      options.io_timeout_ms <= 0) {
    error = "max_clients, queue_messages, queue_bytes and io_timeout_ms must be positive";
    return nullptr;
  }
  if (mg_check_feature(MG_FEATURES_WEBSOCKET) == 0) {
    error = "this civetweb was built without WebSocket support";
    return nullptr;
  }
  static std::once_flag library_once;
  std::call_once(library_once, [] { mg_init_library(0); });

  auto impl = std::make_unique<Impl>();
  impl->options = std::move(options);
  impl->session_id = std::to_string(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                        std::chrono::system_clock::now().time_since_epoch())
                                        .count());

  // Each open WebSocket holds a worker thread; 8 more serve HTTP requests and refusals.
  const std::string threads = std::to_string(impl->options.max_clients + 8);
  const std::string timeout = std::to_string(impl->options.io_timeout_ms);
  const char* config[] = {"listening_ports",
                          ports.c_str(),
                          "num_threads",
                          threads.c_str(),
                          "request_timeout_ms",
                          timeout.c_str(),
                          "websocket_timeout_ms",
                          timeout.c_str(),
                          "enable_websocket_ping_pong",
                          "yes",
                          "enable_keep_alive",
                          "no",
                          nullptr};
  mg_callbacks callbacks{};
  callbacks.log_message = &Impl::OnLog;
  mg_init_data init{};
  init.callbacks = &callbacks;
  init.user_data = impl.get();
  init.configuration_options = config;
  char text[256] = "";
  unsigned code = 0;
  mg_error_data start_error{&code, text, sizeof text};
  impl->ctx = mg_start2(&init, &start_error);
  if (impl->ctx == nullptr) {
    error = where + (text[0] != '\0' ? text : "cannot listen");
    return nullptr;
  }
  mg_server_port server_ports[4] = {};
  const int n = mg_get_server_ports(impl->ctx, 4, server_ports);
  impl->port = n > 0 ? server_ports[0].port : 0;
  impl->wake_host = ports.substr(0, ports.rfind(':'));
  if (impl->wake_host == "0.0.0.0") impl->wake_host = "127.0.0.1";
  if (impl->wake_host == "[::]") impl->wake_host = "[::1]";

  mg_set_auth_handler(impl->ctx, "/", &Impl::OnAuthorize, impl.get());
  mg_set_websocket_handler_with_subprotocols(impl->ctx, "/", &kSubprotocols, &Impl::OnConnect,
                                             &Impl::OnReady, &Impl::OnData, &Impl::OnClose,
                                             impl.get());
  mg_set_request_handler(impl->ctx, "/", &Impl::OnHttp, impl.get());
  return std::unique_ptr<FoxgloveServer>(new FoxgloveServer(std::move(impl)));
}

std::unique_ptr<FoxgloveServer> FoxgloveServer::StartUnbound(FoxgloveServerOptions options) {
  auto impl = std::make_unique<Impl>();
  impl->options = std::move(options);
  impl->session_id = "unbound";
  return std::unique_ptr<FoxgloveServer>(new FoxgloveServer(std::move(impl)));
}

int FoxgloveServer::port() const { return impl_->port; }

uint32_t FoxgloveServer::AddChannel(ChannelSpec spec) {
  std::lock_guard lock(impl_->mutex_);
  const uint32_t id = impl_->next_channel_++;
  Impl::Channel& channel = impl_->channels_[id];
  const bool protobuf = spec.encoding == "protobuf";
  channel.advert = Json{{"id", id},
                        {"topic", spec.topic},
                        {"encoding", spec.encoding},
                        {"schemaName", spec.schema_name},
                        {"schema", protobuf ? Base64(spec.schema) : spec.schema}};
  if (protobuf) channel.advert["schemaEncoding"] = "protobuf";
  channel.spec = std::move(spec);
  const Json advertise{{"op", "advertise"}, {"channels", Json::array({channel.advert})}};
  for (auto& [conn, client] : impl_->clients_) {
    if (client->ready) impl_->EnqueueJson(*client, advertise);
  }
  return id;
}

void FoxgloveServer::RemoveChannel(uint32_t channel) {
  impl_->ChangeSubscriptions([&](Impl::Changes& changes) {
    auto it = impl_->channels_.find(channel);
    if (it == impl_->channels_.end()) return;
    for (const auto& [client, subscription] : it->second.subscribers) {
      client->subscriptions.erase(subscription);
    }
    if (!it->second.subscribers.empty()) changes.emplace_back(channel, false);
    impl_->channels_.erase(it);
    const Json unadvertise{{"op", "unadvertise"}, {"channelIds", Json::array({channel})}};
    for (auto& [conn, client] : impl_->clients_) {
      if (client->ready) impl_->EnqueueJson(*client, unadvertise);
    }
  });
}

bool FoxgloveServer::HasSubscribers(uint32_t channel) const {
  std::lock_guard lock(impl_->mutex_);
  auto it = impl_->channels_.find(channel);
  return it != impl_->channels_.end() && !it->second.subscribers.empty();
}

void FoxgloveServer::SetSubscriptionListener(std::function<void(uint32_t, bool)> listener) {
  std::lock_guard listener_lock(impl_->listener_mutex_);
  std::lock_guard lock(impl_->mutex_);
  impl_->listener_ = std::move(listener);
}

void FoxgloveServer::Publish(uint32_t channel, uint64_t log_time_ns, std::string_view payload) {
  std::lock_guard lock(impl_->mutex_);
  auto it = impl_->channels_.find(channel);
  if (it == impl_->channels_.end()) return;
  for (const auto& [client, subscription] : it->second.subscribers) {
    Impl::Outgoing message;
    message.opcode = MG_WEBSOCKET_OPCODE_BINARY;
    message.lossy = it->second.spec.lossy;
    message.data.resize(kMessageDataHeaderBytes + payload.size());
    char* out = message.data.data();
    out[0] = char(kMessageDataOpcode);
    for (int i = 0; i < 4; ++i) out[1 + i] = char((subscription >> (8 * i)) & 0xff);
    for (int i = 0; i < 8; ++i) out[5 + i] = char((log_time_ns >> (8 * i)) & 0xff);
    if (!payload.empty()) {
      std::memcpy(out + kMessageDataHeaderBytes, payload.data(), payload.size());
    }
    impl_->Enqueue(*client, std::move(message));
  }
}

void FoxgloveServer::SendStatus(int level, std::string message, std::string id) {
  std::lock_guard lock(impl_->mutex_);
  const Json status = Impl::Status(level, message, id);
  for (auto& [conn, client] : impl_->clients_) {
    if (client->ready) impl_->EnqueueJson(*client, status);
  }
}

HttpResponse FoxgloveServer::HandleHttp(const HttpRequest& request) const {
  if (std::optional<HttpResponse> refusal = impl_->RefuseAccess(request)) return *refusal;
  return impl_->Route(request);
}

struct FoxgloveServer::LocalClient::State {
  Impl* server = nullptr;
  Impl::Client* client = nullptr;  // owned by the server's clients_
};

FoxgloveServer::LocalClient::LocalClient(std::unique_ptr<State> state) : state_(std::move(state)) {}

FoxgloveServer::LocalClient::~LocalClient() { state_->server->Disconnect(*state_->client); }

bool FoxgloveServer::LocalClient::Receive(uint8_t bits, std::string_view payload) {
  return state_->server->Receive(*state_->client, bits, payload.data(), payload.size()) != 0;
}

std::vector<FoxgloveServer::LocalClient::Frame> FoxgloveServer::LocalClient::TakeSent() {
  Impl::Client& client = *state_->client;
  std::lock_guard lock(client.queue_mutex);
  std::vector<Frame> sent;
  for (Impl::Outgoing& message : client.queue) {
    sent.push_back({message.opcode, std::move(message.data)});
  }
  client.queue.clear();
  client.queued_bytes = 0;
  client.queued_control = 0;
  if (client.closing && client.close_code != 0) {  // what the sender sends as it ends
    sent.push_back({MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE,
                    Impl::ClosePayload(client.close_code, client.close_reason)});
    client.close_code = 0;
  }
  for (Frame& frame : client.written) sent.push_back(std::move(frame));
  client.written.clear();
  return sent;
}

std::unique_ptr<FoxgloveServer::LocalClient> FoxgloveServer::ConnectLocal() {
  auto client = std::make_unique<Impl::Client>();
  client->local = true;
  client->remote = "local";
  auto state = std::make_unique<LocalClient::State>();
  state->server = impl_.get();
  state->client = client.get();
  std::lock_guard lock(impl_->mutex_);
  impl_->Greet(*client);
  const Impl::Client* key = client.get();
  impl_->clients_.emplace(key, std::move(client));
  return std::unique_ptr<LocalClient>(new LocalClient(std::move(state)));
}

void FoxgloveServer::AddHttpHandler(std::string path_prefix, HttpHandler handler) {
  std::lock_guard lock(impl_->mutex_);
  impl_->handlers_[std::move(path_prefix)] = std::move(handler);
}

FoxgloveServer::Stats FoxgloveServer::stats() const {
  Stats stats;
  {
    std::lock_guard lock(impl_->mutex_);
    stats.clients = impl_->clients_.size();
  }
  stats.messages_sent = impl_->messages_sent.load();
  stats.messages_dropped = impl_->messages_dropped.load();
  stats.bytes_sent = impl_->bytes_sent.load();
  return stats;
}

void FoxgloveServer::Stop() {
  mg_context* ctx = nullptr;
  {
    std::lock_guard lock(impl_->mutex_);
    impl_->stopped_ = true;
    std::swap(ctx, impl_->ctx);
  }
  if (ctx == nullptr) return;
  // mg_stop joins civetweb's threads; each open WebSocket's close handler joins its sender first.
  // civetweb's master thread sees the stop flag only when its poll of the listening socket
  // returns, after up to 2 s: connections to it make that at once.
  std::mutex mutex;
  std::condition_variable cv;
  bool stopped = false;
  std::thread waker([&] {
    client::NameThisThread("stevi-ws-waker");
    std::unique_lock lock(mutex);
    while (!stopped) {
      lock.unlock();
      PokeListener(impl_->wake_host, impl_->port);
      lock.lock();
      cv.wait_for(lock, std::chrono::milliseconds(20), [&] { return stopped; });
    }
  });
  mg_stop(ctx);
  {
    std::lock_guard lock(mutex);
    stopped = true;
  }
  cv.notify_all();
  waker.join();
}

}  // namespace stevi::station
