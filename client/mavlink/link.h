// The byte links of the MAVLink bridge (`stevi mavlink`): UDP to an autopilot, UDP from one, and a
// serial device. A link carries raw bytes; MAVLink frames are encoded and checked elsewhere
// (codec.h), so whatever arrives is handed up unjudged. The standard library and POSIX (Linux)
// only.
//
// The forms of --link:
// - udp://HOST:PORT sends to HOST:PORT from an ephemeral local port and receives whatever comes
//   back to that port, from any sender. PX4 SITL and companion computers listen on 14540.
// - udpin://ADDR:PORT listens on ADDR:PORT (0.0.0.0: every interface) and sends to whoever spoke
//   last. Anyone who can reach the port can take the destination over, as with every MAVLink UDP
//   server.
// - serial://DEVICE:BAUD, as in serial:///dev/ttyACM0:921600 (the path keeps its leading '/'),
//   or serial://DEVICE at kDefaultSerialBaud. Raw 8N1, no flow control.
// HOST and ADDR are a name, an IPv4 address or a bracketed IPv6 address ([::1]). A name with both
// IPv4 and IPv6 addresses ("localhost") is taken as its IPv4 one, as PX4 and ArduPilot listen on
// IPv4; write [::1] for IPv6.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>

namespace stevi::client::mavlink {

// What --link names.
struct LinkUrl {
  enum class Kind { kUdpOut, kUdpIn, kSerial };
  Kind kind = Kind::kUdpOut;
  // UDP: a name, an IPv4 address or an IPv6 address without its brackets ("::1").
  std::string host{};
  // UDP: 1..65535 from the parser. OpenLink also takes 0 for udpin (an ephemeral port, which
  // LocalPort() reports: for tests).
  int port = 0;
  // Serial: an absolute path ("/dev/ttyACM0").
  std::string device{};
  // Serial: bits per second, one of SerialBaudRates().
  int baud = 0;
  // The URL as the user wrote it, for messages; OpenLink writes the canonical form when empty.
  std::string text{};
};

// Serial without a rate: 57600, the rate of SiK telemetry radios and the default of the PX4 and
// ArduPilot TELEM ports. (A USB CDC-ACM port, /dev/ttyACM*, ignores the rate.)
inline constexpr int kDefaultSerialBaud = 57600;

// The receive buffer the bridge uses, in bytes. A MAVLink frame is at most 280 bytes; a UDP
// datagram longer than the buffer is cut to its size by the kernel (the codec resynchronises).
inline constexpr std::size_t kLinkBufferBytes = 2048;

// The serial rates accepted, in bits per second, ascending: Linux's termios rates from B9600 to
// B4000000 (9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000, 576000, 921600, 1000000,
// 1152000, 1500000, 2000000, 2500000, 3000000, 3500000, 4000000).
std::span<const int> SerialBaudRates();

// Reads a --link value into `out` (text set to `url`). "" when fine, else a message that names
// the problem and the accepted forms, e.g. `--link: unknown scheme "tcp" (use udp://HOST:PORT,
// udpin://ADDR:PORT or serial://DEVICE:BAUD)`. Text from the user is quoted with control bytes
// escaped. A serial device's rate is the text after its last ':' when that ':' follows the last
// '/': a device whose file name holds a ':' (/dev/serial/by-path/...) must be given its rate.
std::string ParseLinkUrl(const std::string& url, LinkUrl& out);

// The canonical text of a URL: "udp://[::1]:14540", "serial:///dev/ttyACM0:921600".
std::string FormatLinkUrl(const LinkUrl& url);

// A link's two directions. Thread safety: Send may be called from any thread (calls are
// serialised), Receive from one thread at a time, concurrently with Send; Interrupt, Describe,
// HasPeer and LocalPort from any thread. Destroy the link only after those threads are done.
// Only a Receive that returns -1 means the link is dead: a failed Send concerns those bytes alone.
class Link {
 public:
  virtual ~Link() = default;

  // Sends one datagram (UDP) or writes all the bytes (serial). "" when sent, else why not:
  // - udpin before anyone has spoken: "no peer yet" (check HasPeer() first);
  // - UDP: the kernel's refusal, e.g. a full send buffer or an unreachable network (the datagram
  //   is dropped; the socket never blocks);
  // - serial: the device gone (EIO), or "wrote N of M bytes" when the device has not taken them
  //   all within one second (the rest is dropped mid-frame; the receiver's codec resynchronises).
  // Empty bytes send nothing and return "".
  virtual std::string Send(std::span<const uint8_t> bytes) = 0;

  // Waits up to `timeout` (negative: 0) for bytes and reads them into `buffer`: one datagram
  // (cut to the buffer's size) or what the serial device holds. Returns how many were read; 0 on
  // timeout, on Interrupt(), on a signal, for an empty datagram or a transient UDP error; -1
  // with `error` set when the link is dead (the serial device gone, a socket error).
  virtual int Receive(std::span<uint8_t> buffer, std::chrono::milliseconds timeout,
                      std::string& error) = 0;

  // Wakes the Receive waiting in another thread, or the next one to start when none is waiting:
  // it returns 0 at once. Interrupts not yet taken by a Receive count as one. Set the reader's
  // stop flag before calling this. Never blocks.
  virtual void Interrupt() = 0;

  // For logs: "udp://127.0.0.1:14540 (from 0.0.0.0:40123)" (a name given is kept in the
  // parentheses: "(localhost, from ...)"), "udpin://0.0.0.0:14550 (peer 127.0.0.1:5000)" or
  // "(no peer yet)", "serial:///dev/ttyACM0:921600".
  virtual std::string Describe() const = 0;

  // Whether Send has somewhere to send: udpin once a peer has spoken; always for the others.
  virtual bool HasPeer() const = 0;

  // The local UDP port bound (udp: the ephemeral source port; udpin: the port listened on);
  // 0 for serial.
  virtual int LocalPort() const = 0;
};

// Opens the link: resolves the host, binds the socket; or opens the serial device (O_NOCTTY,
// non-blocking), locks it against other users of flock(2) and sets it up with termios. nullptr
// with `error` naming the URL and the problem (the OS error's text included) on failure, e.g.
// `serial:///dev/ttyACM9:921600: cannot open /dev/ttyACM9: No such file or directory`.
// Every descriptor is close-on-exec and closed by the link's destructor.
std::unique_ptr<Link> OpenLink(const LinkUrl& url, std::string& error);

}  // namespace stevi::client::mavlink
