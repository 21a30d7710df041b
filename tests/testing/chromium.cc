#include "tests/testing/chromium.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdlib.h>
#include <sys/socket.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <algorithm>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <mutex>
#include <set>
#include <sstream>
#include <string_view>
#include <thread>

extern char** environ;

namespace stevi::testing {
namespace {

using Clock = std::chrono::steady_clock;
using nlohmann::json;

constexpr std::chrono::seconds kLaunchTimeout{30};
constexpr std::chrono::seconds kCloseTimeout{3};      // Browser.close to the exit
constexpr std::chrono::seconds kLeftoversTimeout{2};  // SIGKILL to the exit of every child
constexpr size_t kStderrLimit = 1 << 20;

int RemainingMs(Clock::time_point deadline) {
  const auto left = std::chrono::ceil<std::chrono::milliseconds>(deadline - Clock::now());
  return left.count() > 0 ? static_cast<int>(std::min<int64_t>(left.count(), 1 << 30)) : 0;
}

std::string Errno(const std::string& what) { return what + ": " + std::strerror(errno); }

void CloseFd(int& fd) {
  if (fd >= 0) close(fd);
  fd = -1;
}

// Standard base64 (Page.captureScreenshot's data); stops at '=' or the end.
std::string DecodeBase64(const std::string& text) {
  auto value = [](char c) -> int {
    if (c >= 'A' && c <= 'Z') return c - 'A';
    if (c >= 'a' && c <= 'z') return c - 'a' + 26;
    if (c >= '0' && c <= '9') return c - '0' + 52;
    if (c == '+') return 62;
    if (c == '/') return 63;
    return -1;
  };
  std::string out;
  out.reserve(text.size() / 4 * 3);
  uint32_t bits = 0;
  int count = 0;
  for (const char c : text) {
    const int v = value(c);
    if (v < 0) continue;
    bits = (bits << 6) | static_cast<uint32_t>(v);
    if (++count == 4) {
      out.push_back(static_cast<char>((bits >> 16) & 0xff));
      out.push_back(static_cast<char>((bits >> 8) & 0xff));
      out.push_back(static_cast<char>(bits & 0xff));
      bits = 0;
      count = 0;
    }
  }
  if (count == 3) {
    out.push_back(static_cast<char>((bits >> 10) & 0xff));
    out.push_back(static_cast<char>((bits >> 2) & 0xff));
  } else if (count == 2) {
    out.push_back(static_cast<char>((bits >> 4) & 0xff));
  }
  return out;
}

// A Runtime.RemoteObject as text, the way the console shows it.
std::string RemoteObjectText(const json& object) {
  if (object.contains("value")) {
    const json& v = object["value"];
    return v.is_string() ? v.get<std::string>() : v.dump();
  }
  if (object.contains("unserializableValue"))
    return object["unserializableValue"].get<std::string>();
  if (object.contains("description")) return object["description"].get<std::string>();
  return object.value("type", std::string("?"));
}

// Runtime.ExceptionDetails as text: the exception's description (message and stack) when there
// is one, else the details' text, with the location.
std::string ExceptionText(const json& details) {
  std::string text = details.value("text", std::string());
  if (details.contains("exception")) {
    const json& exception = details["exception"];
    const std::string description = RemoteObjectText(exception);
    text = text == "Uncaught" || text.empty() ? description : text + " " + description;
  }
  const std::string url = details.value("url", std::string());
  if (!url.empty()) {
    text += " (" + url + ":" + std::to_string(details.value("lineNumber", 0) + 1) + ":" +
            std::to_string(details.value("columnNumber", 0) + 1) + ")";
  }
  return text;
}

// Kills the processes Chromium left, and waits (bounded) for their exit: the members of its
// process group (zygotes, renderers, GPU and utility processes) and those naming its private
// directory on their command line (the crashpad handlers, which make process groups of their own).
// The group leader itself is skipped: its caller reaps it. Zombies are reaped by init.
void KillLeftovers(pid_t pgid, const std::string& private_dir, Clock::time_point deadline) {
  std::vector<int> pidfds;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator("/proc", ec)) {
    const std::string name = entry.path().filename().string();
    if (name.empty() || name.find_first_not_of("0123456789") != std::string::npos) continue;
    const pid_t process = static_cast<pid_t>(std::stol(name));
    if (process == pgid) continue;
    std::ifstream stat_file(entry.path() / "stat");
    std::string stat;
    std::getline(stat_file, stat);
    // pid (comm) state ppid pgrp ...; comm may hold spaces and parentheses.
    const size_t close_paren = stat.rfind(')');
    if (close_paren == std::string::npos) continue;
    std::istringstream fields(stat.substr(close_paren + 1));
    char state = 0;
    long ppid = 0, pgrp = 0;
    if (!(fields >> state >> ppid >> pgrp) || state == 'Z') continue;
    bool ours = pgrp == pgid;
    if (!ours) {
      std::ifstream cmdline_file(entry.path() / "cmdline", std::ios::binary);
      const std::string cmdline((std::istreambuf_iterator<char>(cmdline_file)),
                                std::istreambuf_iterator<char>());
      ours = cmdline.find(private_dir) != std::string::npos;
    }
    if (!ours) continue;
    // A pidfd first, so that the kill and the wait are sure to address this very process.
    const int fd = static_cast<int>(syscall(SYS_pidfd_open, process, 0));
    if (fd < 0) continue;
    syscall(SYS_pidfd_send_signal, fd, SIGKILL, nullptr, 0);
    pidfds.push_back(fd);
  }
  for (int fd : pidfds) {
    pollfd p = {fd, POLLIN, 0};
    poll(&p, 1, RemainingMs(deadline));
    close(fd);
  }
}

}  // namespace

