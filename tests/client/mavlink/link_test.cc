#include "client/mavlink/link.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <dirent.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <stdlib.h>
#include <sys/socket.h>
#include <termios.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <future>
#include <map>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

namespace stevi::client::mavlink {
namespace {

using std::chrono::milliseconds;
using std::chrono::seconds;
using std::chrono::steady_clock;
using ::testing::HasSubstr;
using ::testing::StartsWith;
using Bytes = std::vector<uint8_t>;

// Every bounded wait for an event that should come: generous, as the machine may be loaded; the
// tests pass in milliseconds.
constexpr milliseconds kEventTimeout{5000};

constexpr std::string_view kForms =
    " (use udp://HOST:PORT, udpin://ADDR:PORT or serial://DEVICE:BAUD)";
constexpr std::string_view kRates =
    "9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000, 576000, 921600, 1000000, 1152000, "
    "1500000, 2000000, 2500000, 3000000, 3500000, 4000000";

Bytes Text(std::string_view text) { return Bytes(text.begin(), text.end()); }

Bytes EveryByteValue() {
  Bytes bytes(256);
  for (int i = 0; i < 256; ++i) bytes[i] = static_cast<uint8_t>(i);
  return bytes;
}

// A descriptor closed at the end of its scope.
class ScopedFd {
 public:
  explicit ScopedFd(int fd = -1) : fd_(fd) {}
  ScopedFd(const ScopedFd&) = delete;
  ScopedFd& operator=(const ScopedFd&) = delete;
  ~ScopedFd() { Close(); }
  int get() const { return fd_; }
  void Close() { Reset(-1); }
  void Reset(int fd) {
    if (fd_ >= 0) ::close(fd_);
    fd_ = fd;
  }

 private:
  int fd_;
};

// The first non-empty Receive within the timeout; empty on timeout. `error` set on -1.
Bytes ReceiveSome(Link& link, std::string& error, milliseconds timeout = kEventTimeout) {
  std::array<uint8_t, kLinkBufferBytes> buffer{};
  const steady_clock::time_point deadline = steady_clock::now() + timeout;
  while (steady_clock::now() < deadline) {
    const auto left = std::chrono::duration_cast<milliseconds>(deadline - steady_clock::now());
    const int n = link.Receive(buffer, left, error);
    if (n < 0) return {};
    if (n > 0) return Bytes(buffer.begin(), buffer.begin() + n);
  }
  return {};
}

Bytes ReceiveSome(Link& link) {
  std::string error;
  Bytes bytes = ReceiveSome(link, error);
  EXPECT_EQ(error, "");
  return bytes;
}

// A datagram socket of the test's on a loopback address and an ephemeral port.
class Peer {
 public:
  explicit Peer(int family = AF_INET)
      : family_(family), fd_(::socket(family, SOCK_DGRAM | SOCK_CLOEXEC, 0)) {
    sockaddr_storage address = Loopback(0);
    ok_ = fd_.get() >= 0 && ::bind(fd_.get(), reinterpret_cast<sockaddr*>(&address), Length()) == 0;
    socklen_t length = sizeof(address);
    ::getsockname(fd_.get(), reinterpret_cast<sockaddr*>(&address), &length);
    port_ = ntohs(family == AF_INET6 ? reinterpret_cast<sockaddr_in6*>(&address)->sin6_port
                                     : reinterpret_cast<sockaddr_in*>(&address)->sin_port);
  }

  bool ok() const { return ok_; }
  int port() const { return port_; }

  void SendTo(int port, const Bytes& bytes) const {
    sockaddr_storage to = Loopback(port);
    ASSERT_EQ(::sendto(fd_.get(), bytes.data(), bytes.size(), 0, reinterpret_cast<sockaddr*>(&to),
                       Length()),
              static_cast<ssize_t>(bytes.size()))
        << std::strerror(errno);
  }

  // The next datagram within the timeout and the port it came from; nullopt on timeout.
  std::optional<std::pair<Bytes, int>> Receive(milliseconds timeout = kEventTimeout) const {
    pollfd p{fd_.get(), POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(timeout.count())) != 1) return std::nullopt;
    Bytes bytes(65536);
    sockaddr_storage from{};
    socklen_t length = sizeof(from);
    const ssize_t n = ::recvfrom(fd_.get(), bytes.data(), bytes.size(), 0,
                                 reinterpret_cast<sockaddr*>(&from), &length);
    if (n < 0) return std::nullopt;
    bytes.resize(static_cast<std::size_t>(n));
    const int port =
        ntohs(from.ss_family == AF_INET6 ? reinterpret_cast<sockaddr_in6*>(&from)->sin6_port
                                         : reinterpret_cast<sockaddr_in*>(&from)->sin_port);
    return std::make_pair(std::move(bytes), port);
  }

