#include "client/mavlink/link.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <sys/file.h>
#include <sys/socket.h>
#include <termios.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <charconv>
#include <climits>
#include <cstring>
#include <mutex>
#include <optional>
#include <string_view>
#include <utility>

namespace stevi::client::mavlink {
namespace {

using std::chrono::milliseconds;
using std::chrono::steady_clock;

constexpr std::string_view kForms =
    "use udp://HOST:PORT, udpin://ADDR:PORT or serial://DEVICE:BAUD";
constexpr std::string_view kHostForms =
    "a name, an IPv4 address or a bracketed IPv6 address such as [::1]";

// How long a serial Send waits in all for the device to take its bytes.
constexpr milliseconds kSerialWriteTimeout{1000};

struct BaudRate {
  int rate;
  speed_t speed;
};

// Linux's termios rates from B9600 up (bits/termios-baud.h).
constexpr std::array<BaudRate, 18> kBaudRates = {{
    {9600, B9600},
    {19200, B19200},
    {38400, B38400},
    {57600, B57600},
    {115200, B115200},
    {230400, B230400},
    {460800, B460800},
    {500000, B500000},
    {576000, B576000},
    {921600, B921600},
    {1000000, B1000000},
    {1152000, B1152000},
    {1500000, B1500000},
    {2000000, B2000000},
    {2500000, B2500000},
    {3000000, B3000000},
    {3500000, B3500000},
    {4000000, B4000000},
}};

constexpr std::array<int, kBaudRates.size()> kRates = [] {
  std::array<int, kBaudRates.size()> rates{};
  for (std::size_t i = 0; i < kBaudRates.size(); ++i) rates[i] = kBaudRates[i].rate;
  return rates;
}();

std::optional<speed_t> SpeedOf(int rate) {
  for (const BaudRate& b : kBaudRates) {
    if (b.rate == rate) return b.speed;
  }
  return std::nullopt;
}

std::string RatesText() {
  std::string out;
  for (const int rate : kRates) {
    if (!out.empty()) out += ", ";
    out += std::to_string(rate);
  }
  return out;
}

// strerror's text, thread-safe (the GNU strerror_r).
std::string ErrnoText(int error) {
  std::array<char, 256> buffer{};
  return strerror_r(error, buffer.data(), buffer.size());
}

// User text for a message: in double quotes, with quotes, backslashes and bytes outside printable
// ASCII escaped, and cut at 200 bytes.
std::string Quote(std::string_view text) {
  constexpr std::size_t kMaxShown = 200;
  std::string out = "\"";
  for (std::size_t i = 0; i < text.size() && i < kMaxShown; ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    if (c == '"' || c == '\\') {
      out += '\\';
      out += static_cast<char>(c);
    } else if (c < 0x20 || c >= 0x7F) {
      constexpr std::string_view kHex = "0123456789abcdef";
      out += "\\x";
      out += kHex[c >> 4];
      out += kHex[c & 0xF];
    } else {
      out += static_cast<char>(c);
    }
  }
  if (text.size() > kMaxShown) out += "...";
  return out + "\"";
}

bool AllDigits(std::string_view text) {
  return !text.empty() &&
         std::all_of(text.begin(), text.end(), [](char c) { return c >= '0' && c <= '9'; });
}

// A decimal whole number of at most 9 digits; nullopt for anything else.
std::optional<int> ParseSmallNumber(std::string_view text) {
  if (!AllDigits(text) || text.size() > 9) return std::nullopt;
  int value = 0;
  std::from_chars(text.data(), text.data() + text.size(), value);
  return value;
}

// Characters of a host name or an IPv4 address.
bool IsNameText(std::string_view text) {
  return std::all_of(text.begin(), text.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '-' ||
           c == '.' || c == '_';
  });
}

// An IPv6 address, with an optional zone ("fe80::1%eth0").
bool IsIpv6Literal(const std::string& text) {
  const std::size_t zone = text.find('%');
  const std::string address = text.substr(0, zone);
  if (zone != std::string::npos && !IsNameText(text.substr(zone + 1))) return false;
  in6_addr parsed{};
  return inet_pton(AF_INET6, address.c_str(), &parsed) == 1;
}

// HOST:PORT or [IPV6]:PORT after "udp://" or "udpin://", into out.host and out.port.
std::string ParseHostPort(std::string_view scheme, std::string_view rest, const std::string& url,
                          LinkUrl& out) {
  const bool listening = scheme == "udpin";
  const std::string form = std::string(scheme) + (listening ? "://ADDR:PORT" : "://HOST:PORT");
  const std::string example = listening ? "udpin://0.0.0.0:14550" : "udp://127.0.0.1:14540";
  std::string_view host;
  std::optional<std::string_view> port_text;  // nullopt: no ':' after the host
  if (!rest.empty() && rest.front() == '[') {
    const std::size_t close = rest.find(']');
    if (close == std::string_view::npos) {
      return "--link: " + Quote(url) + " opens a '[' it does not close (" + form + ", as in " +
             std::string(scheme) + "://[::1]:14540)";
    }
    host = rest.substr(1, close - 1);
    const std::string_view after = rest.substr(close + 1);
    if (!after.empty() && after.front() != ':') {
      return "--link: " + Quote(url) + " has " + Quote(after) + " after ']' where ':PORT' belongs";
    }
    if (!after.empty()) port_text = after.substr(1);
    if (!host.empty() && !IsIpv6Literal(std::string(host))) {
      return "--link: " + Quote(host) + " in " + Quote(url) + " is not an IPv6 address";
    }
  } else {
    const std::size_t colon = rest.rfind(':');
    host = rest.substr(0, colon);
    if (colon != std::string_view::npos) port_text = rest.substr(colon + 1);
    if (host.find(':') != std::string_view::npos) {
      return "--link: " + Quote(url) + ": put an IPv6 address in brackets, as in " +
             std::string(scheme) + "://[::1]:14540";
    }
    if (!IsNameText(host)) {
      return "--link: host " + Quote(host) + " in " + Quote(url) + " is not " +
             std::string(kHostForms);
    }
  }
  if (host.empty()) {
    return "--link: " + Quote(url) + " has no " + (listening ? "address" : "host") + " (" + form +
           (listening ? "; udpin://0.0.0.0:PORT listens on every interface)"
                      : "; HOST is " + std::string(kHostForms) + ")");
  }
  if (!port_text.has_value() || port_text->empty()) {
    return "--link: " + Quote(url) + " has no port (" + form + ", as in " + example + ")";
  }
  const std::optional<int> port = ParseSmallNumber(*port_text);
  if (!port.has_value() || *port < 1 || *port > 65535) {
    return "--link: port " + Quote(*port_text) + " in " + Quote(url) +
           " is not a whole number in 1..65535";
  }
  out.kind = listening ? LinkUrl::Kind::kUdpIn : LinkUrl::Kind::kUdpOut;
  out.host = std::string(host);
  out.port = *port;
  return "";
}

// DEVICE[:BAUD] after "serial://", into out.device and out.baud.
std::string ParseSerial(std::string_view rest, const std::string& url, LinkUrl& out) {
  constexpr std::string_view kSerialForm =
      "serial://DEVICE:BAUD, as in serial:///dev/ttyACM0:921600";
  std::string_view device = rest;
  int baud = kDefaultSerialBaud;
  const std::size_t colon = rest.rfind(':');
  const std::size_t slash = rest.rfind('/');
  if (colon != std::string_view::npos && (slash == std::string_view::npos || colon > slash)) {
    device = rest.substr(0, colon);
    const std::string_view baud_text = rest.substr(colon + 1);
    const std::optional<int> rate = ParseSmallNumber(baud_text);
    if (!rate.has_value() || !SpeedOf(*rate).has_value()) {
      std::string message = "--link: baud rate " + Quote(baud_text) + " in " + Quote(url) +
                            " is not one of " + RatesText();
      if (!baud_text.empty() && !AllDigits(baud_text)) {
        message += " (a device whose file name holds a ':' must be given its rate after it)";
      }
      return message;
    }
    baud = *rate;
  }
  if (device.empty()) {
    return "--link: " + Quote(url) + " has no device (" + std::string(kSerialForm) + ")";
  }
  if (device.front() != '/') {
    return "--link: device " + Quote(device) + " in " + Quote(url) +
           " is not an absolute path (the path keeps its '/' after serial://: " +
           std::string(kSerialForm) + ")";
  }
  out.kind = LinkUrl::Kind::kSerial;
  out.device = std::string(device);
  out.baud = baud;
  return "";
}

// A file descriptor, closed when dropped.
class Fd {
 public:
  Fd() = default;
  explicit Fd(int fd) : fd_(fd) {}
  Fd(const Fd&) = delete;
  Fd& operator=(const Fd&) = delete;
  Fd(Fd&& other) noexcept : fd_(std::exchange(other.fd_, -1)) {}
  Fd& operator=(Fd&& other) noexcept {
    if (this != &other) {
      Close();
      fd_ = std::exchange(other.fd_, -1);
    }
    return *this;
  }
  ~Fd() { Close(); }

