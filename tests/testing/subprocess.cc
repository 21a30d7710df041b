#include "tests/testing/subprocess.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <stdexcept>

namespace stevi::testing {
namespace {

using Clock = std::chrono::steady_clock;

// Reads what is available from fd into buffer; false at EOF or error.
bool ReadSome(int fd, std::string& buffer) {
  char chunk[4096];
  const ssize_t n = read(fd, chunk, sizeof chunk);
  if (n <= 0) return false;
  buffer.append(chunk, static_cast<size_t>(n));
  return true;
}

int RemainingMs(Clock::time_point deadline) {
  const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
  return left.count() > 0 ? static_cast<int>(left.count()) : 0;
}

}  // namespace

Subprocess::Subprocess(const std::vector<std::string>& argv)
    : program_(argv.empty() ? "" : argv[0]) {
  // Everything that allocates happens before fork. The test process has threads (gRPC,
  // GStreamer, Aravis): a lock one of them held at the fork stays held in the child forever, and
  // the child, allocating, would hang before exec.
  std::vector<char*> args;
  args.reserve(argv.size() + 1);
  for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  // Close-on-exec, so that a child started by another thread at the same moment cannot inherit
  // these pipes and hold them open past this child's exit. dup2 below gives the child its own
  // ends without the flag.
  int out_pipe[2], err_pipe[2];
  if (pipe2(out_pipe, O_CLOEXEC) != 0 || pipe2(err_pipe, O_CLOEXEC) != 0) {
    throw std::runtime_error("pipe failed");
  }
  pid_ = fork();
  if (pid_ < 0) throw std::runtime_error("fork failed");
  if (pid_ == 0) {
    // Async-signal-safe calls only.
    dup2(out_pipe[1], STDOUT_FILENO);
    dup2(err_pipe[1], STDERR_FILENO);
    execv(args[0], args.data());
    _exit(127);
  }
  close(out_pipe[1]);
  close(err_pipe[1]);
  out_fd_ = out_pipe[0];
  err_fd_ = err_pipe[0];
}

Subprocess::~Subprocess() {
  if (!reaped_ && pid_ > 0) {
    int status = 0;
    if (waitpid(pid_, &status, WNOHANG) == pid_) {
      // It had ended by itself: what it last wrote may be a sanitizer's report.
      reaped_ = true;
      const auto deadline = Clock::now() + std::chrono::milliseconds(200);
      pollfd fd = {err_fd_, POLLIN, 0};
      while (poll(&fd, 1, RemainingMs(deadline)) > 0 && ReadSome(err_fd_, err_)) {
      }
    } else {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
  }
  if (const std::string report = SanitizerReport(); !report.empty()) {
    ADD_FAILURE() << program_ << " stopped on a sanitizer report:\n" << report;
  }
  if (out_fd_ >= 0) close(out_fd_);
  if (err_fd_ >= 0) close(err_fd_);
}

std::string Subprocess::SanitizerReport() const {
  for (const char* marker : {"WARNING: ThreadSanitizer", "ERROR: AddressSanitizer",
                             "ERROR: LeakSanitizer", "runtime error:"}) {
    const size_t at = err_.find(marker);
    if (at != std::string::npos) return err_.substr(at, 8000);
  }
  return "";
}

std::optional<std::string> Subprocess::WaitForStderrLine(const std::string& needle,
                                                         std::chrono::milliseconds timeout) {
  return WaitForLine(/*from_stdout=*/false, needle, timeout);
}

std::optional<std::string> Subprocess::WaitForStdoutLine(const std::string& needle,
                                                         std::chrono::milliseconds timeout) {
  return WaitForLine(/*from_stdout=*/true, needle, timeout);
}

std::optional<std::string> Subprocess::WaitForLine(bool from_stdout, const std::string& needle,
                                                   std::chrono::milliseconds timeout) {
  const auto deadline = Clock::now() + timeout;
  std::string& text = from_stdout ? out_ : err_;
  size_t& scanned = from_stdout ? out_scanned_ : err_scanned_;
  const int fd = from_stdout ? out_fd_ : err_fd_;
  const int other_fd = from_stdout ? err_fd_ : out_fd_;
  std::string& other_text = from_stdout ? err_ : out_;
  while (true) {
    // Complete lines not yet scanned.
    size_t end;
    while ((end = text.find('\n', scanned)) != std::string::npos) {
      std::string line = text.substr(scanned, end - scanned);
      scanned = end + 1;
      if (line.find(needle) != std::string::npos) return line;
    }
    // Keep the other pipe flowing too, so the child never blocks on a full pipe.
    pollfd fds[2] = {{fd, POLLIN, 0}, {other_fd, POLLIN, 0}};
    const int ready = poll(fds, 2, RemainingMs(deadline));
    if (ready <= 0) return std::nullopt;
    if ((fds[1].revents & POLLIN) != 0) ReadSome(other_fd, other_text);
    if ((fds[0].revents & (POLLIN | POLLHUP)) != 0 && !ReadSome(fd, text)) return std::nullopt;
  }
}

void Subprocess::Signal(int signal_number) {
  if (!reaped_) kill(pid_, signal_number);
}

std::optional<int> Subprocess::Wait(std::chrono::milliseconds timeout) {
  const auto deadline = Clock::now() + timeout;
  bool out_open = true, err_open = true;
  // Drain both pipes until EOF (the child exited or closed them), then reap.
  while ((out_open || err_open) && Clock::now() < deadline) {
    pollfd fds[2] = {{out_open ? out_fd_ : -1, POLLIN, 0}, {err_open ? err_fd_ : -1, POLLIN, 0}};
    if (poll(fds, 2, RemainingMs(deadline)) <= 0) break;
    if ((fds[0].revents & (POLLIN | POLLHUP)) != 0 && !ReadSome(out_fd_, out_)) out_open = false;
    if ((fds[1].revents & (POLLIN | POLLHUP)) != 0 && !ReadSome(err_fd_, err_)) err_open = false;
  }
  if (out_open || err_open) return std::nullopt;  // timed out; the destructor kills it
  // Both pipes reached EOF: the child is exiting, so a blocking wait is bounded.
  int status = 0;
  if (waitpid(pid_, &status, 0) != pid_) return std::nullopt;
  reaped_ = true;
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  return std::nullopt;
}

std::string Subprocess::DrainStdout() { return out_; }
std::string Subprocess::DrainStderr() { return err_; }

RunResult Run(const std::vector<std::string>& argv, std::chrono::milliseconds timeout) {
  Subprocess process(argv);
  RunResult result;
  const std::optional<int> code = process.Wait(timeout);
  result.exit_code = code.value_or(-1);
  result.out = process.DrainStdout();
  result.err = process.DrainStderr();
  return result;
}

std::string BinaryPath(const std::string& name) {
  return std::string(STEVI_BINARY_DIR) + "/" + name;
}

}  // namespace stevi::testing
