// Batches filled in order by worker threads into a fixed ring of buffers that the consumer owns
// and reuses for the whole run, so that a steady state allocates nothing. Slot j of batch b is
// filled into buffer b % depth once the consumer has let go of the batch that used the buffer
// before (batch b - depth). The loaders of the pre-trainer (trainer/batch_loader.h) and of
// Python (paircast.torch.ShardLoader, shard/shard_batches.h) are this ring with their own fill.
//
// Items are numbered over the whole run: batch b holds items [b B, min((b + 1) B, items)), so
// the last batch may be short.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <exception>
#include <functional>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>

namespace paircast {

class BatchRing {
 public:
  // Fills item `item` (slot `slot` of batch `batch`) into buffer `buffer`. Returns false when the
  // item cannot be used (the consumer then redoes the batch without it); an exception stops the
  // ring and is rethrown by next().
  using Fill = std::function<bool(int64_t item, int64_t batch, int slot, int buffer)>;

  struct Options {
    int threads = 1;
    int batchSize = 1;
    int prefetch = 2;   // batches filled ahead of the one the consumer takes
    int keep = 1;       // batches the consumer holds: the last `keep` returned stay intact
    int64_t first = 0;  // the first batch
    int64_t items = 0;  // items in the run
    bool dropLast = false;
  };

  struct Ready {
    int64_t batch = 0;
    int buffer = 0;
    int size = 0;             // items in the batch (batchSize but for a short last one)
    std::vector<int> failed;  // slots whose fill returned false
  };

  BatchRing(const Options& o, Fill fill);
  ~BatchRing();
  BatchRing(const BatchRing&) = delete;
  BatchRing& operator=(const BatchRing&) = delete;

  // Buffers the consumer must provide: keep + prefetch.
  int depth() const { return depth_; }
  static int depthOf(const Options& o) { return o.keep + o.prefetch; }

  // The next batch, filled; nullopt after the last one. The buffers of the `keep` batches
  // returned last are not written until the consumer takes another. Rethrows a fill's exception.
  std::optional<Ready> next();
  // Redoes the batch next() returned last, and the ones after it. With the workers stopped,
  // `edit` changes the consumer's plan (drops the failed items) and returns the count of items
  // left.
  void redo(const std::function<int64_t()>& edit);

 private:
  // Under mu_: the batches of the run; the items a worker may take; the size of a batch (0 past
  // the last); whether it is filled.
  int64_t batches() const;
  int64_t issueLimit() const;
  int sizeOf(int64_t batch) const;
  bool complete(int64_t batch) const;
  bool canIssue() const;
  void work();

  const Options o_;
  const int depth_;
  Fill fill_;
  std::mutex mu_;
  std::condition_variable cv_;
  int64_t items_;
  int64_t taken_;            // the next batch next() returns
  int64_t issue_;            // the next item a worker takes
  int inFlight_ = 0;         // fills under way
  uint64_t generation_ = 0;  // bumped by redo(): fills of an older one are discarded
  struct BufferState {
    int64_t batch = -1;
    int done = 0;
    std::vector<int> failed;
  };
  std::vector<BufferState> buffers_;
  std::exception_ptr failure_;
  bool stop_ = false, paused_ = false;
  std::vector<std::thread> threads_;
};

}  // namespace paircast
