#include "tests/testing/ws_client.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <random>

namespace stevi::testing {
namespace {

using Clock = std::chrono::steady_clock;

constexpr char kGuid[] = "258EAFA5-E914-47DA-95CA-C5AB0DC85B11";
constexpr char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

// SHA-1 (FIPS 180-4), enough for the handshake.
std::array<uint8_t, 20> Sha1(std::string_view data) {
  uint32_t h[5] = {0x67452301, 0xEFCDAB89, 0x98BADCFE, 0x10325476, 0xC3D2E1F0};
  std::string message(data);
  const uint64_t bit_length = uint64_t(data.size()) * 8;
  message += char(0x80);
  while (message.size() % 64 != 56) message += char(0);
  for (int i = 7; i >= 0; --i) message += char((bit_length >> (8 * i)) & 0xff);
  auto rotl = [](uint32_t x, int n) { return (x << n) | (x >> (32 - n)); };
  for (size_t chunk = 0; chunk < message.size(); chunk += 64) {
    uint32_t w[80];
    for (int i = 0; i < 16; ++i) {
      w[i] = (uint32_t(uint8_t(message[chunk + 4 * i])) << 24) |
             (uint32_t(uint8_t(message[chunk + 4 * i + 1])) << 16) |
             (uint32_t(uint8_t(message[chunk + 4 * i + 2])) << 8) |
             uint32_t(uint8_t(message[chunk + 4 * i + 3]));
    }
    for (int i = 16; i < 80; ++i) w[i] = rotl(w[i - 3] ^ w[i - 8] ^ w[i - 14] ^ w[i - 16], 1);
    uint32_t a = h[0], b = h[1], c = h[2], d = h[3], e = h[4];
    for (int i = 0; i < 80; ++i) {
      uint32_t f = 0;
      uint32_t k = 0;
      if (i < 20) {
        f = (b & c) | (~b & d);
        k = 0x5A827999;
      } else if (i < 40) {
        f = b ^ c ^ d;
        k = 0x6ED9EBA1;
      } else if (i < 60) {
        f = (b & c) | (b & d) | (c & d);
        k = 0x8F1BBCDC;
      } else {
        f = b ^ c ^ d;
        k = 0xCA62C1D6;
      }
      const uint32_t t = rotl(a, 5) + f + e + k + w[i];
      e = d;
      d = c;
      c = rotl(b, 30);
      b = a;
      a = t;
    }
    h[0] += a;
    h[1] += b;
    h[2] += c;
    h[3] += d;
    h[4] += e;
  }
  std::array<uint8_t, 20> digest{};
  for (int i = 0; i < 5; ++i) {
    for (int j = 0; j < 4; ++j) digest[4 * i + j] = uint8_t(h[i] >> (24 - 8 * j));
  }
  return digest;
}

std::string Lower(std::string text) {
  std::transform(text.begin(), text.end(), text.begin(),
                 [](unsigned char c) { return char(std::tolower(c)); });
  return text;
}

std::string Trim(std::string_view text) {
  while (!text.empty() && (text.front() == ' ' || text.front() == '\t')) text.remove_prefix(1);
  while (!text.empty() && (text.back() == ' ' || text.back() == '\t' || text.back() == '\r')) {
    text.remove_suffix(1);
  }
  return std::string(text);
}

int Remaining(Clock::time_point deadline) {
  const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
  return int(std::max<int64_t>(0, left.count()));
}

// A connected TCP socket to HOST:PORT, or -1 and `error`.
int ConnectTcp(const std::string& host, int port, std::string& error) {
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(uint16_t(port));
  if (inet_pton(AF_INET, host.c_str(), &address.sin_addr) != 1) {
    error = "not an IPv4 address: " + host;
    return -1;
  }
  const int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) {
    error = std::string("socket: ") + std::strerror(errno);
    return -1;
  }
  if (connect(fd, reinterpret_cast<const sockaddr*>(&address), sizeof address) != 0) {
    error = std::string("connect: ") + std::strerror(errno);
    close(fd);
    return -1;
  }
  const int one = 1;
  setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
  return fd;
}

bool WriteAll(int fd, std::string_view bytes) {
  while (!bytes.empty()) {
    const ssize_t n = send(fd, bytes.data(), bytes.size(), MSG_NOSIGNAL);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    bytes.remove_prefix(size_t(n));
  }
  return true;
}

// Reads until "\r\n\r\n"; the header block (without it) and anything past it in `rest`.
bool ReadHead(int fd, Clock::time_point deadline, std::string& head, std::string& rest) {
  std::string data;
  for (;;) {
    const size_t end = data.find("\r\n\r\n");
    if (end != std::string::npos) {
      head = data.substr(0, end);
      rest = data.substr(end + 4);
      return true;
    }
    pollfd p{fd, POLLIN, 0};
    if (poll(&p, 1, Remaining(deadline)) <= 0) return false;
    char buffer[4096];
    const ssize_t n = recv(fd, buffer, sizeof buffer, 0);
    if (n <= 0) return false;
    data.append(buffer, size_t(n));
  }
}

// "HTTP/1.1 101 ..." and the headers.
bool ParseHead(const std::string& head, int& status, std::map<std::string, std::string>& headers) {
  size_t line_end = head.find("\r\n");
  const std::string status_line = head.substr(0, line_end);
  if (status_line.rfind("HTTP/1.", 0) != 0 || status_line.size() < 12) return false;
  status = std::atoi(status_line.c_str() + 9);
  while (line_end != std::string::npos) {
    const size_t start = line_end + 2;
    line_end = head.find("\r\n", start);
    const std::string line = head.substr(start, line_end - start);
    const size_t colon = line.find(':');
    if (colon == std::string::npos) continue;
    const std::string name = Lower(line.substr(0, colon));
    const std::string value = Trim(std::string_view(line).substr(colon + 1));
    auto [it, inserted] = headers.emplace(name, value);
    if (!inserted) it->second += ", " + value;
  }
  return true;
}

// Reads until EOF or the deadline into `out`; true on EOF.
bool ReadToEnd(int fd, Clock::time_point deadline, std::string& out) {
  for (;;) {
    pollfd p{fd, POLLIN, 0};
    if (poll(&p, 1, Remaining(deadline)) <= 0) return false;
    char buffer[4096];
    const ssize_t n = recv(fd, buffer, sizeof buffer, 0);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) return errno == ECONNRESET;
    if (n == 0) return true;
    out.append(buffer, size_t(n));
  }
}

}  // namespace

