#include "tests/bench/soak_process.h"

#include <dirent.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>
#include <thread>

namespace stevi::soak {
namespace {

using Clock = std::chrono::steady_clock;

long FileSize(const std::string& path) {
  struct stat st {};
  return stat(path.c_str(), &st) == 0 ? static_cast<long>(st.st_size) : 0;
}

std::string ReadFrom(const std::string& path, long offset) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return "";
  in.seekg(offset);
  std::ostringstream out;
  out << in.rdbuf();
  return out.str();
}

}  // namespace

ChildProcess::ChildProcess(std::string name, std::vector<std::string> argv, std::string log_path)
    : name_(std::move(name)), argv_(std::move(argv)), log_path_(std::move(log_path)) {}

bool ChildProcess::Start(std::string* error) {
  if (pid_ > 0) {
    *error = name_ + " is already running";
    return false;
  }
  std::vector<char*> args;
  for (std::string& a : argv_) args.push_back(a.data());
  args.push_back(nullptr);
  // Everything that allocates happens before fork: the soak has threads.
  const int log = open(log_path_.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  if (log < 0) {
    *error = log_path_ + ": " + std::strerror(errno);
    return false;
  }
  const int null = open("/dev/null", O_RDONLY | O_CLOEXEC);
  log_offset_ = FileSize(log_path_);
  const pid_t parent = getpid();
  const pid_t pid = fork();
  if (pid == 0) {
    setpgid(0, 0);  // Ctrl-C on the terminal reaches the soak, not its children
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != parent) _exit(126);
    if (null >= 0) dup2(null, STDIN_FILENO);
    dup2(log, STDOUT_FILENO);
    dup2(log, STDERR_FILENO);
    execv(args[0], args.data());
    _exit(127);
  }
  const int fork_errno = errno;
  close(log);
  if (null >= 0) close(null);
  if (pid < 0) {
    *error = "cannot start " + argv_[0] + ": " + std::strerror(fork_errno);
    return false;
  }
  pid_ = pid;
  ended_how_.clear();
  return true;
}

void ChildProcess::Reaped(int status) {
  if (WIFEXITED(status)) {
    ended_how_ = "exit " + std::to_string(WEXITSTATUS(status));
  } else if (WIFSIGNALED(status)) {
    ended_how_ = "signal " + std::to_string(WTERMSIG(status));
  } else {
    ended_how_ = "ended";
  }
  pid_ = -1;
}

bool ChildProcess::Running() {
  if (pid_ <= 0) return false;
  int status = 0;
  if (waitpid(pid_, &status, WNOHANG) == pid_) {
    Reaped(status);
    return false;
  }
  return true;
}

std::optional<std::string> ChildProcess::WaitForLogLine(const std::string& needle,
                                                        std::chrono::milliseconds timeout) {
  const auto deadline = Clock::now() + timeout;
  while (true) {
    const std::string text = ReadFrom(log_path_, log_offset_);
    size_t start = 0, end;
    while ((end = text.find('\n', start)) != std::string::npos) {
      std::string line = text.substr(start, end - start);
      if (line.find(needle) != std::string::npos) return line;
      start = end + 1;
    }
    if (!Running() || Clock::now() >= deadline) return std::nullopt;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
}

std::chrono::milliseconds ChildProcess::Terminate(std::chrono::milliseconds grace) {
  const auto start = Clock::now();
  if (pid_ <= 0) return std::chrono::milliseconds(0);
  kill(pid_, SIGTERM);
  const auto deadline = start + grace;
  while (Running() && Clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  if (pid_ > 0) Kill();
  return std::chrono::duration_cast<std::chrono::milliseconds>(Clock::now() - start);
}

void ChildProcess::Kill() {
  if (pid_ <= 0) return;
  kill(pid_, SIGKILL);
  int status = 0;
  if (waitpid(pid_, &status, 0) == pid_) {  // bounded: SIGKILL cannot be caught
    Reaped(status);
  } else {
    pid_ = -1;
  }
}

std::string ChildProcess::LogTail(size_t bytes) const {
  const long size = FileSize(log_path_);
  return ReadFrom(log_path_, std::max(0L, size - static_cast<long>(bytes)));
}

ProcSample ReadProc(pid_t pid) {
  ProcSample s;
  if (pid <= 0) return s;
  const std::string dir = "/proc/" + std::to_string(pid);
  std::ifstream status(dir + "/status");
  if (!status) return s;
  std::string line;
  bool rss = false, threads = false;
  while (std::getline(status, line)) {
    if (line.rfind("VmRSS:", 0) == 0) {
      s.rss_kb = std::strtol(line.c_str() + 6, nullptr, 10);
      rss = true;
    } else if (line.rfind("Threads:", 0) == 0) {
      s.threads = static_cast<int>(std::strtol(line.c_str() + 8, nullptr, 10));
      threads = true;
    }
  }
  DIR* fd_dir = opendir((dir + "/fd").c_str());
  if (fd_dir == nullptr) return s;
  int n = 0;
  while (const dirent* e = readdir(fd_dir)) {
    if (e->d_name[0] != '.') ++n;
  }
  closedir(fd_dir);
  // Reading our own fd folder holds one descriptor open: not counted.
  if (pid == getpid()) --n;
  s.fds = n;
  if (DIR* tasks = opendir((dir + "/task").c_str())) {
    while (const dirent* e = readdir(tasks)) {
      if (e->d_name[0] == '.') continue;
      std::ifstream comm(dir + "/task/" + e->d_name + "/comm");
      std::string name;
      if (std::getline(comm, name)) ++s.thread_names[name];
    }
    closedir(tasks);
  }
  s.ok = rss && threads;
  return s;
}

}  // namespace stevi::soak
