#include "drivers/live_source.h"

#include <cstdio>

namespace stevi::drivers {

void InterruptWait(std::mutex& mu, bool& interrupted, std::condition_variable& cv) {
  {
    std::lock_guard lock(mu);
    interrupted = true;
  }
  cv.notify_all();
}

std::string SecondsText(std::chrono::nanoseconds d) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1f s", std::chrono::duration<double>(d).count());
  return buf;
}

std::string MillisText(int64_t ns) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1f ms", static_cast<double>(ns) / 1e6);
  return buf;
}

}  // namespace stevi::drivers
