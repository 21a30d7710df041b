// Runs the project's binaries from tests: capture output, wait for a line, signal, reap.
#pragma once

#include <sys/types.h>

#include <chrono>
#include <optional>
#include <string>
#include <vector>

namespace stevi::testing {

// A child process with its stdout and stderr on pipes. Killed (SIGKILL) and reaped on destruction
// if still running. A child that stopped on a sanitizer's report (halt_on_error, as
// deploy/sanitize.sh runs them) fails the test with the report when it is destroyed: otherwise a
// test whose server died would fail on a timeout with the cause unseen.
class Subprocess {
 public:
  // argv[0] is the program path. Aborts the test run (throws) if it cannot start.
  explicit Subprocess(const std::vector<std::string>& argv);
  ~Subprocess();
  Subprocess(const Subprocess&) = delete;
  Subprocess& operator=(const Subprocess&) = delete;

  // Reads stderr until a line containing `needle` arrives (returned), EOF, or the timeout.
  std::optional<std::string> WaitForStderrLine(const std::string& needle,
                                               std::chrono::milliseconds timeout);
  // The same for stdout (the lines scanned by each are their own).
  std::optional<std::string> WaitForStdoutLine(const std::string& needle,
                                               std::chrono::milliseconds timeout);
  void Signal(int signal_number);
  // Waits for the exit (bounded); returns the exit code, or nullopt on timeout or a signal death.
  std::optional<int> Wait(std::chrono::milliseconds timeout);
  // All of stdout / stderr read so far plus what remains (call after Wait()).
  std::string DrainStdout();
  std::string DrainStderr();
  // The sanitizer report in the stderr read so far, or "".
  std::string SanitizerReport() const;

 private:
  std::optional<std::string> WaitForLine(bool from_stdout, const std::string& needle,
                                         std::chrono::milliseconds timeout);

  std::string program_;
  pid_t pid_ = -1;
  int out_fd_ = -1, err_fd_ = -1;
  std::string out_, err_;
  size_t out_scanned_ = 0, err_scanned_ = 0;
  bool reaped_ = false;
};

// Runs a command to completion (bounded by `timeout`), returning {exit code, stdout, stderr}.
struct RunResult {
  int exit_code = -1;  // -1: timed out or killed by a signal
  std::string out;
  std::string err;
};
RunResult Run(const std::vector<std::string>& argv, std::chrono::milliseconds timeout);

// Path of a binary built by this project (tests get it from the STEVI_BINARY_DIR definition).
std::string BinaryPath(const std::string& name);

}  // namespace stevi::testing
