// FoxgloveServer's inside, internal to it: one WebSocket client's state (internal::Client) and
// FoxgloveServer::Impl, shared by the server's sources: foxglove_server.cc (start, stop, channels,
// publishing), foxglove_connection.cc (a WebSocket client from its connect to its close: the
// queue and sender thread, the frames and messages it sends) and foxglove_http.cc (HTTP
// requests, the access token, the WebSocket admission, the handlers).
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <unordered_map>
#include <utility>
#include <vector>

#include <civetweb.h>

#include "client/station/foxglove_channels.h"
#include "client/station/foxglove_framing.h"
#include "client/station/foxglove_protocol.h"
#include "client/station/foxglove_server.h"

namespace stevi::station {
namespace internal {

// A message in a client's send queue.
struct Outgoing {
  int opcode = MG_WEBSOCKET_OPCODE_TEXT;  // TEXT: a JSON control message, never dropped
  std::string data;
  bool lossy = false;
};

// One WebSocket connection. Its subscriptions are in Impl::channels_.
struct Client {
  const mg_connection* conn_id = nullptr;  // from the connect handler
  mg_connection* conn = nullptr;           // from the ready handler: for writing
  std::string remote;

  // Guarded by Impl::mutex_.
  bool ready = false;

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
  Reassembly incoming;

  // A LocalClient: no connection and no sender; the queue waits for TakeSent, and `written`
  // holds the frames written at once (guarded by queue_mutex).
  bool local = false;
  std::vector<FoxgloveServer::LocalClient::Frame> written;
};

// "IP:PORT" (IPv6: "[IP]:PORT") of a request's peer.
std::string RemoteAddress(const mg_request_info* info);

}  // namespace internal

struct FoxgloveServer::Impl {
  using Json = internal::Json;
  using Client = internal::Client;
  using Outgoing = internal::Outgoing;
  using Changes = internal::SubscriptionChanges;

  FoxgloveServerOptions options;
  mg_context* ctx = nullptr;
  int port = 0;
  std::string session_id;
  std::string wake_host;  // a numeric address that reaches the listening socket (Stop's pokes)

  mutable std::mutex mutex_;  // guards what follows
  std::unordered_map<const Client*, std::unique_ptr<Client>> clients_;
  internal::Channels channels_;
  std::map<std::string, HttpHandler, std::greater<>> handlers_;  // longest prefix first
  bool stopped_ = false;

  // Taken before mutex_ around every subscription change, so that listener calls are in order.
  std::mutex listener_mutex_;
  std::function<void(uint32_t, bool)> listener_;

  std::atomic<uint64_t> messages_sent{0};
  std::atomic<uint64_t> messages_dropped{0};
  std::atomic<uint64_t> bytes_sent{0};

  // ---- starting (foxglove_server.cc)

  // Starts civetweb on `ports` (civetweb's listening_ports); false and `error` set when it cannot.
  bool Listen(const std::string& ports, const std::string& where, std::string& error);
  void SetHandlers();

  // ---- queues (foxglove_connection.cc)

  // Queues `message` for `client`; drops binary messages when the queue is over its limits.
  void Enqueue(Client& client, Outgoing message);
  void EnqueueJson(Client& client, const Json& json);
  // Queues `json` for every client that is ready (mutex_ held).
  void EnqueueJsonToAll(const Json& json);
  // Ends the client's sending: the queue is dropped and, with a code, a close frame is sent.
  static void CloseLocked(Client& client, uint16_t code, std::string reason);
  static void Close(Client& client, uint16_t code, std::string reason);
  void SenderLoop(Client& client);
  // Writes one frame at once, beside the sender (local clients: kept for TakeSent).
  static void WriteNow(Client& client, int opcode, std::string_view payload);

  // ---- a client's messages (foxglove_connection.cc)

  void Warn(Client& client, std::string_view message);

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

  void HandleText(Client& client, std::string_view text);
  void Subscribe(Client& client, const std::vector<internal::SubscriptionItem>& items);
  void Unsubscribe(Client& client, const std::vector<internal::SubscriptionItem>& items);

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

  // ---- a WebSocket client's life (foxglove_connection.cc)

  int Connect(const mg_connection* conn);
  void Ready(mg_connection* conn);
  // Marks the client ready and queues serverInfo and every channel (mutex_ held).
  void Greet(Client& client);
  int Data(mg_connection* conn, int bits, char* bytes, size_t size);
  // One frame from the client (civetweb's data handler): 0 ends the connection.
  int Receive(Client& client, int bits, const char* bytes, size_t size);
  void Closed(const mg_connection* conn);
  // Stops the client's sender, ends its subscriptions and forgets it (it is destroyed).
  void Disconnect(Client& client);

  // ---- HTTP (foxglove_http.cc)

  // The WebSocket admission checks, answered in HTTP before the handshake. civetweb calls the
  // authorization handler for every request it matches (HTTP too: passed through).
  int Authorize(mg_connection* conn);
  int Http(mg_connection* conn);
  // Reads the request's body into `request`; the refusal when it is too large.
  std::optional<HttpResponse> ReadBody(mg_connection* conn, const mg_request_info* info,
                                       HttpRequest& request) const;
  // Without the access token a path under /api/ gets 401 (no token) or 403 (a wrong one).
  std::optional<HttpResponse> RefuseAccess(const HttpRequest& request) const;
  // The handler of the longest prefix of the path; its exceptions become 500.
  HttpResponse Route(const HttpRequest& request) const;
};

}  // namespace stevi::station