  int get() const { return fd_; }
  bool ok() const { return fd_ >= 0; }

 private:
  void Close() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }

  int fd_ = -1;
};

// A socket address with its length.
struct SocketAddress {
  sockaddr_storage storage{};
  socklen_t length = 0;

  const sockaddr* get() const { return reinterpret_cast<const sockaddr*>(&storage); }
  sockaddr* get() { return reinterpret_cast<sockaddr*>(&storage); }
};

// "127.0.0.1:14540", "[::1]:14540".
std::string FormatAddress(const SocketAddress& address) {
  std::array<char, NI_MAXHOST> host{};
  std::array<char, NI_MAXSERV> port{};
  if (getnameinfo(address.get(), address.length, host.data(), host.size(), port.data(), port.size(),
                  NI_NUMERICHOST | NI_NUMERICSERV) != 0) {
    return "(unknown address)";
  }
  if (address.storage.ss_family == AF_INET6) {
    return "[" + std::string(host.data()) + "]:" + port.data();
  }
  return std::string(host.data()) + ":" + port.data();
}

int PortOf(const SocketAddress& address) {
  if (address.storage.ss_family == AF_INET) {
    return ntohs(reinterpret_cast<const sockaddr_in*>(&address.storage)->sin_port);
  }
  if (address.storage.ss_family == AF_INET6) {
    return ntohs(reinterpret_cast<const sockaddr_in6*>(&address.storage)->sin6_port);
  }
  return 0;
}