struct Browser::Impl {
  ~Impl() { Shutdown(); }

  // A command's outcome: the reply's result, or the protocol / transport error.
  struct Reply {
    bool ok = false;
    json result;
    std::string error;
  };

  bool Spawn(const std::string& binary, int width, int height, std::string* error);
  Reply Call(const std::string& method, const json& params, bool on_page,
             std::chrono::milliseconds timeout);
  void ReaderLoop();
  void Dispatch(const std::string& text);
  void OnEvent(const json& message);
  std::string ExitDescription() const;
  std::string DeadError() const;  // callers hold mutex
  void Shutdown();

  pid_t pid = -1;
  int pidfd = -1;
  int to_chrome = -1;    // our end of Chromium's fd 3 (a socket: send with MSG_NOSIGNAL)
  int from_chrome = -1;  // our end of Chromium's fd 4
  int stderr_fd = -1;
  int wake_read = -1, wake_write = -1;  // stops the reader thread
  std::string user_data_dir;
  std::thread reader;
  std::mutex write_mutex;

  mutable std::mutex mutex;
  std::condition_variable cv;
  // Guarded by mutex.
  uint64_t next_id = 1;
  std::set<uint64_t> pending;
  std::map<uint64_t, json> replies;
  bool pipe_closed = false;
  std::string exit_text;  // how Chromium ended, once pipe_closed
  bool page_gone = false;
  std::string page_gone_reason;
  std::string session_id;
  std::deque<std::string> loaded;  // loader ids of the last documents that fired "load"
  std::string stderr_text;
  std::vector<std::string> console_messages;
  std::vector<std::string> console_errors;
};

