// Fan-out of results to subscribers, one bounded queue each. No gRPC here.
#pragma once

#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace stevi::server {

// One subscriber's queue. Thread-safe. When full, the oldest entry is dropped and counted, so a
// slow consumer never slows the producer or the other subscribers.
template <typename T>
class Subscription {
 public:
  enum class PopState { kItem, kEmpty, kEnded };
  struct Popped {
    PopState state = PopState::kEmpty;
    std::optional<T> item;
    uint64_t dropped = 0;  // entries dropped so far for this subscriber
  };

  Subscription(uint64_t id, std::string peer, size_t capacity)
      : id_(id), peer_(std::move(peer)), capacity_(capacity == 0 ? 1 : capacity) {}

  uint64_t id() const { return id_; }
  const std::string& peer() const { return peer_; }

  // Called once by the consumer: `notify` runs (on the producer's thread) when an entry arrives
  // or the subscription ends while the consumer is waiting (see Pop()). It must not call Detach().
  void SetNotify(std::function<void()> notify) {
    std::lock_guard lock(notify_mu_);
    notify_ = std::move(notify);
  }

  // After Detach() returns, `notify` is not running and will never run again.
  void Detach() {
    std::lock_guard lock(notify_mu_);
    notify_ = nullptr;
  }

  void Push(T item) {
    bool wake = false;
    {
      std::lock_guard lock(mu_);
      if (ended_) return;
      if (queue_.size() >= capacity_) {
        queue_.pop_front();
        ++dropped_;
      }
      queue_.push_back(std::move(item));
      wake = std::exchange(waiting_, false);
    }
    if (wake) Notify();
  }

  // Ends the subscription: Pop() returns what is queued, then kEnded.
  void End() {
    bool wake = false;
    {
      std::lock_guard lock(mu_);
      ended_ = true;
      wake = std::exchange(waiting_, false);
    }
    if (wake) Notify();
  }

  // Takes the oldest entry. When there is none, the consumer is marked as waiting and will be
  // notified once, at the next Push() or End().
  Popped Pop() {
    std::lock_guard lock(mu_);
    Popped out;
    out.dropped = dropped_;
    if (!queue_.empty()) {
      out.state = PopState::kItem;
      out.item = std::move(queue_.front());
      queue_.pop_front();
      ++sent_;
    } else if (ended_) {
      out.state = PopState::kEnded;
    } else {
      waiting_ = true;
    }
    return out;
  }

  uint64_t sent() const {
    std::lock_guard lock(mu_);
    return sent_;
  }
  uint64_t dropped() const {
    std::lock_guard lock(mu_);
    return dropped_;
  }

 private:
  void Notify() {
    std::lock_guard lock(notify_mu_);
    if (notify_) notify_();
  }

  const uint64_t id_;
  const std::string peer_;
  const size_t capacity_;
  mutable std::mutex mu_;
  std::deque<T> queue_;
  bool waiting_ = false;
  bool ended_ = false;
  uint64_t dropped_ = 0;
  uint64_t sent_ = 0;
  std::mutex notify_mu_;
  std::function<void()> notify_;
};

// Gives every published entry to every subscriber's queue. Thread-safe.
template <typename T>
class Broadcaster {
 public:
  struct SubscriberStats {
    uint64_t id = 0;
    std::string peer;
    uint64_t sent = 0;
    uint64_t dropped = 0;
  };

  Broadcaster(size_t queue_capacity, size_t max_subscribers)
      : capacity_(queue_capacity), max_subscribers_(max_subscribers) {}

  // nullptr when max_subscribers are already subscribed or the broadcaster was closed.
  std::shared_ptr<Subscription<T>> Subscribe(std::string peer) {
    std::lock_guard lock(mu_);
    if (closed_ || subs_.size() >= max_subscribers_) return nullptr;
    auto sub = std::make_shared<Subscription<T>>(next_id_++, std::move(peer), capacity_);
    subs_.emplace(sub->id(), sub);
    return sub;
  }

  void Unsubscribe(uint64_t id) {
    std::lock_guard lock(mu_);
    subs_.erase(id);
  }

  void Publish(const T& item) {
    for (const auto& sub : Snapshot()) sub->Push(item);
  }

  // Ends every subscription and refuses new ones (shutdown). Returns how many it ended.
  size_t Close() {
    std::vector<std::shared_ptr<Subscription<T>>> subs;
    {
      std::lock_guard lock(mu_);
      closed_ = true;
      for (auto& [id, sub] : subs_) subs.push_back(sub);
    }
    for (const auto& sub : subs) sub->End();
    return subs.size();
  }

  bool closed() const {
    std::lock_guard lock(mu_);
    return closed_;
  }

  std::vector<SubscriberStats> Stats() const {
    std::vector<SubscriberStats> out;
    for (const auto& sub : Snapshot()) {
      out.push_back({sub->id(), sub->peer(), sub->sent(), sub->dropped()});
    }
    return out;
  }

  size_t size() const {
    std::lock_guard lock(mu_);
    return subs_.size();
  }

 private:
  std::vector<std::shared_ptr<Subscription<T>>> Snapshot() const {
    std::lock_guard lock(mu_);
    std::vector<std::shared_ptr<Subscription<T>>> out;
    out.reserve(subs_.size());
    for (const auto& [id, sub] : subs_) out.push_back(sub);
    return out;
  }

  const size_t capacity_;
  const size_t max_subscribers_;
  mutable std::mutex mu_;
  std::map<uint64_t, std::shared_ptr<Subscription<T>>> subs_;
  uint64_t next_id_ = 1;
  bool closed_ = false;
};

}  // namespace stevi::server
