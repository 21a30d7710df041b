#include "server/runtime/broadcaster.h"

#include <gtest/gtest.h>

#include <atomic>
#include <thread>

namespace stevi::server {
namespace {

using Sub = Subscription<int>;

TEST(Subscription, DropsTheOldestWhenFullAndCountsIt) {
  Sub sub(1, "peer", 3);
  for (int i = 1; i <= 5; ++i) sub.Push(i);
  EXPECT_EQ(sub.dropped(), 2u);
  std::vector<int> got;
  for (Sub::Popped p = sub.Pop(); p.state == Sub::PopState::kItem; p = sub.Pop()) {
    got.push_back(*p.item);
    EXPECT_EQ(p.dropped, 2u);
  }
  EXPECT_EQ(got, (std::vector<int>{3, 4, 5}));
  EXPECT_EQ(sub.sent(), 3u);
}

TEST(Subscription, NotifiesOnceAfterAnEmptyPop) {
  Sub sub(1, "peer", 4);
  int notified = 0;
  sub.SetNotify([&] { ++notified; });
  sub.Push(1);
  EXPECT_EQ(notified, 0) << "nobody was waiting";
  EXPECT_EQ(sub.Pop().state, Sub::PopState::kItem);
  EXPECT_EQ(sub.Pop().state, Sub::PopState::kEmpty);  // now waiting
  sub.Push(2);
  sub.Push(3);
  EXPECT_EQ(notified, 1);
  sub.Detach();
  EXPECT_EQ(sub.Pop().state, Sub::PopState::kItem);
  EXPECT_EQ(sub.Pop().state, Sub::PopState::kItem);
  EXPECT_EQ(sub.Pop().state, Sub::PopState::kEmpty);
  sub.Push(4);
  EXPECT_EQ(notified, 1) << "detached: never notified again";
}

TEST(Subscription, EndDrainsThenEnds) {
  Sub sub(1, "peer", 4);
  sub.Push(1);
  sub.End();
  sub.Push(2);  // ignored after the end
  EXPECT_EQ(sub.Pop().state, Sub::PopState::kItem);
  EXPECT_EQ(sub.Pop().state, Sub::PopState::kEnded);
}

TEST(Broadcaster, ASlowSubscriberLosesOnlyItsOwnFrames) {
  Broadcaster<int> b(4, 8);
  auto fast = b.Subscribe("fast");
  auto slow = b.Subscribe("slow");
  ASSERT_TRUE(fast && slow);
  std::vector<int> fast_got;
  for (int i = 1; i <= 100; ++i) {
    b.Publish(i);
    Sub::Popped p = fast->Pop();  // the fast one keeps up
    ASSERT_EQ(p.state, Sub::PopState::kItem);
    fast_got.push_back(*p.item);
  }
  EXPECT_EQ(fast->dropped(), 0u);
  EXPECT_EQ(fast_got.front(), 1);
  EXPECT_EQ(fast_got.back(), 100);
  EXPECT_EQ(slow->dropped(), 96u);
  EXPECT_EQ(*slow->Pop().item, 97);

  const auto stats = b.Stats();
  ASSERT_EQ(stats.size(), 2u);
  EXPECT_EQ(stats[0].peer, "fast");
  EXPECT_EQ(stats[0].sent, 100u);
  EXPECT_EQ(stats[1].dropped, 96u);
}

TEST(Broadcaster, LimitsSubscribersAndRefusesAfterClose) {
  Broadcaster<int> b(2, 2);
  auto a = b.Subscribe("a");
  auto c = b.Subscribe("c");
  EXPECT_EQ(b.Subscribe("over"), nullptr);
  b.Unsubscribe(a->id());
  auto d = b.Subscribe("d");
  EXPECT_NE(d, nullptr);
  b.Close();
  EXPECT_EQ(c->Pop().state, Sub::PopState::kEnded);
  EXPECT_EQ(b.Subscribe("late"), nullptr);
}

TEST(Broadcaster, ConcurrentPublishAndConsumeLosesNothingWithRoom) {
  constexpr int kFrames = 2000;
  Broadcaster<int> b(kFrames, 4);
  auto sub = b.Subscribe("consumer");
  std::atomic<int> next{1};
  bool in_order = true;
  std::thread consumer([&] {
    std::mutex mu;
    std::condition_variable cv;
    bool wake = false;
    sub->SetNotify([&] {
      std::lock_guard lock(mu);
      wake = true;
      cv.notify_one();
    });
    while (next.load() <= kFrames) {
      Sub::Popped p = sub->Pop();
      if (p.state == Sub::PopState::kItem) {
        in_order = in_order && *p.item == next.load();
        ++next;
      } else {
        std::unique_lock lock(mu);
        cv.wait(lock, [&] { return wake; });
        wake = false;
      }
    }
    sub->Detach();
  });
  for (int i = 1; i <= kFrames; ++i) b.Publish(i);
  consumer.join();
  EXPECT_TRUE(in_order);
  EXPECT_EQ(sub->dropped(), 0u);
  EXPECT_EQ(sub->sent(), static_cast<uint64_t>(kFrames));
}

}  // namespace
}  // namespace stevi::server