bool Browser::Impl::Spawn(const std::string& binary, int width, int height, std::string* error) {
  const char* tmp = std::getenv("TMPDIR");
  std::string pattern =
      std::string(tmp != nullptr && *tmp != '\0' ? tmp : "/tmp") + "/stevi-chromium-XXXXXX";
  if (mkdtemp(pattern.data()) == nullptr) {
    *error = Errno("cannot create a user data directory from " + pattern);
    return false;
  }
  user_data_dir = pattern;

  const std::vector<std::string> args = {
      binary,
      "--headless",
      "--no-sandbox",
      "--disable-gpu",
      "--disable-dev-shm-usage",
      "--user-data-dir=" + user_data_dir,
      "--remote-debugging-pipe",
      "--window-size=" + std::to_string(width) + "," + std::to_string(height),
      "--hide-scrollbars",
      "--mute-audio",
      "--no-first-run",
      "--no-default-browser-check",
      "--disable-background-networking",
      "--disable-component-update",
      "--disable-sync",
      "--disable-extensions",
      "--disable-features=Translate,MediaRouter,OptimizationHints",
      "--password-store=basic",
      "about:blank",
  };
  std::vector<char*> argv;
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  // Chromium's other files (the crashpad database, caches) go to the private directory too,
  // not to $HOME/.config/chromium.
  std::vector<std::string> env_strings = {"XDG_CONFIG_HOME=" + user_data_dir + "/xdg-config",
                                          "XDG_CACHE_HOME=" + user_data_dir + "/xdg-cache"};
  for (char** e = environ; *e != nullptr; ++e) {
    const std::string_view entry(*e);
    if (entry.starts_with("XDG_CONFIG_HOME=") || entry.starts_with("XDG_CACHE_HOME=")) continue;
    env_strings.emplace_back(entry);
  }
  std::vector<char*> envp;
  for (const std::string& e : env_strings) envp.push_back(const_cast<char*>(e.c_str()));
  envp.push_back(nullptr);

  // Our ends go to members at once, so that Shutdown() closes them on any failure below.
  int command_pair[2], reply_pipe[2], err_pipe[2], wake_pipe[2];
  if (socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, command_pair) != 0) {
    *error = Errno("socketpair");
    return false;
  }
  to_chrome = command_pair[0];
  if (pipe2(reply_pipe, O_CLOEXEC) != 0) {
    close(command_pair[1]);
    *error = Errno("pipe2");
    return false;
  }
  from_chrome = reply_pipe[0];
  if (pipe2(err_pipe, O_CLOEXEC) != 0) {
    close(command_pair[1]);
    close(reply_pipe[1]);
    *error = Errno("pipe2");
    return false;
  }
  stderr_fd = err_pipe[0];
  const int dev_null = open("/dev/null", O_RDWR | O_CLOEXEC);
  // Stops the reader thread.
  if (pipe2(wake_pipe, O_CLOEXEC) == 0) {
    wake_read = wake_pipe[0];
    wake_write = wake_pipe[1];
  }
  if (dev_null < 0 || wake_read < 0) {
    for (int fd : {command_pair[1], reply_pipe[1], err_pipe[1], dev_null}) {
      if (fd >= 0) close(fd);
    }
    *error = Errno("open /dev/null or pipe2");
    return false;
  }

  const pid_t child = fork();
  if (child < 0) {
    for (int fd : {command_pair[1], reply_pipe[1], err_pipe[1], dev_null}) close(fd);
    *error = Errno("fork");
    return false;
  }
  if (child == 0) {
    // Child: async-signal-safe calls only. Move the ends above 10 first, so that the dup2s below
    // cannot clobber each other, and land without FD_CLOEXEC.
    setpgid(0, 0);
    const int in = fcntl(command_pair[1], F_DUPFD, 10);
    const int out = fcntl(reply_pipe[1], F_DUPFD, 10);
    const int err = fcntl(err_pipe[1], F_DUPFD, 10);
    if (in < 0 || out < 0 || err < 0) _exit(126);
    dup2(dev_null, STDIN_FILENO);
    dup2(err, STDOUT_FILENO);
    dup2(err, STDERR_FILENO);
    dup2(in, 3);
    dup2(out, 4);
    close_range(5, ~0U, 0);  // nothing else of the test process leaks into Chromium
    execve(argv[0], argv.data(), envp.data());
    _exit(127);
  }
  pid = child;
  setpgid(pid, pid);  // also here, so that a kill of the group cannot race the child's setpgid
  for (int fd : {command_pair[1], reply_pipe[1], err_pipe[1], dev_null}) close(fd);
  fcntl(to_chrome, F_SETFL, fcntl(to_chrome, F_GETFL) | O_NONBLOCK);
  // glibc 2.36's <sys/pidfd.h> lacks extern "C": call the kernel directly. -1 on kernels before
  // 5.3: Shutdown() then kills without waiting.
  pidfd = static_cast<int>(syscall(SYS_pidfd_open, pid, 0));
  reader = std::thread([this] { ReaderLoop(); });
  return true;
}