  // Whether a datagram is queued now (no wait).
  bool HasPending() const {
    uint8_t byte = 0;
    return ::recv(fd_.get(), &byte, 1, MSG_PEEK | MSG_DONTWAIT) >= 0;
  }

 private:
  sockaddr_storage Loopback(int port) const {
    sockaddr_storage address{};
    if (family_ == AF_INET6) {
      auto* in6 = reinterpret_cast<sockaddr_in6*>(&address);
      in6->sin6_family = AF_INET6;
      in6->sin6_addr = in6addr_loopback;
      in6->sin6_port = htons(static_cast<uint16_t>(port));
    } else {
      auto* in = reinterpret_cast<sockaddr_in*>(&address);
      in->sin_family = AF_INET;
      in->sin_addr.s_addr = htonl(INADDR_LOOPBACK);
      in->sin_port = htons(static_cast<uint16_t>(port));
    }
    return address;
  }
  socklen_t Length() const {
    return family_ == AF_INET6 ? sizeof(sockaddr_in6) : sizeof(sockaddr_in);
  }

  int family_;
  ScopedFd fd_;
  bool ok_ = false;
  int port_ = 0;
};

std::unique_ptr<Link> Open(const LinkUrl& url) {
  std::string error;
  std::unique_ptr<Link> link = OpenLink(url, error);
  EXPECT_NE(link, nullptr) << error;
  EXPECT_EQ(error, "");
  return link;
}

std::string OpenError(const LinkUrl& url) {
  std::string error;
  EXPECT_EQ(OpenLink(url, error), nullptr);
  return error;
}

LinkUrl Parsed(const std::string& text) {
  LinkUrl url;
  EXPECT_EQ(ParseLinkUrl(text, url), "") << text;
  EXPECT_EQ(url.text, text);
  return url;
}

std::string ParseError(const std::string& text) {
  LinkUrl url;
  return ParseLinkUrl(text, url);
}

TEST(ParseLinkUrl, TakesUdpWithNamesAndAddresses) {
  LinkUrl url = Parsed("udp://127.0.0.1:14540");
  EXPECT_EQ(url.kind, LinkUrl::Kind::kUdpOut);
  EXPECT_EQ(url.host, "127.0.0.1");
  EXPECT_EQ(url.port, 14540);

  url = Parsed("udp://px4-sitl.local:1");
  EXPECT_EQ(url.host, "px4-sitl.local");
  EXPECT_EQ(url.port, 1);

  url = Parsed("udp://[::1]:65535");
  EXPECT_EQ(url.host, "::1") << "kept without its brackets";
  EXPECT_EQ(url.port, 65535);

  url = Parsed("udp://[fe80::1%eth0]:14540");
  EXPECT_EQ(url.host, "fe80::1%eth0");

  url = Parsed("udpin://0.0.0.0:14550");
  EXPECT_EQ(url.kind, LinkUrl::Kind::kUdpIn);
  EXPECT_EQ(url.host, "0.0.0.0");
  EXPECT_EQ(url.port, 14550);

  url = Parsed("udpin://localhost:14550");
  EXPECT_EQ(url.host, "localhost");
}

TEST(ParseLinkUrl, TakesSerialWithAndWithoutRate) {
  LinkUrl url = Parsed("serial:///dev/ttyACM0:921600");
  EXPECT_EQ(url.kind, LinkUrl::Kind::kSerial);
  EXPECT_EQ(url.device, "/dev/ttyACM0");
  EXPECT_EQ(url.baud, 921600);

  url = Parsed("serial:///dev/ttyUSB0");
  EXPECT_EQ(url.device, "/dev/ttyUSB0");
  EXPECT_EQ(url.baud, kDefaultSerialBaud);
  EXPECT_EQ(kDefaultSerialBaud, 57600);

  // A ':' in the file name is the device's when the rate follows it.
  url = Parsed("serial:///dev/serial/by-path/pci-0000:00:14.0-usb-0:1:1.0-port0:115200");
  EXPECT_EQ(url.device, "/dev/serial/by-path/pci-0000:00:14.0-usb-0:1:1.0-port0");
  EXPECT_EQ(url.baud, 115200);

  // Directories with a ':' and no rate.
  url = Parsed("serial:///dev/odd:dir/ttyS0");
  EXPECT_EQ(url.device, "/dev/odd:dir/ttyS0");
  EXPECT_EQ(url.baud, kDefaultSerialBaud);

  ASSERT_EQ(SerialBaudRates().size(), 18U);
  for (const int rate : SerialBaudRates()) {
    EXPECT_EQ(Parsed("serial:///dev/ttyS0:" + std::to_string(rate)).baud, rate);
  }
}

TEST(ParseLinkUrl, FormatReadsBack) {
  for (const std::string text :
       {"udp://127.0.0.1:14540", "udp://[::1]:14540", "udpin://0.0.0.0:14550",
        "udp://px4.local:14540", "serial:///dev/ttyACM0:921600"}) {
    EXPECT_EQ(FormatLinkUrl(Parsed(text)), text);
  }
  EXPECT_EQ(FormatLinkUrl(Parsed("serial:///dev/ttyUSB0")), "serial:///dev/ttyUSB0:57600");
}

struct BadUrl {
  std::string url;
  std::string message;
};

TEST(ParseLinkUrl, RefusesEachBadFormWithItsMessage) {
  const std::string no_host_udp =
      " has no host (udp://HOST:PORT; HOST is a name, an IPv4 address or a bracketed IPv6 "
      "address such as [::1])";
  const std::string port_range = " is not a whole number in 1..65535";
  const std::vector<BadUrl> cases = {
      {"127.0.0.1:14540", "--link: \"127.0.0.1:14540\" has no scheme" + std::string(kForms)},
      {"", "--link: \"\" has no scheme" + std::string(kForms)},
      {"tcp://host:5760", "--link: unknown scheme \"tcp\"" + std::string(kForms)},
      {"UDP://host:14540", "--link: unknown scheme \"UDP\"" + std::string(kForms)},
      {"udp://host",
       "--link: \"udp://host\" has no port (udp://HOST:PORT, as in udp://127.0.0.1:14540)"},
      {"udp://host:",
       "--link: \"udp://host:\" has no port (udp://HOST:PORT, as in udp://127.0.0.1:14540)"},
      {"udpin://0.0.0.0",
       "--link: \"udpin://0.0.0.0\" has no port (udpin://ADDR:PORT, as in "
       "udpin://0.0.0.0:14550)"},
      {"udp://[::1]",
       "--link: \"udp://[::1]\" has no port (udp://HOST:PORT, as in udp://127.0.0.1:14540)"},
      {"udp://host:0", "--link: port \"0\" in \"udp://host:0\"" + port_range},
      {"udp://host:65536", "--link: port \"65536\" in \"udp://host:65536\"" + port_range},
      {"udp://host:abc", "--link: port \"abc\" in \"udp://host:abc\"" + port_range},
      {"udp://host:-1", "--link: port \"-1\" in \"udp://host:-1\"" + port_range},
      {"udp://host:+5", "--link: port \"+5\" in \"udp://host:+5\"" + port_range},
      {"udp://host:14540/", "--link: port \"14540/\" in \"udp://host:14540/\"" + port_range},
      {"udp://host:99999999999999999999",
       "--link: port \"99999999999999999999\" in \"udp://host:99999999999999999999\"" + port_range},
      {"udp://:14540", "--link: \"udp://:14540\"" + no_host_udp},
      {"udp://[]:14540", "--link: \"udp://[]:14540\"" + no_host_udp},
      {"udpin://:14550",
       "--link: \"udpin://:14550\" has no address (udpin://ADDR:PORT; udpin://0.0.0.0:PORT "
       "listens on every interface)"},
      {"udp://::1:14540",
       "--link: \"udp://::1:14540\": put an IPv6 address in brackets, as in "
       "udp://[::1]:14540"},
      {"udp://[::1:14540",
       "--link: \"udp://[::1:14540\" opens a '[' it does not close (udp://HOST:PORT, as in "
       "udp://[::1]:14540)"},
      {"udp://[px4]:14540", "--link: \"px4\" in \"udp://[px4]:14540\" is not an IPv6 address"},
      {"udp://[::1]14540",
       "--link: \"udp://[::1]14540\" has \"14540\" after ']' where ':PORT' belongs"},
      {"udp://user@host:14540",
       "--link: host \"user@host\" in \"udp://user@host:14540\" is not a name, an IPv4 address "
       "or a bracketed IPv6 address such as [::1]"},
      {std::string("udp://a\x01\"b:1"),
       "--link: host \"a\\x01\\\"b\" in \"udp://a\\x01\\\"b:1\" is not a name, an IPv4 address "
       "or a bracketed IPv6 address such as [::1]"},
      {"serial:///dev/ttyUSB0:12345",
       "--link: baud rate \"12345\" in "
       "\"serial:///dev/ttyUSB0:12345\" is not one of " +
           std::string(kRates)},
      {"serial:///dev/ttyUSB0:",
       "--link: baud rate \"\" in \"serial:///dev/ttyUSB0:\" is not one "
       "of " +
           std::string(kRates)},
      {"serial:///dev/ttyUSB0:fast",
       "--link: baud rate \"fast\" in \"serial:///dev/ttyUSB0:fast\" is not one of " +
           std::string(kRates) +
           " (a device whose file name holds a ':' must be given its rate after it)"},
      {"serial://",
       "--link: \"serial://\" has no device (serial://DEVICE:BAUD, as in "
       "serial:///dev/ttyACM0:921600)"},
      {"serial://:921600",
       "--link: \"serial://:921600\" has no device (serial://DEVICE:BAUD, as in "
       "serial:///dev/ttyACM0:921600)"},
      {"serial://dev/ttyUSB0:57600",
       "--link: device \"dev/ttyUSB0\" in \"serial://dev/ttyUSB0:57600\" is not an absolute path "
       "(the path keeps its '/' after serial://: serial://DEVICE:BAUD, as in "
       "serial:///dev/ttyACM0:921600)"},
  };
  for (const BadUrl& c : cases) EXPECT_EQ(ParseError(c.url), c.message) << c.url;
}

TEST(UdpOut, SendsToTheHostAndReceivesTheReply) {
  Peer autopilot;
  ASSERT_TRUE(autopilot.ok());
  const std::unique_ptr<Link> link =
      Open(Parsed("udp://127.0.0.1:" + std::to_string(autopilot.port())));
  ASSERT_NE(link, nullptr);
  EXPECT_TRUE(link->HasPeer());
  ASSERT_GT(link->LocalPort(), 0);
  EXPECT_EQ(link->Describe(), "udp://127.0.0.1:" + std::to_string(autopilot.port()) +
                                  " (from 0.0.0.0:" + std::to_string(link->LocalPort()) + ")");

  const Bytes sent = EveryByteValue();
  ASSERT_EQ(link->Send(sent), "");
  const auto got = autopilot.Receive();
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(got->first, sent) << "one datagram, every byte value as it was";
  EXPECT_EQ(got->second, link->LocalPort()) << "sent from the port Describe() names";

  autopilot.SendTo(got->second, Text("reply"));
  EXPECT_EQ(ReceiveSome(*link), Text("reply"));
  EXPECT_EQ(link->Send({}), "") << "nothing to send";
}

TEST(UdpOut, ReceivesFromAnySender) {
  Peer autopilot;
  Peer other;
  ASSERT_TRUE(autopilot.ok() && other.ok());
  const std::unique_ptr<Link> link =
      Open(Parsed("udp://127.0.0.1:" + std::to_string(autopilot.port())));
  ASSERT_NE(link, nullptr);
  other.SendTo(link->LocalPort(), Text("from elsewhere"));
  EXPECT_EQ(ReceiveSome(*link), Text("from elsewhere"));
  ASSERT_EQ(link->Send(Text("still to the autopilot")), "");
  const auto got = autopilot.Receive();
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(got->first, Text("still to the autopilot"));
  EXPECT_FALSE(other.HasPending());
}

TEST(UdpOut, TakesANameAsItsIpv4Address) {
  Peer autopilot;  // on 127.0.0.1 only
  ASSERT_TRUE(autopilot.ok());
  const std::unique_ptr<Link> link =
      Open(Parsed("udp://localhost:" + std::to_string(autopilot.port())));
  ASSERT_NE(link, nullptr);
  EXPECT_EQ(link->Describe(), "udp://127.0.0.1:" + std::to_string(autopilot.port()) +
                                  " (localhost, from 0.0.0.0:" + std::to_string(link->LocalPort()) +
                                  ")");
  ASSERT_EQ(link->Send(Text("hi")), "");
  const auto got = autopilot.Receive();
  ASSERT_TRUE(got.has_value()) << "localhost must be 127.0.0.1, where PX4 listens";
  EXPECT_EQ(got->first, Text("hi"));
}

TEST(UdpOut, CarriesIpv6) {
  Peer autopilot(AF_INET6);
  if (!autopilot.ok()) GTEST_SKIP() << "no IPv6 loopback here";
  const std::unique_ptr<Link> link =
      Open(Parsed("udp://[::1]:" + std::to_string(autopilot.port())));
  ASSERT_NE(link, nullptr);
  EXPECT_EQ(link->Describe(), "udp://[::1]:" + std::to_string(autopilot.port()) +
                                  " (from [::]:" + std::to_string(link->LocalPort()) + ")");
  ASSERT_EQ(link->Send(Text("six")), "");
  const auto got = autopilot.Receive();
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(got->first, Text("six"));
  autopilot.SendTo(got->second, Text("back"));
  EXPECT_EQ(ReceiveSome(*link), Text("back"));
}

TEST(UdpOut, NamesAHostThatDoesNotResolve) {
  // .invalid never resolves (RFC 6761).
  const std::string error = OpenError(Parsed("udp://stevi-no-such-host.invalid:14540"));
  EXPECT_THAT(error, StartsWith("udp://stevi-no-such-host.invalid:14540: cannot resolve host "
                                "\"stevi-no-such-host.invalid\": "));
}

TEST(UdpOut, RefusesPortZero) {
  EXPECT_EQ(OpenError({.kind = LinkUrl::Kind::kUdpOut, .host = "127.0.0.1", .port = 0}),
            "udp://127.0.0.1:0: port 0 is not in 1..65535");
}

LinkUrl Listen(int port = 0) {
  return {.kind = LinkUrl::Kind::kUdpIn, .host = "127.0.0.1", .port = port};
}

TEST(UdpIn, SendsToWhoeverSpokeLast) {
  const std::unique_ptr<Link> link = Open(Listen());
  ASSERT_NE(link, nullptr);
  const int port = link->LocalPort();
  ASSERT_GT(port, 0);
  const std::string here = "udpin://127.0.0.1:" + std::to_string(port);
  EXPECT_FALSE(link->HasPeer());
  EXPECT_EQ(link->Describe(), here + " (no peer yet)");
  EXPECT_EQ(link->Send(Text("too early")), "no peer yet");

  Peer first;
  Peer second;
  ASSERT_TRUE(first.ok() && second.ok());
  first.SendTo(port, Text("one"));
  EXPECT_EQ(ReceiveSome(*link), Text("one"));
  EXPECT_TRUE(link->HasPeer());
  EXPECT_EQ(link->Describe(), here + " (peer 127.0.0.1:" + std::to_string(first.port()) + ")");
  ASSERT_EQ(link->Send(Text("to one")), "");
  auto got = first.Receive();
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(got->first, Text("to one"));
  EXPECT_EQ(got->second, port);

  second.SendTo(port, Text("two"));
  EXPECT_EQ(ReceiveSome(*link), Text("two"));
  EXPECT_EQ(link->Describe(), here + " (peer 127.0.0.1:" + std::to_string(second.port()) + ")");
  ASSERT_EQ(link->Send(Text("to two")), "");
  got = second.Receive();
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(got->first, Text("to two"));
  EXPECT_FALSE(first.HasPending()) << "the first peer is no longer the destination";
}

TEST(UdpIn, NamesAnAddressInUse) {
  Peer taken;
  ASSERT_TRUE(taken.ok());
  const std::string port = std::to_string(taken.port());
  EXPECT_EQ(OpenError(Parsed("udpin://127.0.0.1:" + port)),
            "udpin://127.0.0.1:" + port + ": cannot listen on 127.0.0.1:" + port +
                ": Address already in use");
}

TEST(UdpIn, TruncatesADatagramToTheBuffer) {
  const std::unique_ptr<Link> link = Open(Listen());
  ASSERT_NE(link, nullptr);
  Peer peer;
  ASSERT_TRUE(peer.ok());
  Bytes big(3000);
  for (std::size_t i = 0; i < big.size(); ++i) big[i] = static_cast<uint8_t>(i * 7);
  peer.SendTo(link->LocalPort(), big);
  std::array<uint8_t, kLinkBufferBytes> buffer{};
  std::string error;
  int n = 0;
  const steady_clock::time_point deadline = steady_clock::now() + kEventTimeout;
  while (n == 0 && steady_clock::now() < deadline) n = link->Receive(buffer, kEventTimeout, error);
  ASSERT_EQ(n, static_cast<int>(kLinkBufferBytes)) << error;
  EXPECT_TRUE(std::equal(buffer.begin(), buffer.end(), big.begin()));
}

// The bridge's shape: a reader thread in Receive while a writer thread sends.
TEST(Link, SendsWhileAnotherThreadReceives) {
  const std::unique_ptr<Link> link = Open(Listen());
  ASSERT_NE(link, nullptr);
  Peer peer;
  ASSERT_TRUE(peer.ok());
  constexpr int kCount = 50;
  std::promise<void> first_heard;
  std::future<std::vector<Bytes>> heard = std::async(std::launch::async, [&] {
    std::vector<Bytes> out;
    std::string error;
    while (out.size() < kCount) {
      Bytes bytes = ReceiveSome(*link, error);
      if (bytes.empty()) break;
      out.push_back(std::move(bytes));
      if (out.size() == 1) first_heard.set_value();
    }
    return out;
  });
  peer.SendTo(link->LocalPort(), Text("0"));
  ASSERT_EQ(first_heard.get_future().wait_for(kEventTimeout), std::future_status::ready);
  for (int i = 1; i < kCount; ++i) {
    peer.SendTo(link->LocalPort(), Text(std::to_string(i)));
    ASSERT_EQ(link->Send(Text("reply " + std::to_string(i))), "");
    const auto got = peer.Receive();
    ASSERT_TRUE(got.has_value()) << i;
    EXPECT_EQ(got->first, Text("reply " + std::to_string(i)));
  }
  const std::vector<Bytes> received = heard.get();
  ASSERT_EQ(received.size(), static_cast<std::size_t>(kCount));
  for (int i = 0; i < kCount; ++i) EXPECT_EQ(received[i], Text(std::to_string(i)));
}

// Starts a Receive with a 10 s timeout in another thread, checks that it waits, interrupts it and
// returns how long it took to return after the interrupt.
milliseconds InterruptBlockedReceive(Link& link) {
  std::future<int> receiving = std::async(std::launch::async, [&link] {
    std::array<uint8_t, 64> buffer{};
    std::string error;
    const int n = link.Receive(buffer, seconds(10), error);
    EXPECT_EQ(error, "");
    return n;
  });
  // Not a synchronisation: asserts that Receive does wait (an interrupt sent before it starts
  // would wake it too).
  EXPECT_EQ(receiving.wait_for(milliseconds(100)), std::future_status::timeout);
  const steady_clock::time_point start = steady_clock::now();
  link.Interrupt();
  EXPECT_EQ(receiving.wait_for(kEventTimeout), std::future_status::ready);
  const auto took = std::chrono::duration_cast<milliseconds>(steady_clock::now() - start);
  EXPECT_EQ(receiving.get(), 0);
  return took;
}

TEST(Interrupt, WakesABlockedUdpReceivePromptly) {
  const std::unique_ptr<Link> link = Open(Listen());
  ASSERT_NE(link, nullptr);
  EXPECT_LT(InterruptBlockedReceive(*link), milliseconds(1000));
}

TEST(Interrupt, BeforeReceiveWakesTheNextOneOnly) {
  const std::unique_ptr<Link> link = Open(Listen());
  ASSERT_NE(link, nullptr);
  link->Interrupt();
  link->Interrupt();  // counts as one with the first
  std::array<uint8_t, 64> buffer{};
  std::string error;
  const steady_clock::time_point start = steady_clock::now();
  EXPECT_EQ(link->Receive(buffer, seconds(10), error), 0);
  EXPECT_LT(steady_clock::now() - start, milliseconds(1000));
  // Taken: the next Receive waits for data again.
  Peer peer;
  ASSERT_TRUE(peer.ok());
  peer.SendTo(link->LocalPort(), Text("after"));
  EXPECT_EQ(ReceiveSome(*link), Text("after"));
}

// A pseudo-terminal: the master stays with the test, the slave is the link's device.
struct Pty {
  ScopedFd master;
  std::string slave;
};

std::unique_ptr<Pty> OpenPty() {
  auto pty = std::make_unique<Pty>();
  const int master = ::posix_openpt(O_RDWR | O_NOCTTY | O_CLOEXEC);
  if (master < 0) return nullptr;
  pty->master.Reset(master);
  std::array<char, 128> name{};
  if (::grantpt(master) != 0 || ::unlockpt(master) != 0 ||
      ::ptsname_r(master, name.data(), name.size()) != 0) {
    return nullptr;
  }
  pty->slave = name.data();
  return pty;
}

LinkUrl Serial(const std::string& device, int baud = 115200) {
  return {.kind = LinkUrl::Kind::kSerial, .device = device, .baud = baud};
}

// Reads `count` bytes from the master within the timeout.
Bytes ReadMaster(int master, std::size_t count) {
  Bytes out;
  const steady_clock::time_point deadline = steady_clock::now() + kEventTimeout;
  while (out.size() < count && steady_clock::now() < deadline) {
    pollfd p{master, POLLIN, 0};
    if (::poll(&p, 1, 100) != 1) continue;
    std::array<uint8_t, 512> buffer{};
    const ssize_t n = ::read(master, buffer.data(), buffer.size());
    if (n <= 0) break;
    out.insert(out.end(), buffer.begin(), buffer.begin() + n);
  }
  return out;
}

TEST(Serial, CarriesEveryByteValueBothWaysRaw) {
  const std::unique_ptr<Pty> pty = OpenPty();
  ASSERT_NE(pty, nullptr) << std::strerror(errno);
  const std::unique_ptr<Link> link = Open(Serial(pty->slave));
  ASSERT_NE(link, nullptr);
  EXPECT_EQ(link->Describe(), "serial://" + pty->slave + ":115200");
  EXPECT_TRUE(link->HasPeer());
  EXPECT_EQ(link->LocalPort(), 0);

  // The slave's settings, as the master sees them.
  termios tio{};
  ASSERT_EQ(::tcgetattr(pty->master.get(), &tio), 0);
  EXPECT_EQ(::cfgetospeed(&tio), static_cast<speed_t>(B115200));
  EXPECT_EQ(::cfgetispeed(&tio), static_cast<speed_t>(B115200));
  EXPECT_EQ(tio.c_cflag & CSIZE, static_cast<tcflag_t>(CS8));
  EXPECT_EQ(tio.c_cflag & (PARENB | CSTOPB | CRTSCTS), 0U) << "8N1, no hardware flow control";
  EXPECT_EQ(tio.c_cflag & (CLOCAL | CREAD), static_cast<tcflag_t>(CLOCAL | CREAD));
  EXPECT_EQ(tio.c_iflag & (IXON | IXOFF | ICRNL | INLCR | ISTRIP), 0U);
  EXPECT_EQ(tio.c_oflag & OPOST, 0U);
  EXPECT_EQ(tio.c_lflag & (ICANON | ECHO | ISIG | IEXTEN), 0U);
  EXPECT_EQ(tio.c_cc[VMIN], 1);
  EXPECT_EQ(tio.c_cc[VTIME], 0);

  // In: every byte value (NUL, CR, LF, XON, XOFF, ^C, ^D, DEL, 0xFF among them) as it was.
  const Bytes all = EveryByteValue();
  ASSERT_EQ(::write(pty->master.get(), all.data(), all.size()), static_cast<ssize_t>(all.size()));
  Bytes got;
  std::string error;
  while (got.size() < all.size()) {
    const Bytes part = ReceiveSome(*link, error);
    ASSERT_FALSE(part.empty()) << "after " << got.size() << " bytes: " << error;
    got.insert(got.end(), part.begin(), part.end());
  }
  EXPECT_EQ(got, all);

  // Out: the same, twice, in one Send.
  Bytes twice = all;
  twice.insert(twice.end(), all.begin(), all.end());
  ASSERT_EQ(link->Send(twice), "");
  EXPECT_EQ(ReadMaster(pty->master.get(), twice.size()), twice);
}

TEST(Serial, RefusesABadBaud) {
  const std::unique_ptr<Pty> pty = OpenPty();
  ASSERT_NE(pty, nullptr);
  EXPECT_EQ(
      OpenError(Serial(pty->slave, 12345)),
      "serial://" + pty->slave + ":12345: baud rate 12345 is not one of " + std::string(kRates));
  EXPECT_THAT(ParseError("serial://" + pty->slave + ":12345"), HasSubstr("is not one of 9600"));
}

TEST(Serial, NamesAMissingDeviceAndTheOsError) {
  EXPECT_EQ(OpenError(Parsed("serial:///dev/stevi-no-such-tty:921600")),
            "serial:///dev/stevi-no-such-tty:921600: cannot open /dev/stevi-no-such-tty: No such "
            "file or directory");
}

TEST(Serial, RefusesAFileThatIsNotATerminal) {
  EXPECT_EQ(OpenError(Serial("/dev/null")),
            "serial:///dev/null:115200: not a serial device: Inappropriate ioctl for device");
}

TEST(Serial, RefusesADeviceAnotherLinkHolds) {
  const std::unique_ptr<Pty> pty = OpenPty();
  ASSERT_NE(pty, nullptr);
  const std::unique_ptr<Link> link = Open(Serial(pty->slave));
  ASSERT_NE(link, nullptr);
  EXPECT_EQ(OpenError(Serial(pty->slave)),
            "serial://" + pty->slave + ":115200: in use by another process (flock)");
}

// Linux hangs the slave up when the master closes (pty_close calls tty_vhangup): poll reports
// POLLIN|POLLERR|POLLHUP, read returns 0 (EIO on older kernels) and write fails with EIO. A USB
// adapter unplugged is hung up the same way.
TEST(Serial, ReportsTheDeviceGoneWhenTheMasterCloses) {
  const std::unique_ptr<Pty> pty = OpenPty();
  ASSERT_NE(pty, nullptr);
  const std::unique_ptr<Link> link = Open(Serial(pty->slave));
  ASSERT_NE(link, nullptr);
  pty->master.Close();
  std::array<uint8_t, kLinkBufferBytes> buffer{};
  std::string error;
  const steady_clock::time_point start = steady_clock::now();
  EXPECT_EQ(link->Receive(buffer, seconds(10), error), -1);
  EXPECT_LT(steady_clock::now() - start, milliseconds(1000));
  EXPECT_THAT(error, StartsWith("serial://" + pty->slave + ":115200: device gone ("));
  EXPECT_THAT(link->Send(Text("anyone?")), StartsWith("write: Input/output error"));
}

TEST(Serial, SendGivesUpWhenTheDeviceTakesNoMore) {
  const std::unique_ptr<Pty> pty = OpenPty();
  ASSERT_NE(pty, nullptr);
  const std::unique_ptr<Link> link = Open(Serial(pty->slave));
  ASSERT_NE(link, nullptr);
  // Nobody reads the master: the pty's buffers fill and the rest waits for the bound (1 s).
  const Bytes flood(1 << 20, 0x55);
  const steady_clock::time_point start = steady_clock::now();
  const std::string error = link->Send(flood);
  const auto took = steady_clock::now() - start;
  EXPECT_THAT(error, ::testing::MatchesRegex(
                         "wrote [0-9]+ of 1048576 bytes: the device took no more within 1000 ms"));
  EXPECT_GE(took, milliseconds(900));
  EXPECT_LT(took, milliseconds(5000));
}

TEST(Serial, InterruptWakesABlockedReceivePromptly) {
  const std::unique_ptr<Pty> pty = OpenPty();
  ASSERT_NE(pty, nullptr);
  const std::unique_ptr<Link> link = Open(Serial(pty->slave));
  ASSERT_NE(link, nullptr);
  EXPECT_LT(InterruptBlockedReceive(*link), milliseconds(1000));
}

// The descriptors open in this process, each with whether it is close-on-exec.
std::map<int, bool> OpenDescriptors() {
  std::map<int, bool> out;
  DIR* dir = ::opendir("/proc/self/fd");
  if (dir == nullptr) return out;
  while (const dirent* entry = ::readdir(dir)) {
    const int fd = std::atoi(entry->d_name);
    if (entry->d_name[0] == '.' || fd == ::dirfd(dir)) continue;
    out[fd] = (::fcntl(fd, F_GETFD) & FD_CLOEXEC) != 0;
  }
  ::closedir(dir);
  return out;
}

TEST(OpenLink, HoldsCloseOnExecDescriptorsAndClosesThemAll) {
  const std::unique_ptr<Pty> pty = OpenPty();
  ASSERT_NE(pty, nullptr);
  const std::map<int, bool> before = OpenDescriptors();
  ASSERT_FALSE(before.empty()) << "no /proc/self/fd";
  {
    Peer autopilot;
    ASSERT_TRUE(autopilot.ok());
    const std::map<int, bool> with_peer = OpenDescriptors();
    const std::unique_ptr<Link> out = Open(Parsed("udp://127.0.0.1:14540"));
    const std::unique_ptr<Link> in = Open(Listen());
    const std::unique_ptr<Link> serial = Open(Serial(pty->slave));
    ASSERT_TRUE(out != nullptr && in != nullptr && serial != nullptr);
    const std::map<int, bool> during = OpenDescriptors();
    EXPECT_EQ(during.size(), with_peer.size() + 6) << "a socket or device and an eventfd each";
    for (const auto& [fd, cloexec] : during) {
      if (with_peer.count(fd) == 0) {
        EXPECT_TRUE(cloexec) << "descriptor " << fd;
      }
    }
    // Failures leave nothing behind either.
    EXPECT_NE(OpenError(Serial(pty->slave)), "");
    EXPECT_NE(OpenError(Serial("/dev/null")), "");
    EXPECT_NE(OpenError(Parsed("udpin://127.0.0.1:" + std::to_string(autopilot.port()))), "");
    EXPECT_EQ(OpenDescriptors(), during);
  }
  EXPECT_EQ(OpenDescriptors(), before);
}

}  // namespace
}  // namespace stevi::client::mavlink