std::string Base64Encode(std::string_view bytes) {
  std::string out;
  size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const uint32_t v =
        (uint8_t(bytes[i]) << 16) | (uint8_t(bytes[i + 1]) << 8) | uint8_t(bytes[i + 2]);
    for (int s = 18; s >= 0; s -= 6) out += kAlphabet[(v >> s) & 63];
  }
  if (i < bytes.size()) {
    uint32_t v = uint8_t(bytes[i]) << 16;
    if (i + 1 < bytes.size()) v |= uint8_t(bytes[i + 1]) << 8;
    out += kAlphabet[v >> 18];
    out += kAlphabet[(v >> 12) & 63];
    out += i + 1 < bytes.size() ? kAlphabet[(v >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

std::optional<std::string> Base64Decode(std::string_view text) {
  if (text.size() % 4 != 0) return std::nullopt;
  std::string out;
  for (size_t i = 0; i < text.size(); i += 4) {
    uint32_t v = 0;
    int pad = 0;
    for (int j = 0; j < 4; ++j) {
      const char c = text[i + j];
      const char* p = c == '=' ? nullptr : std::strchr(kAlphabet, c);
      if (c == '=') {
        if (i + 4 != text.size() || j < 2) return std::nullopt;
        ++pad;
      } else if (p == nullptr || c == '\0' || pad > 0) {
        return std::nullopt;
      }
      v = (v << 6) | uint32_t(p != nullptr ? p - kAlphabet : 0);
    }
    out += char(v >> 16);
    if (pad < 2) out += char((v >> 8) & 0xff);
    if (pad < 1) out += char(v & 0xff);
  }
  if (Base64Encode(out) != text) return std::nullopt;  // non-canonical padding bits
  return out;
}

std::string WebSocketAccept(std::string_view key) {
  const std::array<uint8_t, 20> digest = Sha1(std::string(key) + kGuid);
  return Base64Encode(
      std::string_view(reinterpret_cast<const char*>(digest.data()), digest.size()));
}

uint16_t WsMessage::close_code() const {
  if (opcode != kClose || payload.size() < 2) return 0;
  return uint16_t((uint8_t(payload[0]) << 8) | uint8_t(payload[1]));
}

std::unique_ptr<WsClient> WsClient::Connect(const std::string& host, int port,
                                            const WsOptions& options, std::string& error) {
  const Clock::time_point deadline = Clock::now() + options.timeout;
  const int fd = ConnectTcp(host, port, error);
  if (fd < 0) return nullptr;
  std::unique_ptr<WsClient> client(new WsClient());
  client->fd_ = fd;

  std::mt19937 random(std::random_device{}());
  std::string nonce(16, '\0');
  for (char& c : nonce) c = char(random() & 0xff);
  const std::string key = Base64Encode(nonce);
  std::string request = "GET " + options.path + " HTTP/1.1\r\nHost: " + host + ":" +
                        std::to_string(port) +
                        "\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                        "Sec-WebSocket-Key: " +
                        key + "\r\nSec-WebSocket-Version: 13\r\n";
  if (!options.subprotocols.empty()) {
    request += "Sec-WebSocket-Protocol: ";
    for (size_t i = 0; i < options.subprotocols.size(); ++i) {
      request += (i > 0 ? ", " : "") + options.subprotocols[i];
    }
    request += "\r\n";
  }
  for (const auto& [name, value] : options.headers) request += name + ": " + value + "\r\n";
  request += "\r\n";
  if (!WriteAll(fd, request)) {
    error = "cannot send the upgrade request";
    return nullptr;
  }
  std::string head;
  if (!ReadHead(fd, deadline, head, client->buffer_) ||
      !ParseHead(head, client->status_, client->headers_)) {
    error = "no HTTP response to the upgrade request";
    return nullptr;
  }
  if (client->status_ != 101) {
    // A refusal: its body (by Content-Length, else until the server closes).
    const auto length = client->headers_.find("content-length");
    if (length != client->headers_.end()) {
      const size_t n = std::stoul(length->second);
      if (client->buffer_.size() < n) {
        bool timed_out = false;
        std::string more;
        client->ReadExactly(n - client->buffer_.size(), more, deadline, &timed_out);
        client->buffer_ += more;
      }
      client->body_ = client->buffer_.substr(0, n);
    } else {
      ReadToEnd(fd, deadline, client->buffer_);
      client->body_ = client->buffer_;
    }
    client->buffer_.clear();
    return client;
  }
  const auto accept = client->headers_.find("sec-websocket-accept");
  if (accept == client->headers_.end() || accept->second != WebSocketAccept(key)) {
    error = "101 without the right Sec-WebSocket-Accept";
    return nullptr;
  }
  const auto protocol = client->headers_.find("sec-websocket-protocol");
  if (protocol != client->headers_.end()) client->subprotocol_ = protocol->second;
  client->open_ = true;
  return client;
}

WsClient::~WsClient() { Abort(); }

void WsClient::Abort() {
  if (fd_ >= 0) close(fd_);
  fd_ = -1;
  open_ = false;
}

bool WsClient::SendRaw(std::string_view bytes) { return fd_ >= 0 && WriteAll(fd_, bytes); }

bool WsClient::SendFrame(int opcode, std::string_view payload, bool fin) {
  std::string frame;
  frame += char((fin ? 0x80 : 0) | (opcode & 0x0f));
  if (payload.size() < 126) {
    frame += char(0x80 | payload.size());
  } else if (payload.size() <= 0xffff) {
    frame += char(0x80 | 126);
    frame += char(payload.size() >> 8);
    frame += char(payload.size() & 0xff);
  } else {
    frame += char(0x80 | 127);
    for (int i = 7; i >= 0; --i) frame += char((uint64_t(payload.size()) >> (8 * i)) & 0xff);
  }
  static std::mt19937 random(12345);
  char mask[4];
  for (char& m : mask) m = char(random() & 0xff);
  frame.append(mask, 4);
  const size_t start = frame.size();
  frame.append(payload);
  for (size_t i = 0; i < payload.size(); ++i) frame[start + i] ^= mask[i % 4];
  return SendRaw(frame);
}

bool WsClient::SendClose(uint16_t code) {
  std::string payload;
  payload += char(code >> 8);
  payload += char(code & 0xff);
  return SendFrame(WsMessage::kClose, payload, true);
}

bool WsClient::ReadExactly(size_t n, std::string& out, Clock::time_point deadline,
                           bool* timed_out) {
  *timed_out = false;
  while (buffer_.size() < n) {
    if (fd_ < 0) return false;
    pollfd p{fd_, POLLIN, 0};
    const int ready = poll(&p, 1, Remaining(deadline));
    if (ready < 0 && errno == EINTR) continue;
    if (ready == 0) {
      *timed_out = true;
      return false;
    }
    if (ready < 0) return false;
    char buffer[65536];
    const ssize_t got = recv(fd_, buffer, sizeof buffer, 0);
    if (got < 0 && errno == EINTR) continue;
    if (got <= 0) return false;
    buffer_.append(buffer, size_t(got));
  }
  out = buffer_.substr(0, n);
  buffer_.erase(0, n);
  return true;
}

std::optional<WsMessage> WsClient::Receive(std::chrono::milliseconds timeout) {
  if (ended_ || fd_ < 0) return WsMessage{WsMessage::kEnd, ""};
  const Clock::time_point deadline = Clock::now() + timeout;
  WsMessage message;
  bool in_message = false;
  // Bytes of a partly read frame stay in buffer_ on timeout: a frame is consumed only whole.
  for (;;) {
    bool timed_out = false;
    std::string head;
    if (!ReadExactly(2, head, deadline, &timed_out)) {
      if (timed_out) return std::nullopt;
      ended_ = true;
      return WsMessage{WsMessage::kEnd, ""};
    }
    const bool fin = (uint8_t(head[0]) & 0x80) != 0;
    const int opcode = uint8_t(head[0]) & 0x0f;
    const bool masked = (uint8_t(head[1]) & 0x80) != 0;
    uint64_t length = uint8_t(head[1]) & 0x7f;
    std::string extended;
    const size_t extended_bytes = length == 126 ? 2 : length == 127 ? 8 : 0;
    std::string rest;
    // Peek the whole frame before consuming it, so that a timeout leaves the stream intact.
    auto restore = [&](const std::string& consumed) { buffer_.insert(0, consumed); };
    if (extended_bytes > 0) {
      if (!ReadExactly(extended_bytes, extended, deadline, &timed_out)) {
        restore(head);
        if (timed_out) return std::nullopt;
        ended_ = true;
        return WsMessage{WsMessage::kEnd, ""};
      }
      length = 0;
      for (char c : extended) length = (length << 8) | uint8_t(c);
    }
    std::string mask;
    if (masked && !ReadExactly(4, mask, deadline, &timed_out)) {
      restore(head + extended);
      if (timed_out) return std::nullopt;
      ended_ = true;
      return WsMessage{WsMessage::kEnd, ""};
    }
    std::string payload;
    if (!ReadExactly(size_t(length), payload, deadline, &timed_out)) {
      restore(head + extended + mask);
      if (timed_out) return std::nullopt;
      ended_ = true;
      return WsMessage{WsMessage::kEnd, ""};
    }
    if (masked) {
      for (size_t i = 0; i < payload.size(); ++i) payload[i] ^= mask[i % 4];
    }
    if (opcode == 0x9) {  // ping: pong with the same payload
      SendFrame(0xA, payload, true);
      continue;
    }
    if (opcode == 0xA) continue;
    if (opcode == WsMessage::kClose) {
      ended_ = true;
      return WsMessage{WsMessage::kClose, payload};
    }
    if (opcode == 0x0) {
      if (!in_message) continue;  // a stray continuation: ignored
      message.payload += payload;
    } else {
      message.opcode = opcode;
      message.payload = payload;
      in_message = true;
    }
    if (fin) return message;
  }
}

std::optional<HttpReply> HttpRequestOnce(
    const std::string& host, int port, const std::string& method, const std::string& target,
    const std::vector<std::pair<std::string, std::string>>& headers, const std::string& body,
    std::string& error, std::chrono::milliseconds timeout) {
  const Clock::time_point deadline = Clock::now() + timeout;
  const int fd = ConnectTcp(host, port, error);
  if (fd < 0) return std::nullopt;
  std::string request = method + " " + target + " HTTP/1.1\r\nHost: " + host + ":" +
                        std::to_string(port) + "\r\nConnection: close\r\n";
  for (const auto& [name, value] : headers) request += name + ": " + value + "\r\n";
  if (!body.empty()) request += "Content-Length: " + std::to_string(body.size()) + "\r\n";
  request += "\r\n";
  // The body may be refused before it is read: a failed write of it is not an error here.
  WriteAll(fd, request);
  WriteAll(fd, body);
  std::string head;
  std::string rest;
  HttpReply reply;
  if (!ReadHead(fd, deadline, head, rest) || !ParseHead(head, reply.status, reply.headers)) {
    error = "no HTTP response";
    close(fd);
    return std::nullopt;
  }
  const auto length = reply.headers.find("content-length");
  if (length != reply.headers.end()) {
    const size_t n = std::stoul(length->second);
    while (rest.size() < n) {
      pollfd p{fd, POLLIN, 0};
      if (poll(&p, 1, Remaining(deadline)) <= 0) break;
      char buffer[4096];
      const ssize_t got = recv(fd, buffer, sizeof buffer, 0);
      if (got <= 0) break;
      rest.append(buffer, size_t(got));
    }
    reply.body = rest.substr(0, n);
  } else {
    ReadToEnd(fd, deadline, rest);
    reply.body = rest;
  }
  close(fd);
  return reply;
}

}  // namespace stevi::testing