void Browser::Impl::ReaderLoop() {
  std::string buffer;
  size_t scanned = 0;
  bool reply_open = true, stderr_open = true;
  std::vector<char> chunk(1 << 16);
  while (true) {
    pollfd fds[3] = {{wake_read, POLLIN, 0},
                     {reply_open ? from_chrome : -1, POLLIN, 0},
                     {stderr_open ? stderr_fd : -1, POLLIN, 0}};
    if (poll(fds, 3, -1) < 0) {
      if (errno == EINTR) continue;
      break;
    }
    if (fds[0].revents != 0) break;
    if ((fds[1].revents & (POLLIN | POLLHUP | POLLERR)) != 0) {
      const ssize_t n = read(from_chrome, chunk.data(), chunk.size());
      if (n > 0) {
        buffer.append(chunk.data(), static_cast<size_t>(n));
        size_t start = 0, end;
        while ((end = buffer.find('\0', scanned)) != std::string::npos) {
          Dispatch(buffer.substr(start, end - start));
          start = scanned = end + 1;
        }
        buffer.erase(0, start);
        scanned = buffer.size();
      } else if (n == 0 || errno != EINTR) {
        reply_open = false;
        const std::string exit = ExitDescription();
        std::lock_guard lock(mutex);
        exit_text = exit;
        pipe_closed = true;
        cv.notify_all();
      }
    }
    if ((fds[2].revents & (POLLIN | POLLHUP | POLLERR)) != 0) {
      const ssize_t n = read(stderr_fd, chunk.data(), chunk.size());
      if (n > 0) {
        std::lock_guard lock(mutex);
        stderr_text.append(chunk.data(), static_cast<size_t>(n));
        if (stderr_text.size() > kStderrLimit) stderr_text.erase(0, stderr_text.size() / 2);
      } else if (n == 0 || errno != EINTR) {
        stderr_open = false;
      }
    }
  }
}

void Browser::Impl::Dispatch(const std::string& text) {
  json message = json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (message.is_discarded() || !message.is_object()) return;
  if (message.contains("id")) {
    if (!message["id"].is_number_unsigned()) return;
    const uint64_t id = message["id"].get<uint64_t>();
    std::lock_guard lock(mutex);
    if (pending.erase(id) > 0) {  // else its caller gave up waiting
      replies[id] = std::move(message);
      cv.notify_all();
    }
    return;
  }
  OnEvent(message);
}

void Browser::Impl::OnEvent(const json& message) {
  const std::string method = message.value("method", std::string());
  const json params = message.value("params", json::object());
  const std::string session = message.value("sessionId", std::string());
  std::lock_guard lock(mutex);
  if (method == "Target.detachedFromTarget") {
    if (!session_id.empty() && params.value("sessionId", std::string()) == session_id) {
      page_gone = true;
      page_gone_reason = "the page was closed (detached from its target)";
      cv.notify_all();
    }
    return;
  }
  if (session.empty() || session != session_id) return;
  if (method == "Page.lifecycleEvent") {
    if (params.value("name", std::string()) == "load") {
      loaded.push_back(params.value("loaderId", std::string()));
      if (loaded.size() > 64) loaded.pop_front();
      cv.notify_all();
    }
  } else if (method == "Inspector.targetCrashed") {
    page_gone = true;
    page_gone_reason = "the page's renderer crashed";
    cv.notify_all();
  } else if (method == "Runtime.consoleAPICalled") {
    const std::string type = params.value("type", std::string("log"));
    std::string text;
    for (const json& arg : params.value("args", json::array())) {
      if (!text.empty()) text += ' ';
      text += RemoteObjectText(arg);
    }
    console_messages.push_back(type + ": " + text);
    if (type == "error" || type == "assert")
      console_errors.push_back("console." + type + ": " + text);
  } else if (method == "Runtime.exceptionThrown") {
    console_errors.push_back("uncaught: " +
                             ExceptionText(params.value("exceptionDetails", json())));
  } else if (method == "Log.entryAdded") {
    const json entry = params.value("entry", json::object());
    const std::string url = entry.value("url", std::string());
    // The browser's own favicon request is not the page's doing.
    const bool favicon = url.size() >= 12 && url.compare(url.size() - 12, 12, "/favicon.ico") == 0;
    if (entry.value("level", std::string()) == "error" && !favicon) {
      std::string text = "log." + entry.value("source", std::string("other")) + ": " +
                         entry.value("text", std::string());
      if (!url.empty()) text += " " + url;
      console_errors.push_back(std::move(text));
    }
  }
}