// The datagram address of host:port: its first IPv4 address, else its first IPv6 one. `passive`
// for an address to bind. "" or the problem.
std::string Resolve(const std::string& host, int port, bool passive, SocketAddress& out) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_DGRAM;
  hints.ai_flags = AI_NUMERICSERV | (passive ? AI_PASSIVE : 0);
  if (host.find(':') != std::string::npos) hints.ai_flags |= AI_NUMERICHOST;
  addrinfo* found = nullptr;
  const int status = getaddrinfo(host.c_str(), std::to_string(port).c_str(), &hints, &found);
  if (status != 0) {
    const std::string reason = status == EAI_SYSTEM ? ErrnoText(errno) : gai_strerror(status);
    return "cannot resolve host " + Quote(host) + ": " + reason;
  }
  const addrinfo* chosen = nullptr;
  for (const addrinfo* a = found; a != nullptr; a = a->ai_next) {
    if (a->ai_family == AF_INET && chosen == nullptr) chosen = a;
  }
  for (const addrinfo* a = found; a != nullptr && chosen == nullptr; a = a->ai_next) {
    if (a->ai_family == AF_INET6) chosen = a;
  }
  const bool taken = chosen != nullptr && chosen->ai_addrlen <= sizeof(out.storage);
  if (taken) {
    std::memcpy(&out.storage, chosen->ai_addr, chosen->ai_addrlen);
    out.length = chosen->ai_addrlen;
  }
  freeaddrinfo(found);
  if (!taken) return "host " + Quote(host) + " has no IPv4 or IPv6 address";
  return "";
}

