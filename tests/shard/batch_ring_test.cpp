// BatchRing: batches in order, each buffer left alone while the consumer holds it, a run that
// starts at a later batch, a redone batch, a worker's error rethrown, and a stop at any point.
#include "util/batch_ring.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <stdexcept>
#include <thread>

namespace paircast {
namespace {

// Each fill writes its item into the slot of a buffer, after a short varying wait, and checks
// that the consumer does not hold that buffer.
struct Recorder {
  explicit Recorder(const BatchRing::Options& o)
      : slots(BatchRing::depthOf(o), std::vector<int64_t>(o.batchSize, -1)),
        held(BatchRing::depthOf(o)) {}
  bool fill(int64_t item, int slot, int buffer) {
    if (held[buffer]) overwrote = true;
    std::this_thread::sleep_for(std::chrono::microseconds(item * 37 % 200));
    slots[buffer][slot] = item;
    ++calls;
    return true;
  }
  std::vector<std::vector<int64_t>> slots;
  std::vector<std::atomic<bool>> held;
  std::atomic<bool> overwrote{false};
  std::atomic<int> calls{0};
};

BatchRing::Options options(int threads, int batch, int64_t items) {
  BatchRing::Options o;
  o.threads = threads;
  o.batchSize = batch;
  o.prefetch = 2;
  o.keep = 2;
  o.items = items;
  return o;
}

TEST(BatchRing, GivesBatchesInOrderAndNeverWritesAHeldBuffer) {
  for (int threads : {1, 3}) {
    const auto o = options(threads, 4, 50);
    Recorder r(o);
    BatchRing ring(
        o, [&](int64_t item, int64_t, int slot, int buffer) { return r.fill(item, slot, buffer); });
    std::vector<int> order;  // buffers taken, the last `keep` of them held
    int64_t expected = 0;
    while (true) {
      // Taking the next batch lets go of the one that leaves the last `keep`.
      if (order.size() >= 2) r.held[order[order.size() - 2]] = false;
      auto b = ring.next();
      if (!b) break;
      r.held[b->buffer] = true;
      order.push_back(b->buffer);
      EXPECT_EQ(b->batch, expected++);
      EXPECT_EQ(b->size, b->batch < 12 ? 4 : 2);  // 50 = 12 x 4 + 2
      EXPECT_TRUE(b->failed.empty());
      for (int j = 0; j < b->size; ++j) EXPECT_EQ(r.slots[b->buffer][j], b->batch * 4 + j);
      std::this_thread::sleep_for(std::chrono::microseconds(300));  // the consumer at work
    }
    EXPECT_EQ(expected, 13);
    EXPECT_EQ(r.calls, 50);
    EXPECT_FALSE(r.overwrote) << threads << " threads";
    EXPECT_FALSE(ring.next());  // and stays at the end
  }
}

TEST(BatchRing, DropsAShortLastBatchWhenAsked) {
  auto o = options(2, 4, 10);
  o.dropLast = true;
  Recorder r(o);
  BatchRing ring(
      o, [&](int64_t item, int64_t, int slot, int buffer) { return r.fill(item, slot, buffer); });
  int batches = 0;
  while (ring.next()) ++batches;
  EXPECT_EQ(batches, 2);
  EXPECT_EQ(r.calls, 8);  // the two items of the short batch were never filled
}

TEST(BatchRing, StartsAtItsFirstBatch) {
  auto o = options(2, 3, 20);
  o.first = 5;  // a run that resumes at batch 5: items from 15
  Recorder r(o);
  BatchRing ring(
      o, [&](int64_t item, int64_t, int slot, int buffer) { return r.fill(item, slot, buffer); });
  auto first = ring.next();
  ASSERT_TRUE(first);
  EXPECT_EQ(first->batch, 5);
  EXPECT_EQ(r.slots[first->buffer][0], 15);
  auto second = ring.next();
  ASSERT_TRUE(second);
  EXPECT_EQ(second->size, 2);  // batch 6 ends short
  EXPECT_FALSE(ring.next());
  EXPECT_EQ(r.calls, 5);  // the items before batch 5 were never filled
}

TEST(BatchRing, RedoesABatchWithoutItsFailedItems) {
  const auto o = options(2, 4, 12);
  std::vector<int64_t> plan(12);
  for (int i = 0; i < 12; ++i) plan[i] = 100 + i;
  std::vector<std::vector<int64_t>> slots(BatchRing::depthOf(o), std::vector<int64_t>(4));
  BatchRing ring(o, [&](int64_t item, int64_t, int slot, int buffer) {
    if (plan[item] == 105 || plan[item] == 107) return false;  // unusable items
    slots[buffer][slot] = plan[item];
    return true;
  });
  auto b = ring.next();
  ASSERT_TRUE(b && b->failed.empty());
  b = ring.next();
  ASSERT_TRUE(b);
  EXPECT_EQ(b->failed, (std::vector<int>{1, 3}));
  ring.redo([&] {
    plan.erase(plan.begin() + 7);
    plan.erase(plan.begin() + 5);
    return static_cast<int64_t>(plan.size());
  });
  b = ring.next();
  ASSERT_TRUE(b && b->failed.empty());
  EXPECT_EQ(b->batch, 1);
  EXPECT_EQ(slots[b->buffer], (std::vector<int64_t>{104, 106, 108, 109}));
  b = ring.next();
  ASSERT_TRUE(b);
  EXPECT_EQ(b->size, 2);
  EXPECT_EQ(slots[b->buffer][1], 111);
  EXPECT_FALSE(ring.next());
}

TEST(BatchRing, RethrowsAFillsErrorInOrder) {
  const auto o = options(3, 4, 40);
  BatchRing ring(o, [&](int64_t item, int64_t, int, int) -> bool {
    if (item == 6) throw std::runtime_error("item 6 is broken");
    return true;
  });
  try {
    while (ring.next()) {
    }
    FAIL() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_STREQ(e.what(), "item 6 is broken");
  }
}

TEST(BatchRing, StopsAtAnyPoint) {
  for (int taken : {0, 1, 5}) {
    auto o = options(2, 8, std::numeric_limits<int64_t>::max() / 2);
    std::atomic<int> calls{0};
    {
      BatchRing ring(o, [&](int64_t, int64_t, int, int) {
        ++calls;
        return true;
      });
      for (int i = 0; i < taken; ++i) ASSERT_TRUE(ring.next());
    }  // joins: no hang, no fill after
    const int after = calls;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
    EXPECT_EQ(calls, after);
    EXPECT_LE(after, (taken + 2) * 8);  // never more than the prefetch ahead
  }
}

}  // namespace
}  // namespace paircast