// How the main process ended ("; exit status 0", "; killed by signal 9"), or "" if it is still
// running 1 s after closing its pipe. It is not reaped: Shutdown() does that.
std::string Browser::Impl::ExitDescription() const {
  if (pidfd >= 0) {
    pollfd fd = {pidfd, POLLIN, 0};
    if (poll(&fd, 1, 1000) <= 0) return "";
  }
  siginfo_t info{};
  if (waitid(P_PID, static_cast<id_t>(pid), &info, WEXITED | WNOHANG | WNOWAIT) != 0 ||
      info.si_pid != pid) {
    return "";
  }
  return info.si_code == CLD_EXITED ? "; exit status " + std::to_string(info.si_status)
                                    : "; killed by signal " + std::to_string(info.si_status);
}

std::string Browser::Impl::DeadError() const {
  std::string error = "chromium closed its DevTools pipe (it exited or crashed)" + exit_text;
  // The end of stderr, without the D-Bus noise of a machine with no bus.
  std::istringstream lines(stderr_text);
  std::vector<std::string> kept;
  for (std::string line; std::getline(lines, line);) {
    if (line.find("dbus") == std::string::npos && !line.empty()) kept.push_back(line);
  }
  const size_t first = kept.size() > 15 ? kept.size() - 15 : 0;
  if (first < kept.size()) error += "; its stderr ends with:";
  for (size_t i = first; i < kept.size(); ++i) error += "\n  " + kept[i];
  return error;
}

Browser::Impl::Reply Browser::Impl::Call(const std::string& method, const json& params,
                                         bool on_page, std::chrono::milliseconds timeout) {
  const auto deadline = Clock::now() + timeout;
  Reply reply;
  json message = {{"method", method}, {"params", params}};
  uint64_t id;
  {
    std::lock_guard lock(mutex);
    if (pipe_closed) {
      reply.error = DeadError();
      return reply;
    }
    if (on_page && page_gone) {
      reply.error = page_gone_reason;
      return reply;
    }
    id = next_id++;
    pending.insert(id);
    message["id"] = id;
    if (on_page) message["sessionId"] = session_id;
  }
  std::string bytes = message.dump();
  bytes.push_back('\0');
  std::string write_error;
  {
    std::lock_guard lock(write_mutex);
    size_t sent = 0;
    while (sent < bytes.size() && write_error.empty()) {
      const ssize_t n = send(to_chrome, bytes.data() + sent, bytes.size() - sent, MSG_NOSIGNAL);
      if (n > 0) {
        sent += static_cast<size_t>(n);
      } else if (n < 0 && (errno == EAGAIN || errno == EINTR)) {
        pollfd fd = {to_chrome, POLLOUT, 0};
        if (poll(&fd, 1, RemainingMs(deadline)) == 0) write_error = "timed out writing " + method;
      } else {
        write_error = Errno("cannot write to chromium");
      }
    }
  }
  std::unique_lock lock(mutex);
  if (!write_error.empty()) {
    pending.erase(id);
    reply.error = pipe_closed ? DeadError() : write_error;
    return reply;
  }
  cv.wait_until(lock, deadline,
                [&] { return replies.count(id) > 0 || pipe_closed || (on_page && page_gone); });
  const auto it = replies.find(id);
  if (it == replies.end()) {
    pending.erase(id);
    if (pipe_closed) {
      reply.error = DeadError();
    } else if (on_page && page_gone) {
      reply.error = page_gone_reason;
    } else {
      reply.error = method + ": no reply within " + std::to_string(timeout.count()) + " ms";
    }
    return reply;
  }
  const json answer = std::move(it->second);
  replies.erase(it);
  if (answer.contains("error")) {
    const json& e = answer["error"];
    reply.error = method + ": " + e.value("message", std::string("error"));
    if (e.contains("data")) {
      reply.error +=
          " (" + (e["data"].is_string() ? e["data"].get<std::string>() : e["data"].dump()) + ")";
    }
    return reply;
  }
  reply.ok = true;
  reply.result = answer.value("result", json::object());
  return reply;
}

