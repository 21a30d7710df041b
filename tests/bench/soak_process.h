// The soak's child processes (tests/bench/soak.cc): started with their output in a log file (a
// soak runs for half an hour: pipes would fill and block a child nobody reads), in a process group
// of their own (Ctrl-C reaches the soak alone, which then stops them in order), and killed when the
// soak dies (PR_SET_PDEATHSIG). Plus what /proc says about a process.
#pragma once

#include <sys/types.h>

#include <chrono>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace stevi::soak {

class ChildProcess {
 public:
  // `name` is for messages; the output (stdout and stderr) goes to `log_path`, appended to.
  ChildProcess(std::string name, std::vector<std::string> argv, std::string log_path);
  ~ChildProcess() { Kill(); }
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  // Starts the program (again, after it ended); false and `error` when it cannot. Call from the
  // main thread only: the death signal follows the thread that forked.
  bool Start(std::string* error);
  // Waits until a log line written since the last Start() contains `needle` (returned), the
  // process exits, or the timeout.
  std::optional<std::string> WaitForLogLine(const std::string& needle,
                                            std::chrono::milliseconds timeout);
  // SIGTERM, then SIGKILL after `grace`; returns the time the process took to exit.
  std::chrono::milliseconds Terminate(std::chrono::milliseconds grace);
  // SIGKILL: gone at once, as on a power cut.
  void Kill();
  // True while the process runs (reaps it when it has ended).
  bool Running();
  // The exit status of the last run ("exit 0", "signal 9"), empty while running.
  const std::string& ended_how() const { return ended_how_; }

  // Replaces argument i (argv[0] is the program) for the next Start().
  void SetArgument(size_t i, std::string value) { argv_.at(i) = std::move(value); }

  pid_t pid() const { return pid_; }
  const std::string& name() const { return name_; }
  const std::string& log_path() const { return log_path_; }
  // The log's last `bytes` bytes.
  std::string LogTail(size_t bytes = 2000) const;

 private:
  void Reaped(int status);

  std::string name_;
  std::vector<std::string> argv_;
  std::string log_path_;
  pid_t pid_ = -1;
  long log_offset_ = 0;  // where the current run's output starts
  std::string ended_how_;
};

// One process as /proc shows it: resident memory (VmRSS), open file descriptors and threads.
struct ProcSample {
  bool ok = false;  // false when the process is gone
  long rss_kb = 0;
  int fds = 0;
  int threads = 0;
  // Threads by name (/proc/PID/task/TID/comm): stevi's are "stevi-*", a library's carry its own
  // name or, unnamed, the program's.
  std::map<std::string, int> thread_names;
};
ProcSample ReadProc(pid_t pid);

}  // namespace stevi::soak
