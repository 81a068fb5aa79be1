#include "system/bounded_queue.h"

#include <thread>
#include <vector>

#include <gtest/gtest.h>

namespace m2s::slam {
namespace {

TEST(BoundedQueue, DropOldestKeepsTheLatestAndCountsDrops) {
  BoundedQueue<int> q(2, BoundedQueue<int>::Policy::kDropOldest);
  for (int i = 0; i < 5; ++i) EXPECT_TRUE(q.Push(i));
  EXPECT_EQ(q.dropped(), 3);
  EXPECT_EQ(q.size(), 2u);
  EXPECT_EQ(q.Pop(), 3);
  EXPECT_EQ(q.Pop(), 4);
  EXPECT_EQ(q.TryPop(), std::nullopt);
}

TEST(BoundedQueue, StopIsEndOfStreamAfterDraining) {
  BoundedQueue<int> q(4, BoundedQueue<int>::Policy::kBlock);
  q.Push(1);
  q.Push(2);
  q.Stop();
  EXPECT_FALSE(q.Push(3));
  EXPECT_EQ(q.Pop(), 1);
  EXPECT_EQ(q.Pop(), 2);
  EXPECT_EQ(q.Pop(), std::nullopt);
  q.Restart();
  EXPECT_TRUE(q.Push(5));
  EXPECT_EQ(q.Pop(), 5);
}

TEST(BoundedQueue, StopWakesABlockedConsumerAndProducer) {
  BoundedQueue<int> q(1, BoundedQueue<int>::Policy::kBlock);
  std::optional<int> popped = 42;
  std::thread consumer([&] { popped = q.Pop(); });
  q.Stop();
  consumer.join();
  EXPECT_EQ(popped, std::nullopt);

  BoundedQueue<int> full(1, BoundedQueue<int>::Policy::kBlock);
  full.Push(1);
  bool pushed = true;
  std::thread producer([&] { pushed = full.Push(2); });  // blocks: the queue is full
  full.Stop();
  producer.join();
  EXPECT_FALSE(pushed);
}

TEST(BoundedQueue, BlockingPolicyHandsEveryItemOverInOrder) {
  BoundedQueue<int> q(2, BoundedQueue<int>::Policy::kBlock);
  constexpr int kItems = 1000;
  std::thread producer([&] {
    for (int i = 0; i < kItems; ++i) q.Push(i);
    q.Stop();
  });
  std::vector<int> got;
  while (auto v = q.Pop()) got.push_back(*v);
  producer.join();
  ASSERT_EQ(got.size(), static_cast<size_t>(kItems));
  for (int i = 0; i < kItems; ++i) EXPECT_EQ(got[i], i);
  EXPECT_EQ(q.dropped(), 0);
}

TEST(BoundedQueue, PopForTimesOut) {
  BoundedQueue<int> q(1, BoundedQueue<int>::Policy::kBlock);
  EXPECT_EQ(q.PopFor(0.01), std::nullopt);
  q.Push(7);
  EXPECT_EQ(q.PopFor(0.01), 7);
}

}  // namespace
}  // namespace m2s::slam