void Browser::Impl::Shutdown() {
  if (pid > 0) {
    const auto deadline = Clock::now() + kCloseTimeout;
    bool closed = false;
    {
      std::lock_guard lock(mutex);
      closed = pipe_closed;
    }
    // Ask politely (it replies, then exits), then wait for the exit.
    if (!closed) Call("Browser.close", json::object(), false, std::chrono::seconds(1));
    bool exited = false;
    if (pidfd >= 0) {
      pollfd fd = {pidfd, POLLIN, 0};
      exited = poll(&fd, 1, RemainingMs(deadline)) > 0;
    }
    // The leader is not reaped yet, so its group id cannot have been reused: kill what is left of
    // the group (the leader if it hung, stray renderers) and the crashpad handlers, then reap.
    kill(-pid, SIGKILL);
    if (!exited) kill(pid, SIGKILL);
    KillLeftovers(pid, user_data_dir, Clock::now() + kLeftoversTimeout);
  }
  // The reader reads `pid` (ExitDescription): stop it before reaping.
  if (reader.joinable()) {
    const char byte = 1;
    if (write(wake_write, &byte, 1) < 0) {
      // The pipe is ours and empty; a failed write leaves nothing to do but join.
    }
    reader.join();
  }
  if (pid > 0) {
    waitpid(pid, nullptr, 0);
    pid = -1;
  }
  CloseFd(pidfd);
  CloseFd(to_chrome);
  CloseFd(from_chrome);
  CloseFd(stderr_fd);
  CloseFd(wake_read);
  CloseFd(wake_write);
  if (!user_data_dir.empty()) {
    std::error_code ignored;
    std::filesystem::remove_all(user_data_dir, ignored);
    user_data_dir.clear();
  }
}

std::string Browser::WantedChromium() {
  const char* env = std::getenv("STEVI_CHROMIUM");
  return env != nullptr && *env != '\0' ? std::string(env) : std::string("/usr/bin/chromium");
}

std::string Browser::ChromiumPath() {
  const std::string wanted = WantedChromium();
  std::error_code ec;
  if (!std::filesystem::is_regular_file(wanted, ec) || access(wanted.c_str(), X_OK) != 0) return "";
  return wanted;
}

std::unique_ptr<Browser> Browser::Launch(std::string* error, int width, int height) {
  std::string ignored;
  if (error == nullptr) error = &ignored;
  const std::string binary = ChromiumPath();
  if (binary.empty()) {
    *error = "no Chromium executable at " + WantedChromium() +
             " (install the chromium package or set STEVI_CHROMIUM)";
    return nullptr;
  }
  auto impl = std::make_unique<Impl>();
  if (!impl->Spawn(binary, width, height, error)) return nullptr;
  const auto deadline = Clock::now() + kLaunchTimeout;
  auto left = [&] { return std::chrono::milliseconds(RemainingMs(deadline)); };
  auto failed = [&](const Impl::Reply& r, const std::string& step) {
    *error = "chromium (" + binary + ") did not start: " + step + ": " + r.error;
    return nullptr;
  };

  Impl::Reply r = impl->Call("Target.createTarget", {{"url", "about:blank"}}, false, left());
  if (!r.ok) return failed(r, "Target.createTarget");
  const std::string target_id = r.result.value("targetId", std::string());
  r = impl->Call("Target.attachToTarget", {{"targetId", target_id}, {"flatten", true}}, false,
                 left());
  if (!r.ok) return failed(r, "Target.attachToTarget");
  {
    std::lock_guard lock(impl->mutex);
    impl->session_id = r.result.value("sessionId", std::string());
  }
  // Enable the domains before any navigation: their events start only once enabled. Lifecycle
  // events name the document (loader id) whose "load" fired, which Navigate() waits for.
  for (const char* domain : {"Page.enable", "Runtime.enable", "Log.enable"}) {
    r = impl->Call(domain, json::object(), true, left());
    if (!r.ok) return failed(r, domain);
  }
  r = impl->Call("Page.setLifecycleEventsEnabled", {{"enabled", true}}, true, left());
  if (!r.ok) return failed(r, "Page.setLifecycleEventsEnabled");
  // --window-size sizes the window; the viewport inside it is smaller. Pin the viewport.
  r = impl->Call(
      "Emulation.setDeviceMetricsOverride",
      {{"width", width}, {"height", height}, {"deviceScaleFactor", 1}, {"mobile", false}}, true,
      left());
  if (!r.ok) return failed(r, "Emulation.setDeviceMetricsOverride");
  return std::unique_ptr<Browser>(new Browser(std::move(impl)));
}

