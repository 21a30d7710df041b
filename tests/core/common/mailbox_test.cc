#include "core/common/mailbox.h"

#include <future>
#include <optional>
#include <thread>

#include <gtest/gtest.h>

namespace stevi {
namespace {

TEST(LatestMailbox, LatestWinsAndDropsAreCounted) {
  LatestMailbox<int> box;
  box.Put(1);
  box.Put(2);
  box.Put(3);
  EXPECT_EQ(box.dropped(), 2u);
  std::optional<int> got = box.Take();
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(*got, 3);

  // A value that was taken is not counted as dropped when the next one arrives.
  box.Put(4);
  EXPECT_EQ(box.dropped(), 2u);
  got = box.Take();
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(*got, 4);
}

TEST(LatestMailbox, TakeBlocksUntilPut) {
  LatestMailbox<int> box;
  std::promise<void> consumer_started;
  std::promise<int> consumer_got;
  std::thread consumer([&] {
    consumer_started.set_value();
    std::optional<int> v = box.Take();
    consumer_got.set_value(v.value_or(-1));
  });
  consumer_started.get_future().wait();
  std::future<int> got = consumer_got.get_future();
  // Nothing was put: the consumer cannot have a value. (Not a proof that it blocks, but any
  // value before Put() would be wrong; the value checked below can only come from Put().)
  EXPECT_NE(got.wait_for(std::chrono::seconds(0)), std::future_status::ready);
  box.Put(42);
  EXPECT_EQ(got.get(), 42);
  consumer.join();
  EXPECT_EQ(box.dropped(), 0u);
}

TEST(LatestMailbox, CloseWakesABlockedTake) {
  LatestMailbox<int> box;
  std::promise<void> consumer_started;
  std::promise<bool> consumer_result;
  std::thread consumer([&] {
    consumer_started.set_value();
    consumer_result.set_value(box.Take().has_value());
  });
  consumer_started.get_future().wait();
  box.Close();
  std::future<bool> result = consumer_result.get_future();
  // Generous bound only to turn a hang (a bug) into a failure rather than a timeout.
  ASSERT_EQ(result.wait_for(std::chrono::seconds(10)), std::future_status::ready);
  EXPECT_FALSE(result.get());
  consumer.join();
}

TEST(LatestMailbox, CloseStillDeliversTheLastValue) {
  LatestMailbox<int> box;
  box.Put(7);
  box.Close();
  std::optional<int> got = box.Take();
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(*got, 7);
  EXPECT_FALSE(box.Take().has_value());
}

// Two threads hand 2000 values through the slot: every one arrives, in order, none twice.
TEST(HandoffSlot, EveryValueArrivesInOrder) {
  HandoffSlot<int> slot;
  constexpr int kCount = 2000;
  std::thread producer([&] {
    for (int i = 0; i < kCount; ++i) ASSERT_TRUE(slot.Put(i));
    slot.Close();
  });
  int expected = 0;
  while (std::optional<int> v = slot.Take()) {
    ASSERT_EQ(*v, expected);
    ++expected;
  }
  producer.join();
  EXPECT_EQ(expected, kCount);
}

// A full slot makes Put() wait for a Take(); Close() releases a waiting Put() with false.
TEST(HandoffSlot, PutWaitsWhileFullAndCloseReleasesIt) {
  HandoffSlot<int> slot;
  ASSERT_TRUE(slot.Put(1));
  std::promise<bool> second_put;
  std::thread producer([&] { second_put.set_value(slot.Put(2)); });
  std::future<bool> put = second_put.get_future();
  EXPECT_NE(put.wait_for(std::chrono::seconds(0)), std::future_status::ready);
  EXPECT_EQ(slot.Take(), std::optional<int>(1));
  EXPECT_TRUE(put.get());  // the Take() made room
  producer.join();

  std::promise<bool> third_put;
  std::thread blocked([&] { third_put.set_value(slot.Put(3)); });  // the slot holds 2: waits
  slot.Close();
  EXPECT_FALSE(third_put.get_future().get());
  blocked.join();
  EXPECT_EQ(slot.Take(), std::optional<int>(2));  // what was left, then nothing
  EXPECT_EQ(slot.Take(), std::nullopt);
}

}  // namespace
}  // namespace stevi