// What a wait for input ended with.
enum class Wake { kReadable, kTimeout, kInterrupted, kFailed };

// What every link shares: the eventfd that Interrupt() signals and the wait on it.
class PollingLink : public Link {
 public:
  explicit PollingLink(Fd wake) : wake_(std::move(wake)) {}

  void Interrupt() override {
    const uint64_t one = 1;
    // EAGAIN only when the counter is full, which still wakes the reader.
    [[maybe_unused]] const ssize_t n = ::write(wake_.get(), &one, sizeof(one));
  }

 protected:
  // Waits until `fd` is readable, hung up or in error (the read that follows says which), the
  // timeout passes or Interrupt() is called (which this takes).
  Wake WaitReadable(int fd, milliseconds timeout, std::string& error) {
    std::array<pollfd, 2> fds = {{{fd, POLLIN, 0}, {wake_.get(), POLLIN, 0}}};
    const auto ms = static_cast<int>(std::clamp<milliseconds::rep>(timeout.count(), 0, INT_MAX));
    const int n = ::poll(fds.data(), fds.size(), ms);
    if (n < 0) {
      if (errno == EINTR) return Wake::kTimeout;
      error = "poll: " + ErrnoText(errno);
      return Wake::kFailed;
    }
    if (n == 0) return Wake::kTimeout;
    if ((fds[1].revents & POLLIN) != 0) {
      uint64_t count = 0;
      [[maybe_unused]] const ssize_t r = ::read(wake_.get(), &count, sizeof(count));
      return Wake::kInterrupted;
    }
    if ((fds[0].revents & POLLNVAL) != 0) {
      error = "poll: descriptor not open";
      return Wake::kFailed;
    }
    return Wake::kReadable;
  }

  // The start of a Receive into `buffer` from `fd`: nullopt once there is something to read, else
  // what Receive returns: -1 with `error` for an empty buffer or a failed wait, 0 when the wait
  // timed out or was interrupted.
  std::optional<int> AwaitReceive(int fd, std::span<uint8_t> buffer, milliseconds timeout,
                                  std::string& error) {
    if (buffer.empty()) {
      error = "Receive: empty buffer";
      return -1;
    }
    const Wake wake = WaitReadable(fd, timeout, error);
    if (wake == Wake::kFailed) return -1;
    if (wake != Wake::kReadable) return 0;
    return std::nullopt;
  }

 private:
  Fd wake_;
};

// An eventfd for PollingLink; "" or the problem.
std::string MakeWake(Fd& out) {
  out = Fd(::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK));
  if (!out.ok()) return "eventfd: " + ErrnoText(errno);
  return "";
}

// udp:// and udpin://.
class UdpLink final : public PollingLink {
 public:
  UdpLink(Fd socket, Fd wake, bool listening, const SocketAddress& local,
          std::optional<SocketAddress> destination, std::string name)
      : PollingLink(std::move(wake)),
        socket_(std::move(socket)),
        listening_(listening),
        local_(local),
        name_(std::move(name)),
        peer_(std::move(destination)) {}

