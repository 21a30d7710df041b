// The station's web server: HTTP handlers by path prefix and, on the same port and path "/", the
// Foxglove WebSocket protocol (https://github.com/foxglove/ws-protocol, docs/spec.md), which
// Foxglove, Lichtblick and the station's own web page speak. Built on civetweb's C API.
//
// The protocol as served:
// - Subprotocols "foxglove.websocket.v1" and "foxglove.sdk.v1" (the same protocol under its new
//   name); the first one the client offers is echoed. A client offering neither gets HTTP 400.
// - On connect: serverInfo (capabilities [], a sessionId), then one advertise with every channel.
//   AddChannel advertises to every client, RemoveChannel unadvertises (and ends its
//   subscriptions).
// - Client ops: subscribe and unsubscribe, with client-chosen subscription ids. Anything else
//   (malformed JSON, unknown or unsupported ops, wrong types, unknown channels or ids, binary
//   frames: we offer no clientPublish) gets a status warning naming the problem; the connection
//   stays. A client message larger than max_incoming_message_bytes closes the connection (1009).
// - A client's Close is answered with a Close echoing its status code; with 1002 (protocol error)
//   when the code is missing a byte or is one no endpoint may send (RFC 6455 7.4).
// - Server messages: binary Message Data frames, 0x01 | u32 subscription id | u64 log time ns |
//   payload (little-endian), to subscribers only, and status messages.
//
// Threads: civetweb runs each connection (HTTP request or open WebSocket) on one of its worker
// threads; each WebSocket client also has one sender thread that drains that client's bounded
// queue (a slow client stalls only its own sender). Every public method is thread-safe.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <google/protobuf/descriptor.h>

namespace stevi::station {

// One HTTP request, as a handler sees it.
struct HttpRequest {
  std::string method;  // "GET", "POST", ...
  std::string path;    // URL-decoded, without the query ("/api/rigs")
  std::string query;   // the raw text after '?', or ""
  std::string body;    // at most FoxgloveServerOptions::max_request_body_bytes
  std::map<std::string, std::string> headers;  // names in lower case
  std::string remote;                          // "IP:PORT" of the peer
};

struct HttpResponse {
  int status = 200;
  std::string content_type = "application/json";
  std::string body{};
  std::vector<std::pair<std::string, std::string>> headers{};  // extra headers
};

// Called on a civetweb worker thread, possibly concurrently with itself. Exceptions become 500.
using HttpHandler = std::function<HttpResponse(const HttpRequest&)>;

struct FoxgloveServerOptions {
  // HOST:PORT, HOST an IPv4 address, [IPv6] or "localhost"; 0.0.0.0 listens on every interface.
  // Port 0: any free port (port() tells which).
  std::string listen = "127.0.0.1:8080";
  std::string name = "stevi station";  // serverInfo.name
  // Open WebSocket connections; more get HTTP 503.
  size_t max_clients = 16;
  // A larger client message (after reassembly of fragments) closes the connection with 1009.
  size_t max_incoming_message_bytes = 64 << 10;
  // A larger HTTP request body gets 413.
  size_t max_request_body_bytes = 1 << 20;
  // Each client's send queue, in messages and bytes. When it is full the oldest message of a
  // lossy channel goes first, else the oldest binary message; JSON messages are never dropped
  // (more than kMaxQueuedControlMessages of them close the connection: the client is not reading).
  size_t queue_messages = 64;
  size_t queue_bytes = 16 << 20;
  // Non-empty: a WebSocket needs ?token=T in its URL or "Authorization: Bearer T" (none: 401,
  // wrong: 403), and HTTP paths under /api/ need "Authorization: Bearer T". Other paths stay open.
  std::string access_token;
  // A write to a client that takes longer fails and closes that client; also civetweb's read
  // timeout, after which an idle WebSocket is pinged (browsers answer).
  int io_timeout_ms = 10000;
};

struct ChannelSpec {
  std::string topic;  // "/rig1/tracks"; unique among the channels
  std::string encoding = "protobuf";
  std::string schema_name;  // fully qualified, no leading dot: "stevi.v1.TrackFrame"
  // protobuf: a serialized FileDescriptorSet (to_foxglove::FileDescriptorSetFor in
  // proto/foxglove/convert.h), sent base64. Other encodings: the schema text as is.
  std::string schema;
  bool lossy = false;  // dropped first when a client's queue is full (images)
};

class FoxgloveServer {
 public:
  // JSON messages queued for one client beyond which that client is closed (1008).
  static constexpr size_t kMaxQueuedControlMessages = 1024;

