#include "tests/testing/fake_gv_camera.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>

#include "drivers/aravis/aravis_camera.h"

extern char** environ;

namespace stevi::testing {

std::string FakeGvCameraProgram() { return STEVI_ARV_FAKE_GV_CAMERA; }

FakeGvCamera::FakeGvCamera(std::string address, std::string serial, std::string log_path,
                           int lost_packets_per_thousand)
    : address_(std::move(address)),
      serial_(std::move(serial)),
      log_path_(std::move(log_path)),
      lost_per_thousand_(lost_packets_per_thousand) {}

void FakeGvCamera::Start() {
  ASSERT_LT(pid_, 0) << id() << " is already running";
  std::vector<std::string> args = {FakeGvCameraProgram(), "-i", address_, "-s", serial_};
  // To see what a camera receives: STEVI_FAKE_CAMERA_DEBUG=device:3 (in its log file, and
  // ARV_DEBUG=stream-thread:2 for this side).
  if (const char* debug = std::getenv("STEVI_FAKE_CAMERA_DEBUG")) {
    args.push_back(std::string("--debug=").append(debug));
  }
  if (lost_per_thousand_ > 0) {
    args.push_back(std::string("--gvsp-lost-ratio=").append(std::to_string(lost_per_thousand_)));
  }
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  // The log is opened here: between fork and exec only async-signal-safe calls are allowed
  // (Aravis's threads run in this process).
  const int log = open(log_path_.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  ASSERT_GE(log, 0) << log_path_ << ": " << std::strerror(errno);
  const pid_t parent = getpid();
  pid_ = fork();
  if (pid_ == 0) {
    // Dies with the test even when ctest kills it at its timeout: no orphaned cameras.
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != parent) _exit(126);
    dup2(log, STDOUT_FILENO);
    dup2(log, STDERR_FILENO);
    execv(argv[0], argv.data());
    _exit(127);
  }
  const int fork_errno = errno;
  close(log);
  ASSERT_GT(pid_, 0) << "cannot start " << args[0] << ": " << std::strerror(fork_errno);
}

void FakeGvCamera::Kill() {
  if (pid_ < 0) return;
  kill(pid_, SIGKILL);
  waitpid(pid_, nullptr, 0);  // bounded: SIGKILL cannot be caught
  pid_ = -1;
}

bool FakeGvCamera::Running() {
  if (pid_ < 0) return false;
  int status = 0;
  if (waitpid(pid_, &status, WNOHANG) == pid_) {
    pid_ = -1;
    return false;
  }
  return true;
}

std::string FakeGvCamera::Log() const {
  std::FILE* f = std::fopen(log_path_.c_str(), "r");
  if (f == nullptr) return "";
  std::string text;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) text.append(buf, n);
  std::fclose(f);
  return text;
}

void ExpectFakeCameraNetwork() {
  const char* netns = std::getenv("STEVI_FAKE_CAMERA_NETNS");
  ASSERT_TRUE(netns != nullptr && std::string(netns) == "inside")
      << "run these tests through tests/drivers/fake_camera_netns.sh (ctest does): the fake "
         "cameras need 127.0.0.2 and a private GigE Vision port";
  ASSERT_TRUE(!FakeGvCameraProgram().empty() && std::filesystem::exists(FakeGvCameraProgram()))
      << "arv-fake-gv-camera-0.8 not found ('" << FakeGvCameraProgram()
      << "'): install Debian's aravis-tools";
}

void WaitDiscoverable(const std::set<std::string>& ids, const std::vector<FakeGvCamera*>& cameras,
                      std::chrono::seconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  std::vector<drivers::DeviceEntry> devices;
  while (std::chrono::steady_clock::now() < deadline) {
    devices = drivers::ListDevices();
    std::set<std::string> found;
    for (const drivers::DeviceEntry& d : devices) found.insert(d.id);
    if (std::includes(found.begin(), found.end(), ids.begin(), ids.end())) return;
    for (FakeGvCamera* camera : cameras) {
      ASSERT_TRUE(camera == nullptr || camera->Running())
          << camera->id() << " exited: " << camera->Log();
    }
  }
  std::string present;
  for (const drivers::DeviceEntry& d : devices)
    present.append(" ").append(drivers::DescribeDevice(d));
  FAIL() << "the fake cameras were not discovered within " << timeout.count()
         << " s; present:" << present;
}

}  // namespace stevi::testing