Browser::Browser(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

Browser::~Browser() = default;

bool Browser::Fail(std::string error) {
  last_error_ = std::move(error);
  return false;
}

bool Browser::Navigate(const std::string& url, std::chrono::milliseconds timeout) {
  const auto deadline = Clock::now() + timeout;
  const Impl::Reply r = impl_->Call("Page.navigate", {{"url", url}}, true, timeout);
  if (!r.ok) return Fail("navigating to " + url + ": " + r.error);
  const std::string error_text = r.result.value("errorText", std::string());
  if (!error_text.empty()) return Fail("navigating to " + url + ": " + error_text);
  const std::string loader = r.result.value("loaderId", std::string());
  if (loader.empty()) return true;  // same document (a #fragment): no load event
  std::unique_lock lock(impl_->mutex);
  const bool loaded = impl_->cv.wait_until(lock, deadline, [&] {
    return std::find(impl_->loaded.begin(), impl_->loaded.end(), loader) != impl_->loaded.end() ||
           impl_->pipe_closed || impl_->page_gone;
  });
  if (impl_->pipe_closed) return Fail("navigating to " + url + ": " + impl_->DeadError());
  if (impl_->page_gone) return Fail("navigating to " + url + ": " + impl_->page_gone_reason);
  if (!loaded) {
    return Fail("navigating to " + url + ": no load event within " +
                std::to_string(timeout.count()) + " ms");
  }
  return true;
}

Browser::Eval Browser::Command(const std::string& method, const nlohmann::json& params,
                               std::chrono::milliseconds timeout) {
  Impl::Reply r = impl_->Call(method, params, true, timeout);
  Eval eval{r.ok, std::move(r.result), std::move(r.error)};
  if (!eval.ok) last_error_ = eval.error;
  return eval;
}

Browser::Eval Browser::Evaluate(const std::string& expression, std::chrono::milliseconds timeout) {
  const json params = {{"expression", expression},
                       {"returnByValue", true},
                       {"awaitPromise", true},
                       {"userGesture", true}};
  const Impl::Reply r = impl_->Call("Runtime.evaluate", params, true, timeout);
  Eval eval;
  if (!r.ok) {
    eval.error = r.error;
  } else if (r.result.contains("exceptionDetails")) {
    eval.error = ExceptionText(r.result["exceptionDetails"]);
  } else {
    const json object = r.result.value("result", json::object());
    if (object.contains("value")) {
      eval.value = object["value"];
    } else if (object.contains("unserializableValue")) {
      eval.value = object["unserializableValue"];
    }
    eval.ok = true;
  }
  if (!eval.ok) last_error_ = eval.error;
  return eval;
}

bool Browser::WaitFor(const std::string& condition, std::chrono::milliseconds timeout) {
  // The condition sits on lines of its own so that a trailing // comment cannot swallow the
  // closing parenthesis.
  const std::string script =
      "new Promise((resolve) => {\n"
      "  const deadline = performance.now() + " +
      std::to_string(timeout.count()) +
      ";\n"
      "  let lastError = null;\n"
      "  const check = () => {\n"
      "    let ok = false;\n"
      "    try { ok = !!(\n" +
      condition +
      "\n); lastError = null; } catch (e) { lastError = String(e); }\n"
      "    if (ok) return resolve({ok: true});\n"
      "    if (performance.now() >= deadline) return resolve({ok: false, "
      "lastError});\n"
      "    setTimeout(check, 10);\n"
      "  };\n"
      "  check();\n"
      "})";
  // The page enforces the timeout; the C++ bound only covers a page that stops answering.
  const Eval eval = Evaluate(script, timeout + std::chrono::seconds(5));
  if (!eval.ok) return Fail("waiting for `" + condition + "`: " + eval.error);
  if (eval.value.is_object() && eval.value.value("ok", false)) return true;
  std::string error =
      "`" + condition + "` still false after " + std::to_string(timeout.count()) + " ms";
  if (eval.value.is_object() && eval.value.contains("lastError") &&
      eval.value["lastError"].is_string()) {
    error += " (it threw: " + eval.value["lastError"].get<std::string>() + ")";
  }
  return Fail(std::move(error));
}

bool Browser::Screenshot(const std::string& png_path, std::chrono::milliseconds timeout) {
  const Impl::Reply r = impl_->Call("Page.captureScreenshot", {{"format", "png"}}, true, timeout);
  if (!r.ok) return Fail("screenshot: " + r.error);
  const std::string png = DecodeBase64(r.result.value("data", std::string()));
  if (png.empty()) return Fail("screenshot: an empty image");
  std::ofstream file(png_path, std::ios::binary | std::ios::trunc);
  file.write(png.data(), static_cast<std::streamsize>(png.size()));
  file.close();
  if (!file) return Fail("screenshot: cannot write " + png_path);
  return true;
}

std::vector<std::string> Browser::ConsoleErrors() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->console_errors;
}

