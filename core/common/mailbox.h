// A one-slot mailbox where the latest value wins: a slow consumer never builds a backlog.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <optional>
#include <utility>

namespace stevi {

// Thread-safe. One or more producers Put(); consumers Take() the newest value.
template <typename T>
class LatestMailbox {
 public:
  // Stores `value`, replacing (and counting as dropped) any value not yet taken.
  void Put(T value) {
    {
      std::lock_guard lock(mu_);
      if (slot_.has_value()) ++dropped_;
      slot_ = std::move(value);
    }
    cv_.notify_one();
  }

  // Blocks until a value is there or Close() is called; nullopt once closed and empty.
  std::optional<T> Take() {
    std::unique_lock lock(mu_);
    cv_.wait(lock, [&] { return slot_.has_value() || closed_; });
    if (!slot_.has_value()) return std::nullopt;
    std::optional<T> out = std::move(slot_);
    slot_.reset();
    return out;
  }

  // Wakes every waiter; later Take() calls return what is left, then nullopt.
  void Close() {
    {
      std::lock_guard lock(mu_);
      closed_ = true;
    }
    cv_.notify_all();
  }

  // Values replaced before anyone took them.
  uint64_t dropped() const {
    std::lock_guard lock(mu_);
    return dropped_;
  }

 private:
  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::optional<T> slot_;
  bool closed_ = false;
  uint64_t dropped_ = 0;
};

}  // namespace stevi