  std::string Send(std::span<const uint8_t> bytes) override {
    if (bytes.empty()) return "";
    SocketAddress to;
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      if (!peer_.has_value()) return "no peer yet";
      to = *peer_;
    }
    const ssize_t n =
        ::sendto(socket_.get(), bytes.data(), bytes.size(), MSG_DONTWAIT, to.get(), to.length);
    if (n < 0) {
      const int e = errno;
      if (e == EAGAIN || e == EWOULDBLOCK) {
        return "send to " + FormatAddress(to) + ": send buffer full, datagram dropped";
      }
      return "send to " + FormatAddress(to) + ": " + ErrnoText(e);
    }
    if (static_cast<std::size_t>(n) != bytes.size()) {
      return "send to " + FormatAddress(to) + ": sent " + std::to_string(n) + " of " +
             std::to_string(bytes.size()) + " bytes";
    }
    return "";
  }

  int Receive(std::span<uint8_t> buffer, milliseconds timeout, std::string& error) override {
    if (const std::optional<int> early = AwaitReceive(socket_.get(), buffer, timeout, error)) {
      return *early;
    }
    SocketAddress from;
    from.length = sizeof(from.storage);
    const ssize_t n = ::recvfrom(socket_.get(), buffer.data(), buffer.size(), MSG_DONTWAIT,
                                 from.get(), &from.length);
    if (n < 0) {
      const int e = errno;
      // ICMP reports and races with another reader pass; the socket stays usable.
      if (e == EAGAIN || e == EWOULDBLOCK || e == EINTR || e == ECONNREFUSED || e == EHOSTUNREACH ||
          e == ENETUNREACH) {
        return 0;
      }
      error = Describe() + ": receive: " + ErrnoText(e);
      return -1;
    }
    if (listening_) {
      const std::lock_guard<std::mutex> lock(mutex_);
      peer_ = from;
    }
    return static_cast<int>(n);
  }

  std::string Describe() const override {
    if (!listening_) {
      SocketAddress to;
      {
        const std::lock_guard<std::mutex> lock(mutex_);
        to = peer_.value_or(SocketAddress{});
      }
      return "udp://" + FormatAddress(to) + " (" + (name_.empty() ? "" : name_ + ", ") + "from " +
             FormatAddress(local_) + ")";
    }
    std::string out = "udpin://" + FormatAddress(local_) + " (";
    const std::lock_guard<std::mutex> lock(mutex_);
    out += peer_.has_value() ? "peer " + FormatAddress(*peer_) : std::string("no peer yet");
    return out + ")";
  }

  bool HasPeer() const override {
    const std::lock_guard<std::mutex> lock(mutex_);
    return peer_.has_value();
  }

  int LocalPort() const override { return PortOf(local_); }

 private:
  Fd socket_;
  const bool listening_;
  const SocketAddress local_;
  // A host name the user gave, shown by Describe(); "" for an address.
  const std::string name_;
  mutable std::mutex mutex_;
  // udp: the destination, fixed; udpin: whoever spoke last.
  std::optional<SocketAddress> peer_;
};

std::unique_ptr<Link> OpenUdp(const LinkUrl& url, std::string& problem) {
  const bool listening = url.kind == LinkUrl::Kind::kUdpIn;
  SocketAddress address;
  problem = Resolve(url.host, url.port, listening, address);
  if (!problem.empty()) return nullptr;
  const int family = address.storage.ss_family;
  Fd socket(::socket(family, SOCK_DGRAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0));
  if (!socket.ok()) {
    problem = "socket: " + ErrnoText(errno);
    return nullptr;
  }
  SocketAddress local;
  if (listening) {
    local = address;
  } else {
    // Broadcast destinations (udp://192.168.1.255:14550) need leave to send.
    const int on = 1;
    ::setsockopt(socket.get(), SOL_SOCKET, SO_BROADCAST, &on, sizeof(on));
    local.storage.ss_family = static_cast<sa_family_t>(family);  // the wildcard, port 0
    local.length = family == AF_INET6 ? sizeof(sockaddr_in6) : sizeof(sockaddr_in);
  }
  if (::bind(socket.get(), local.get(), local.length) != 0) {
    problem = listening ? "cannot listen on " + FormatAddress(address) + ": " + ErrnoText(errno)
                        : "cannot bind a local port: " + ErrnoText(errno);
    return nullptr;
  }
  local.length = sizeof(local.storage);
  if (::getsockname(socket.get(), local.get(), &local.length) != 0) {
    problem = "getsockname: " + ErrnoText(errno);
    return nullptr;
  }
  Fd wake;
  problem = MakeWake(wake);
  if (!problem.empty()) return nullptr;
  std::optional<SocketAddress> destination;
  if (!listening) destination = address;
  in_addr ipv4{};
  const bool numeric =
      url.host.find(':') != std::string::npos || inet_pton(AF_INET, url.host.c_str(), &ipv4) == 1;
  return std::make_unique<UdpLink>(std::move(socket), std::move(wake), listening, local,
                                   destination, numeric ? "" : url.host);
}

