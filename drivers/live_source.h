// What the sources whose Next() waits for capture threads (Aravis cameras, GStreamer pipelines)
// share: interrupting that wait, and the durations in their messages.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>

namespace stevi::drivers {

// A source's Interrupt(): sets `interrupted` under `mu` (Next() checks it under `mu` before and
// after each wait on `cv`) and wakes every waiter on `cv`.
void InterruptWait(std::mutex& mu, bool& interrupted, std::condition_variable& cv);

// "2.5 s" (one decimal).
std::string SecondsText(std::chrono::nanoseconds d);
// "16.7 ms" (one decimal), from nanoseconds.
std::string MillisText(int64_t ns);

}  // namespace stevi::drivers
