// Aravis's fake GigE Vision camera (arv-fake-gv-camera-0.8, Debian's aravis-tools) as a real
// network peer in tests. Run such tests through tests/drivers/fake_camera_netns.sh, which gives
// them 127.0.0.2 and a private GigE Vision port.
#pragma once

#include <sys/types.h>

#include <chrono>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace stevi::testing {

// The program's path, found by CMake (STEVI_ARV_FAKE_GV_CAMERA); empty when it is missing.
std::string FakeGvCameraProgram();

// One arv-fake-gv-camera-0.8 process, its output in a log file. Killed (SIGKILL) and reaped on
// destruction.
class FakeGvCamera {
 public:
  FakeGvCamera(std::string address, std::string serial, std::string log_path,
               int lost_packets_per_thousand = 0);
  ~FakeGvCamera() { Kill(); }
  FakeGvCamera(const FakeGvCamera&) = delete;
  FakeGvCamera& operator=(const FakeGvCamera&) = delete;

  // The device id Aravis gives it.
  std::string id() const { return std::string("Aravis-Fake-").append(serial_); }
  const std::string& serial() const { return serial_; }
  const std::string& address() const { return address_; }

  // Starts the process (or fails the test saying why).
  void Start();
  // SIGKILL: the camera vanishes as on a power cut, without releasing anything.
  void Kill();
  // True while the process runs (false when it exited, e.g. because its address is missing).
  bool Running();
  std::string Log() const;

 private:
  std::string address_, serial_, log_path_;
  int lost_per_thousand_ = 0;
  pid_t pid_ = -1;
};

// Fails the test unless it runs inside fake_camera_netns.sh and the fake camera program exists.
void ExpectFakeCameraNetwork();

// Polls Aravis's discovery (about 1 s a round) until every id answers; fails the test after
// `timeout`, listing what is present, or as soon as one of `cameras` exited.
void WaitDiscoverable(const std::set<std::string>& ids, const std::vector<FakeGvCamera*>& cameras,
                      std::chrono::seconds timeout = std::chrono::seconds(15));

}  // namespace stevi::testing