// serial://.
class SerialLink final : public PollingLink {
 public:
  SerialLink(Fd device, Fd wake, std::string describe)
      : PollingLink(std::move(wake)), device_(std::move(device)), describe_(std::move(describe)) {}

  std::string Send(std::span<const uint8_t> bytes) override {
    const std::lock_guard<std::mutex> lock(send_mutex_);
    const steady_clock::time_point deadline = steady_clock::now() + kSerialWriteTimeout;
    std::size_t done = 0;
    while (done < bytes.size()) {
      const ssize_t n = ::write(device_.get(), bytes.data() + done, bytes.size() - done);
      if (n > 0) {
        done += static_cast<std::size_t>(n);
        continue;
      }
      if (n < 0 && errno == EINTR) continue;
      if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK) {
        return "write: " + ErrnoText(errno) + (errno == EIO ? " (device gone?)" : "");
      }
      // The output buffer is full: wait for room, up to the deadline.
      const auto left =
          std::chrono::duration_cast<milliseconds>(deadline - steady_clock::now()).count();
      if (left <= 0) {
        return "wrote " + std::to_string(done) + " of " + std::to_string(bytes.size()) +
               " bytes: the device took no more within " +
               std::to_string(kSerialWriteTimeout.count()) + " ms";
      }
      pollfd p{device_.get(), POLLOUT, 0};
      if (::poll(&p, 1, static_cast<int>(left) + 1) < 0 && errno != EINTR) {
        return "poll: " + ErrnoText(errno);
      }
    }
    return "";
  }

  int Receive(std::span<uint8_t> buffer, milliseconds timeout, std::string& error) override {
    if (const std::optional<int> early = AwaitReceive(device_.get(), buffer, timeout, error)) {
      return *early;
    }
    // VMIN 1 with O_NONBLOCK: no data reads as EAGAIN, so 0 is end of file, a hung-up tty.
    const ssize_t n = ::read(device_.get(), buffer.data(), buffer.size());
    if (n > 0) return static_cast<int>(n);
    if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR)) return 0;
    error = describe_ + ": device gone (" + (n == 0 ? "hung up" : ErrnoText(errno)) + ")";
    return -1;
  }

  std::string Describe() const override { return describe_; }
  bool HasPeer() const override { return true; }
  int LocalPort() const override { return 0; }

 private:
  Fd device_;
  const std::string describe_;
  std::mutex send_mutex_;
};

// Raw 8N1 at `speed`, no flow control, reads of at least one byte (with O_NONBLOCK: EAGAIN when
// there is none, so that a read of 0 means the tty hung up). "" or the problem.
std::string ConfigureSerial(int fd, speed_t speed, int rate) {
  termios tio{};
  if (::tcgetattr(fd, &tio) != 0) return "not a serial device: " + ErrnoText(errno);
  ::cfmakeraw(&tio);  // no echo, line editing, signals, CR/NL translation or parity; 8 bits
  tio.c_cflag &= ~static_cast<tcflag_t>(CSIZE | CSTOPB | PARENB | CRTSCTS);
  tio.c_cflag |= CS8 | CLOCAL | CREAD;
  tio.c_iflag &= ~static_cast<tcflag_t>(IXON | IXOFF | IXANY);
  tio.c_cc[VMIN] = 1;
  tio.c_cc[VTIME] = 0;
  if (::cfsetispeed(&tio, speed) != 0 || ::cfsetospeed(&tio, speed) != 0) {
    return "cannot set " + std::to_string(rate) + " baud: " + ErrnoText(errno);
  }
  if (::tcsetattr(fd, TCSANOW, &tio) != 0) return "tcsetattr: " + ErrnoText(errno);
  // tcsetattr succeeds when any of the changes took: check the rate did.
  termios now{};
  if (::tcgetattr(fd, &now) != 0) return "tcgetattr: " + ErrnoText(errno);
  if (::cfgetospeed(&now) != speed || ::cfgetispeed(&now) != speed) {
    std::string message = "the device does not take " + std::to_string(rate) + " baud";
    for (const BaudRate& b : kBaudRates) {
      if (b.speed == ::cfgetospeed(&now))
        message += " (it stays at " + std::to_string(b.rate) + ")";
    }
    return message;
  }
  ::tcflush(fd, TCIOFLUSH);  // what was queued before is not ours
  return "";
}

