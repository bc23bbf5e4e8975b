#include "util/batch_ring.h"

#include <algorithm>

#include "util/error.h"

namespace paircast {

BatchRing::BatchRing(const Options& o, Fill fill)
    : o_(o),
      depth_(depthOf(o)),
      fill_(std::move(fill)),
      items_(o.items),
      taken_(o.first),
      issue_(o.first * o.batchSize),
      buffers_(depth_) {
  PAIRCAST_CHECK(o.threads >= 1 && o.batchSize >= 1 && o.prefetch >= 1 && o.keep >= 0);
  for (int t = 0; t < o.threads; ++t) threads_.emplace_back([this] { work(); });
}

BatchRing::~BatchRing() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stop_ = true;
  }
  cv_.notify_all();
  for (auto& t : threads_) t.join();
}

int64_t BatchRing::batches() const {
  const int64_t b = o_.batchSize;
  return o_.dropLast ? items_ / b : (items_ + b - 1) / b;
}

int64_t BatchRing::issueLimit() const {
  return std::min(items_, batches() * o_.batchSize);
}

int BatchRing::sizeOf(int64_t batch) const {
  const int64_t begin = batch * o_.batchSize, end = begin + o_.batchSize;
  if (end <= items_) return o_.batchSize;
  if (batch >= batches()) return 0;
  return static_cast<int>(items_ - begin);
}

bool BatchRing::complete(int64_t batch) const {
  const BufferState& s = buffers_[batch % depth_];
  const int size = sizeOf(batch);
  return size > 0 && s.batch == batch && s.done == size;
}

bool BatchRing::canIssue() const {
  return !paused_ && issue_ < issueLimit() && issue_ / o_.batchSize < taken_ + o_.prefetch;
}

void BatchRing::work() {
  std::unique_lock<std::mutex> lock(mu_);
  while (true) {
    cv_.wait(lock, [&] { return stop_ || failure_ || canIssue(); });
    if (stop_ || failure_) return;
    const int64_t item = issue_++, batch = item / o_.batchSize;
    const int slot = static_cast<int>(item % o_.batchSize),
              buffer = static_cast<int>(batch % depth_);
    if (slot == 0) buffers_[buffer] = BufferState{batch, 0, {}};
    const uint64_t generation = generation_;
    ++inFlight_;
    lock.unlock();
    bool ok = false;
    std::exception_ptr error;
    try {
      ok = fill_(item, batch, slot, buffer);
    } catch (...) {
      error = std::current_exception();
    }
    lock.lock();
    --inFlight_;
    if (generation == generation_) {
      if (error) failure_ = error;
      BufferState& s = buffers_[buffer];
      ++s.done;
      if (!ok && !error) s.failed.push_back(slot);
    }
    cv_.notify_all();
  }
}

std::optional<BatchRing::Ready> BatchRing::next() {
  std::unique_lock<std::mutex> lock(mu_);
  const int64_t batch = taken_;
  cv_.wait(lock, [&] { return failure_ || complete(batch) || batch >= batches(); });
  if (failure_) std::rethrow_exception(failure_);
  if (!complete(batch)) return std::nullopt;
  const BufferState& s = buffers_[batch % depth_];
  Ready r{batch, static_cast<int>(batch % depth_), s.done, s.failed};
  std::sort(r.failed.begin(), r.failed.end());
  ++taken_;
  cv_.notify_all();
  return r;
}

void BatchRing::redo(const std::function<int64_t()>& edit) {
  std::unique_lock<std::mutex> lock(mu_);
  PAIRCAST_CHECK(taken_ > o_.first);
  paused_ = true;
  ++generation_;
  cv_.wait(lock, [&] { return inFlight_ == 0; });
  const int64_t batch = taken_ - 1;
  for (BufferState& s : buffers_)
    if (s.batch >= batch) s = BufferState{};
  items_ = edit();
  taken_ = batch;
  issue_ = batch * o_.batchSize;
  paused_ = false;
  lock.unlock();
  cv_.notify_all();
}

}  // namespace paircast
