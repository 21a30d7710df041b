// The `stevi` commands' stop signals (client/cli/stop_signals.h): a SIGTERM calls the command's
// handler on the signal thread, and replacing the handler waits for a running one to return, so a
// command can destroy what its handler refers to right after OnStopSignal(nullptr). `stevi
// mavlink` crashed (SIGSEGV) at a SIGTERM when its Bridge was destroyed while Bridge::Stop() was
// still running on the signal thread.
#include <gtest/gtest.h>

#include <signal.h>
#include <unistd.h>

#include <chrono>
#include <condition_variable>
#include <mutex>
#include <thread>

#include "client/cli/stop_signals.h"

namespace stevi::client::commands {
namespace {

TEST(StopSignal, ReplacingTheHandlerWaitsForTheRunningOneToReturn) {
  HandleStopSignals();  // first, before this test starts a thread of its own
  std::mutex mu;
  std::condition_variable cv;
  bool entered = false, release = false, returned = false;
  OnStopSignal([&] {
    std::unique_lock lock(mu);
    entered = true;
    cv.notify_all();
    cv.wait(lock, [&] { return release; });
    returned = true;
  });
  ASSERT_EQ(kill(getpid(), SIGTERM), 0);
  {
    std::unique_lock lock(mu);
    ASSERT_TRUE(cv.wait_for(lock, std::chrono::seconds(30), [&] { return entered; }))
        << "the handler was not called";
  }
  bool replaced = false, returned_before_replaced = false;
  std::thread replacer([&] {
    OnStopSignal(nullptr);
    std::lock_guard lock(mu);
    replaced = true;
    returned_before_replaced = returned;
    cv.notify_all();
  });
  {
    // While the handler is held, the replacement must not happen. Half a second proves nothing
    // about longer, but a replacement that does not wait happens within microseconds.
    std::unique_lock lock(mu);
    EXPECT_FALSE(cv.wait_for(lock, std::chrono::milliseconds(500), [&] { return replaced; }))
        << "OnStopSignal(nullptr) returned while the handler was still running";
    release = true;
  }
  cv.notify_all();
  replacer.join();
  EXPECT_TRUE(returned_before_replaced);
}

}  // namespace
}  // namespace stevi::client::commands