  // Listens and serves. nullptr and `error` set (naming the address) when the options are
  // invalid or the address cannot be bound.
  static std::unique_ptr<FoxgloveServer> Start(FoxgloveServerOptions options, std::string& error);

  // A server that listens nowhere (options.listen is not used): only LocalClient and HandleHttp
  // reach it. For tests and the fuzz target.
  static std::unique_ptr<FoxgloveServer> StartUnbound(FoxgloveServerOptions options);

  ~FoxgloveServer();  // Stop()
  FoxgloveServer(const FoxgloveServer&) = delete;
  FoxgloveServer& operator=(const FoxgloveServer&) = delete;

  // The port listened on (the chosen one when options.listen asked for port 0).
  int port() const;

  // Adds a channel and advertises it to every client; returns its id (1, 2, ...; never reused).
  uint32_t AddChannel(ChannelSpec spec);
  // Unadvertises the channel and ends its subscriptions (the subscription listener is told, on
  // this thread). Unknown ids are ignored.
  void RemoveChannel(uint32_t channel);
  bool HasSubscribers(uint32_t channel) const;

  // Called when a channel gets its first subscriber (true) or loses its last (false), on the
  // thread that caused it: a civetweb thread (subscribe, unsubscribe, disconnect, Stop) or the
  // caller of RemoveChannel. Calls are serialised and in order. The listener may call any method
  // but SetSubscriptionListener, RemoveChannel and Stop.
  void SetSubscriptionListener(std::function<void(uint32_t channel, bool subscribed)> listener);

  // Queues one message for every subscriber of `channel` (none: nothing is copied). log_time_ns:
  // the frame header's timestamp (Unix-epoch ns). Never blocks on a client.
  void Publish(uint32_t channel, uint64_t log_time_ns, std::string_view payload);

  // Sends a status message to every client. level: 0 info, 1 warning, 2 error; id optional.
  void SendStatus(int level, std::string message, std::string id = "");

  // Routes HTTP requests whose path starts with `path_prefix` (plain string prefix; the longest
  // wins; "/" takes everything else). Without a match: 404. A plain GET "/" reaches the handler
  // of "/"; a WebSocket upgrade on "/" is the Foxglove protocol.
  void AddHttpHandler(std::string path_prefix, HttpHandler handler);

  // What civetweb's request handler does with a request it has read (method, URL-decoded path,
  // query, headers, body within max_request_body_bytes): the access token check under /api/, the
  // handler of the longest matching prefix (none: 404), a handler's exception as 500. Also the
  // entry for tests and the fuzz target, which have no socket.
  HttpResponse HandleHttp(const HttpRequest& request) const;

  // A WebSocket client without a socket, for tests and the fuzz target: the server serves it as
  // a connection that has completed the handshake (serverInfo and the channels are queued at
  // once). Receive() is what civetweb's data handler gets for each frame; what the server would
  // write waits until TakeSent() (there is no sender thread). Destroy it before its server.
  class LocalClient {
   public:
    struct Frame {
      int opcode = 0;  // RFC 6455: 0x1 text, 0x2 binary, 0x8 close
      std::string payload;
    };
    ~LocalClient();  // as when the connection closes: its subscriptions end
    LocalClient(const LocalClient&) = delete;
    LocalClient& operator=(const LocalClient&) = delete;

    // One frame as received: `bits` its first byte (FIN 0x80, the opcode in the low four bits),
    // `payload` unmasked. False when the server ends the connection (civetweb then closes it).
    bool Receive(uint8_t bits, std::string_view payload);
    // The frames the server sent since the last call, in order; after the server closed the
    // connection, its Close frame (if it sends one) comes last.
    std::vector<Frame> TakeSent();

   private:
    friend class FoxgloveServer;
    struct State;
    explicit LocalClient(std::unique_ptr<State> state);
    std::unique_ptr<State> state_;
  };
  std::unique_ptr<LocalClient> ConnectLocal();

  struct Stats {
    size_t clients = 0;             // open WebSocket connections
    uint64_t messages_sent = 0;     // WebSocket messages written (JSON and binary)
    uint64_t messages_dropped = 0;  // binary messages dropped from full client queues
    uint64_t bytes_sent = 0;        // their payload bytes
  };
  Stats stats() const;

  // Stops listening, closes every connection and joins every thread. Idempotent.
  void Stop();

 private:
  struct Impl;
  explicit FoxgloveServer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace stevi::station
