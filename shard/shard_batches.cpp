#include "shard/shard_batches.h"

#include <algorithm>
#include <cstring>

#include "util/error.h"

namespace paircast {

ShardBatches::ShardBatches(const ShardSet& set, const Options& o,
                           std::vector<std::array<void*, 2>> buffers)
    : set_(set), o_(o), buffers_(std::move(buffers)) {
  if (o.batchSize < 1 || o.height < 1 || o.width < 1 || o.threads < 1 || o.prefetch < 1 ||
      o.keep < 0)
    throw Error("ShardBatches: batch size, crop, threads and prefetch must be positive");
  if (o.layout != PixelLayout::kUint8CHW && o.layout != PixelLayout::kNormalizedFloatCHW)
    throw Error("ShardBatches: the layout must be uint8 or normalised float32, [3, H, W]");
  if (static_cast<int>(buffers_.size()) != depthOf(o))
    throw Error("ShardBatches: " + std::to_string(depthOf(o)) + " buffers needed, " +
                std::to_string(buffers_.size()) + " given");
  plan_.reserve(o.capacity);
  BatchRing::Options r;
  r.threads = o.threads;
  r.batchSize = o.batchSize;
  r.prefetch = o.prefetch;
  r.keep = o.keep;
  r.items = 0;
  r.final = false;
  r.dropLast = o.dropLast;
  ring_ = std::make_unique<BatchRing>(
      r, [this](int64_t item, int64_t, int slot, int buffer) { return fill(item, slot, buffer); });
}

ShardBatches::~ShardBatches() {
  ring_.reset();  // the workers stop before the plan goes
}

size_t ShardBatches::slotBytes() const {
  const size_t element = o_.layout == PixelLayout::kUint8CHW ? 1 : sizeof(float);
  return size_t{3} * o_.height * o_.width * element;
}

void ShardBatches::plan(const std::vector<PairPlan>& pairs, bool final) {
  if (final_) throw Error("ShardBatches: the plan is already complete");
  if (count_ + pairs.size() > o_.capacity)
    throw Error("ShardBatches: more pairs planned than the capacity of " +
                std::to_string(o_.capacity));
  for (const PairPlan& p : pairs) {
    if (p.sample >= set_.size())
      throw Error("ShardBatches: sample " + std::to_string(p.sample) + " of " +
                  std::to_string(set_.size()));
    for (const CropBox* box : {&p.first, &p.second})
      if (box->height != o_.height || box->width != o_.width)
        throw Error("ShardBatches: a crop of " + std::to_string(box->height) + "x" +
                    std::to_string(box->width) + " in batches of " + std::to_string(o_.height) +
                    "x" + std::to_string(o_.width));
    plan_.push_back(p);  // within the reserved capacity: the workers' reads stay valid
  }
  count_ = plan_.size();
  final_ = final;
  ring_->extend(static_cast<int64_t>(count_), final);
}

bool ShardBatches::fill(int64_t item, int slot, int buffer) {
  const PairPlan& p = plan_[static_cast<size_t>(item)];
  const size_t offset = slotBytes() * slot;
  try {
    set_.decodeView(p.sample, 0, p.first, o_.layout, static_cast<char*>(buffers_[buffer][0]) + offset);
    set_.decodeView(p.sample, p.view, p.second, o_.layout,
                    static_cast<char*>(buffers_[buffer][1]) + offset);
    return true;
  } catch (const Error& e) {
    std::lock_guard<std::mutex> lock(errorsMu_);
    errors_[item] = e.what();
    return false;
  }
}

std::optional<ShardBatches::Batch> ShardBatches::next() {
  Batch out;
  if (!final_ && count_ < static_cast<size_t>((taken_ + 1) * o_.batchSize)) {
    out.buffer = -1;
    return out;
  }
  while (true) {
    auto r = ring_->next();
    if (!r) return std::nullopt;
    if (r->failed.empty()) {
      out.buffer = r->buffer;
      out.size = r->size;
      ++taken_;
      return out;
    }
    // Drop the failed pairs from the plan and redo this batch and the ones after it.
    ring_->redo(
        [&] {
          const int64_t first = r->batch * o_.batchSize;
          std::lock_guard<std::mutex> lock(errorsMu_);
          for (int slot : r->failed) out.skipped.push_back(errors_[first + slot]);
          for (auto it = r->failed.rbegin(); it != r->failed.rend(); ++it)
            plan_.erase(plan_.begin() + first + *it);
          errors_.clear();
          count_ = plan_.size();
          return static_cast<int64_t>(count_);
        },
        final_);
    if (!final_ && count_ < static_cast<size_t>((r->batch + 1) * o_.batchSize)) {
      out.buffer = -1;  // the plan must grow before the batch can be redone
      return out;
    }
  }
}

}  // namespace paircast
