#include "client/cli/stop_signals.h"

#include <pthread.h>
#include <signal.h>

#include <condition_variable>
#include <csignal>
#include <cstdlib>
#include <mutex>
#include <thread>
#include <utility>

#include "client/lib/thread_name.h"

namespace stevi::client::commands {

namespace {

// Shared with the detached signal thread, which may outlive main(): never destroyed.
struct StopState {
  std::mutex mu;
  std::condition_variable cv;
  std::function<void()> handler;  // guarded by mu
  bool running = false;           // guarded by mu: the handler is being called
};
StopState& StopSignalState() {
  static StopState* state = new StopState;
  return *state;
}

}  // namespace

void HandleStopSignals() {
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGINT);
  sigaddset(&stop_signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);
  // Detached: the process exits when the command returns.
  StopSignalState();  // made before the thread starts
  std::thread([stop_signals] {
    NameThisThread("stevi-signals");
    for (int received = 0;; ++received) {
      int signal_number = 0;
      if (sigwait(&stop_signals, &signal_number) != 0) continue;
      StopState& stop = StopSignalState();
      std::function<void()> handler;
      {
        std::lock_guard lock(stop.mu);
        handler = stop.handler;
        stop.running = handler != nullptr;
      }
      if (received > 0 || !handler) std::_Exit(128 + signal_number);
      handler();
      {
        std::lock_guard lock(stop.mu);
        stop.running = false;
      }
      stop.cv.notify_all();
    }
  }).detach();
}

void OnStopSignal(std::function<void()> handler) {
  // A handler refers to the command's objects: it must have returned before the command replaces
  // it and destroys them (`stevi mavlink` crashed at a SIGTERM when its Bridge went away while the
  // signal thread was still in Bridge::Stop()).
  StopState& stop = StopSignalState();
  std::unique_lock lock(stop.mu);
  stop.cv.wait(lock, [&stop] { return !stop.running; });
  stop.handler = std::move(handler);
}

}  // namespace stevi::client::commands
