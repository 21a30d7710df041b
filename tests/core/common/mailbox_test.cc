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

}  // namespace
}  // namespace stevi
