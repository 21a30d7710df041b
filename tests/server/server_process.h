// The real binaries in tests: a stevi-server child process on a loopback port, `stevi` commands
// against it, and JSON-lines parsing of their output.
#pragma once

#include <google/protobuf/util/json_util.h>
#include <gtest/gtest.h>

#include <chrono>
#include <memory>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "tests/testing/data.h"
#include "tests/testing/sanitized.h"
#include "tests/testing/subprocess.h"

namespace stevi::testing {

// How long a `stevi` command may take: instrumented under a sanitizer, both it and the server
// run several times slower (as ctest's timeouts are scaled in deploy/sanitize.sh).
inline constexpr std::chrono::seconds kCommandTimeout{kSanitized ? 300 : 60};

// One message per non-empty line; a line that does not parse fails the test.
template <typename Message>
std::vector<Message> ParseJsonLines(const std::string& text) {
  std::vector<Message> out;
  std::istringstream lines(text);
  std::string line;
  while (std::getline(lines, line)) {
    if (line.empty()) continue;
    Message m;
    const auto status = google::protobuf::util::JsonStringToMessage(line, &m);
    EXPECT_TRUE(status.ok()) << "not a " << Message::descriptor()->full_name() << ": " << line;
    out.push_back(m);
  }
  return out;
}

// A stevi-server child on 127.0.0.1 with a port of its own choosing, its data directory in a new
// temporary folder (unless the arguments give one).
class ServerProcess {
 public:
  // Starts the server with `args` after the program name; fails the test when it does not say
  // "serving" within 60 s. Call with ASSERT_NO_FATAL_FAILURE.
  void Start(std::vector<std::string> args, bool default_data_dir = true) {
    args_ = args;
    args.insert(args.begin(), {BinaryPath("stevi-server"), "--listen", "127.0.0.1:0"});
    if (default_data_dir) {
      data_dir_ = MakeTempDir("stevi-server-data");
      args.insert(args.end(), {"--data-dir", data_dir_});
    }
    server_.reset();
    server_ = std::make_unique<Subprocess>(args);
    const std::optional<std::string> line =
        server_->WaitForStderrLine("serving", std::chrono::seconds(60));
    ASSERT_TRUE(line.has_value()) << "the server did not start: " << server_->DrainStderr();
    std::smatch m;
    // The listen= field: the source's description may hold an address too (an RTSP camera's).
    ASSERT_TRUE(std::regex_search(*line, m, std::regex("listen=127\\.0\\.0\\.1:(\\d+)"))) << *line;
    address_ = "127.0.0.1:" + m[1].str();
  }

  // Runs `stevi --server ADDRESS --timeout 20 ARGS...`, for at most `timeout`.
  RunResult Stevi(std::vector<std::string> args,
                  std::chrono::milliseconds timeout = kCommandTimeout) const {
    args.insert(args.begin(), {BinaryPath("stevi"), "--server", address_, "--timeout", "20"});
    return Run(args, timeout);
  }

  // Starts the server again with the same arguments on the same address and data directory (a
  // restart, as systemd does it). Call with ASSERT_NO_FATAL_FAILURE.
  void Restart() {
    server_.reset();
    std::vector<std::string> args = args_;
    args.insert(args.begin(), {BinaryPath("stevi-server"), "--listen", address_});
    if (!data_dir_.empty()) args.insert(args.end(), {"--data-dir", data_dir_});
    server_ = std::make_unique<Subprocess>(args);
    const std::optional<std::string> line =
        server_->WaitForStderrLine("serving", std::chrono::seconds(60));
    ASSERT_TRUE(line.has_value()) << "the server did not restart: " << server_->DrainStderr();
  }

  // Ends the server at once (SIGKILL). A server that had stopped on a sanitizer report fails
  // the test with it (~Subprocess).
  void Stop() { server_.reset(); }
  Subprocess* process() { return server_.get(); }
  const std::string& address() const { return address_; }
  const std::string& data_dir() const { return data_dir_; }

 private:
  std::unique_ptr<Subprocess> server_;
  std::vector<std::string> args_;
  std::string address_;
  std::string data_dir_;
};

}  // namespace stevi::testing
