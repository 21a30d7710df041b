// A small blocking WebSocket client (RFC 6455) and a one-shot HTTP/1.1 request, on plain POSIX
// TCP sockets, for tests of the station's server. One thread uses a client at a time.
#pragma once

#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace stevi::testing {

// Sec-WebSocket-Accept for a Sec-WebSocket-Key: base64(SHA-1(key + the RFC 6455 GUID)).
std::string WebSocketAccept(std::string_view key);
std::string Base64Encode(std::string_view bytes);
// nullopt when `text` is not canonical base64 (padding included).
std::optional<std::string> Base64Decode(std::string_view text);

// A WebSocket message, reassembled from its fragments.
struct WsMessage {
  static constexpr int kText = 0x1;
  static constexpr int kBinary = 0x2;
  static constexpr int kClose = 0x8;
  static constexpr int kEnd = -1;  // the connection ended (EOF or an error) without a close frame
  int opcode = 0;
  std::string payload;
  // kClose: the status code of the payload (0 when none) and its reason.
  uint16_t close_code() const;
};

struct WsOptions {
  std::string path = "/";                                    // with the query, e.g. "/?token=T"
  std::vector<std::string> subprotocols;                     // offered in this order
  std::vector<std::pair<std::string, std::string>> headers;  // extra request headers
  std::chrono::milliseconds timeout{5000};                   // connect and handshake
};

class WsClient {
 public:
  // Connects to HOST:PORT (IPv4 literal) and sends the upgrade request. nullptr and `error` when
  // the TCP connection or the response fails; a refusal (any status but 101) returns a client
  // whose status() says so (and open() is false).
  static std::unique_ptr<WsClient> Connect(const std::string& host, int port,
                                           const WsOptions& options, std::string& error);
  ~WsClient();
  WsClient(const WsClient&) = delete;
  WsClient& operator=(const WsClient&) = delete;

  int status() const { return status_; }
  bool open() const { return open_; }
  // The Sec-WebSocket-Protocol of the response ("" when none).
  const std::string& subprotocol() const { return subprotocol_; }
  // The response's headers (names in lower case) and, for a refusal, its body.
  const std::map<std::string, std::string>& response_headers() const { return headers_; }
  const std::string& response_body() const { return body_; }

  // Sends one message in one frame (masked, as a client must). False when the socket fails.
  bool SendText(std::string_view text) { return SendFrame(0x1, text, true); }
  bool SendBinary(std::string_view bytes) { return SendFrame(0x2, bytes, true); }
  bool SendFrame(int opcode, std::string_view payload, bool fin);
  // Writes raw bytes (malformed frames).
  bool SendRaw(std::string_view bytes);
  // Sends a close frame with `code`.
  bool SendClose(uint16_t code);

  // The next text, binary or close message, waiting at most `timeout`; nullopt on timeout.
  // Pings are answered and pongs skipped. After kClose or kEnd, every call returns kEnd.
  std::optional<WsMessage> Receive(std::chrono::milliseconds timeout);

  // Closes the socket at once (no close handshake).
  void Abort();

 private:
  WsClient() = default;
  // Reads exactly n bytes before `deadline`; false on timeout (*timed_out) or EOF/error.
  bool ReadExactly(size_t n, std::string& out, std::chrono::steady_clock::time_point deadline,
                   bool* timed_out);

  int fd_ = -1;
  int status_ = 0;
  bool open_ = false;
  bool ended_ = false;
  std::string subprotocol_;
  std::map<std::string, std::string> headers_;
  std::string body_;
  std::string buffer_;  // bytes read past what has been consumed
};

struct HttpReply {
  int status = 0;
  std::map<std::string, std::string> headers;  // names in lower case
  std::string body;
};

// One HTTP/1.1 request with "Connection: close"; reads the reply until the server closes.
// `body` non-empty: sent with its Content-Length. nullopt and `error` on failure or timeout.
std::optional<HttpReply> HttpRequestOnce(
    const std::string& host, int port, const std::string& method, const std::string& target,
    const std::vector<std::pair<std::string, std::string>>& headers, const std::string& body,
    std::string& error, std::chrono::milliseconds timeout = std::chrono::seconds(5));

}  // namespace stevi::testing
