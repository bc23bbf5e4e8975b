// Pairs of crops from a ShardSet, batched by a BatchRing (util/batch_ring.h) into buffers the
// caller owns and reuses: what paircast.torch.ShardLoader runs on. The caller plans each pair
// (its sample, the other view, the two crops) with its own random draws, ahead of the workers.
// A pair that does not decode is dropped with its message and the batch is redone with the pairs
// after it, so that the batches are those of a reader that skips it in order.
//
// Legend: B pairs per batch, H, W the crop.
#pragma once

#include <array>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "shard/shard_set.h"
#include "util/batch_ring.h"

namespace paircast {

// One planned pair: view 0 of `sample` cropped to `first`, view `view` cropped to `second`.
struct PairPlan {
  size_t sample = 0;
  int view = 1;
  CropBox first, second;
};

class ShardBatches {
 public:
  struct Options {
    int batchSize = 64, height = 224, width = 224;
    int threads = 2, prefetch = 2, keep = 1;
    bool dropLast = false;
    PixelLayout layout = PixelLayout::kNormalizedFloatCHW;  // kUint8CHW or kNormalizedFloatCHW
    size_t capacity = 0;  // the most pairs the plan will hold
  };
  // Buffers the caller provides: keep + prefetch, each of two [B, 3, H, W] arrays.
  static int depthOf(const Options& o) { return o.keep + o.prefetch; }

  // `set` and the buffers must outlive this. Throws paircast::Error on a bad option.
  ShardBatches(const ShardSet& set, const Options& o, std::vector<std::array<void*, 2>> buffers);
  ~ShardBatches();

  // Appends planned pairs (checked against the set and the crop); `final`: no more will come.
  void plan(const std::vector<PairPlan>& pairs, bool final);
  size_t planned() const { return count_; }
  int64_t taken() const { return taken_; }

  // Pairs the plan should hold for the workers to fill every batch they may.
  size_t wanted() const { return static_cast<size_t>((taken_ + 1 + o_.prefetch) * o_.batchSize); }

  struct Batch {
    int buffer = 0, size = 0;  // buffer -1: the plan must grow (plan()) before the next batch
    std::vector<std::string> skipped;  // the messages of the pairs dropped from it
  };
  // The next batch, whole; nullopt after the last; buffer -1 when the plan, not final, holds too
  // few pairs for it (after a pair was dropped, say).
  std::optional<Batch> next();

 private:
  bool fill(int64_t item, int slot, int buffer);
  size_t slotBytes() const;

  const ShardSet& set_;
  const Options o_;
  std::vector<std::array<void*, 2>> buffers_;
  std::vector<PairPlan> plan_;  // capacity reserved: appends never move it
  size_t count_ = 0;
  bool final_ = false;
  int64_t taken_ = 0;
  std::mutex errorsMu_;
  std::map<int64_t, std::string> errors_;  // by item
  std::unique_ptr<BatchRing> ring_;
};

}  // namespace paircast