std::unique_ptr<Link> OpenSerial(const LinkUrl& url, std::string& problem) {
  const std::optional<speed_t> speed = SpeedOf(url.baud);
  if (!speed.has_value()) {
    problem = "baud rate " + std::to_string(url.baud) + " is not one of " + RatesText();
    return nullptr;
  }
  if (url.device.empty()) {
    problem = "no device";
    return nullptr;
  }
  Fd device(::open(url.device.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC));
  if (!device.ok()) {
    const int e = errno;
    problem = "cannot open " + url.device + ": " + ErrnoText(e);
    if (e == EACCES) problem += " (is the user in the dialout group?)";
    return nullptr;
  }
  if (::flock(device.get(), LOCK_EX | LOCK_NB) != 0) {
    const int e = errno;
    problem = e == EWOULDBLOCK ? "in use by another process (flock)" : "flock: " + ErrnoText(e);
    return nullptr;
  }
  problem = ConfigureSerial(device.get(), *speed, url.baud);
  if (!problem.empty()) return nullptr;
  Fd wake;
  problem = MakeWake(wake);
  if (!problem.empty()) return nullptr;
  LinkUrl canonical = url;
  canonical.text.clear();
  return std::make_unique<SerialLink>(std::move(device), std::move(wake), FormatLinkUrl(canonical));
}

}  // namespace

std::span<const int> SerialBaudRates() { return kRates; }

std::string ParseLinkUrl(const std::string& url, LinkUrl& out) {
  out = LinkUrl{};
  out.text = url;
  const std::size_t separator = url.find("://");
  if (separator == std::string::npos) {
    return "--link: " + Quote(url) + " has no scheme (" + std::string(kForms) + ")";
  }
  const std::string_view scheme = std::string_view(url).substr(0, separator);
  const std::string_view rest = std::string_view(url).substr(separator + 3);
  if (scheme == "udp" || scheme == "udpin") return ParseHostPort(scheme, rest, url, out);
  if (scheme == "serial") return ParseSerial(rest, url, out);
  return "--link: unknown scheme " + Quote(scheme) + " (" + std::string(kForms) + ")";
}

std::string FormatLinkUrl(const LinkUrl& url) {
  if (url.kind == LinkUrl::Kind::kSerial) {
    return "serial://" + url.device + ":" + std::to_string(url.baud);
  }
  const bool ipv6 = url.host.find(':') != std::string::npos;
  return std::string(url.kind == LinkUrl::Kind::kUdpIn ? "udpin://" : "udp://") +
         (ipv6 ? "[" + url.host + "]" : url.host) + ":" + std::to_string(url.port);
}

std::unique_ptr<Link> OpenLink(const LinkUrl& url, std::string& error) {
  error.clear();
  const std::string text = url.text.empty() ? FormatLinkUrl(url) : url.text;
  std::string problem;
  std::unique_ptr<Link> link;
  if (url.kind == LinkUrl::Kind::kSerial) {
    link = OpenSerial(url, problem);
  } else if (url.port < 0 || url.port > 65535 ||
             (url.port == 0 && url.kind != LinkUrl::Kind::kUdpIn)) {
    problem = "port " + std::to_string(url.port) + " is not in 1..65535";
  } else {
    link = OpenUdp(url, problem);
  }
  if (link == nullptr) error = text + ": " + problem;
  return link;
}

}  // namespace stevi::client::mavlink