std::vector<std::string> Browser::ConsoleMessages() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->console_messages;
}

bool Browser::Click(const std::string& selector, std::chrono::milliseconds timeout) {
  const std::string quoted = json(selector).dump();
  const Eval eval = Evaluate("(() => { const e = document.querySelector(" + quoted +
                                 "); if (!e) throw new Error('no element matches ' + " + quoted +
                                 "); e.click(); return true; })()",
                             timeout);
  return eval.ok || Fail("click " + selector + ": " + eval.error);
}

bool Browser::SetValue(const std::string& selector, const std::string& value,
                       std::chrono::milliseconds timeout) {
  const std::string quoted = json(selector).dump();
  const Eval eval =
      Evaluate("(() => { const e = document.querySelector(" + quoted +
                   "); if (!e) throw new Error('no element matches ' + " + quoted +
                   "); e.value = " + json(value).dump() +
                   "; e.dispatchEvent(new Event('input', {bubbles: true}));"
                   " e.dispatchEvent(new Event('change', {bubbles: true})); return true; })()",
               timeout);
  return eval.ok || Fail("set value of " + selector + ": " + eval.error);
}

bool Browser::ClickAt(double x, double y, std::chrono::milliseconds timeout) {
  const auto deadline = Clock::now() + timeout;
  for (const char* type : {"mouseMoved", "mousePressed", "mouseReleased"}) {
    json params = {{"type", type}, {"x", x}, {"y", y}};
    if (std::string(type) != "mouseMoved") {
      params["button"] = "left";
      params["clickCount"] = 1;
    }
    const Impl::Reply r = impl_->Call("Input.dispatchMouseEvent", params, true,
                                      std::chrono::milliseconds(RemainingMs(deadline)));
    if (!r.ok)
      return Fail("click at (" + std::to_string(x) + ", " + std::to_string(y) + "): " + r.error);
  }
  return true;
}

std::string Browser::Stderr() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->stderr_text;
}

pid_t Browser::pid() const { return impl_->pid; }

const std::string& Browser::user_data_dir() const { return impl_->user_data_dir; }

}  // namespace stevi::testing
