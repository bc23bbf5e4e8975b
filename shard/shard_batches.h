// Pairs of crops from a ShardSet, batched by a BatchRing (util/batch_ring.h) into buffers the
// caller owns and reuses: what paircast.torch.ShardLoader runs on. Each pair's draws are those of
// paircast.torch.ShardPairs, made on the worker threads with NumPy's generator
// (util/numpy_random.h): default_rng([seed, epoch, crc32(scene), index]) draws the other view
// when the sample has more than two, then the top and left of view 1's crop, then of the other's.
// A pair that cannot be used (one view, a JPEG that does not decode) is dropped with its message
// and its batch redone with the pairs after it, so that the batches are those of a reader that
// skips it in order.
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

// One pair: view 0 of `sample` cropped to `first`, view `view` cropped to `second`.
struct PairPlan {
  size_t sample = 0;
  int view = 1;
  CropBox first, second;
};

// ShardPairs' draws for sample `sample` of `set` (throws paircast::Error, naming the sample,
// when the crop is larger than its images). A sample of one view gives view 0 and no draws.
PairPlan drawPair(const ShardSet& set, size_t sample, uint64_t seed, uint64_t epoch, int height,
                  int width);

class ShardBatches {
 public:
  struct Options {
    int batchSize = 64, height = 224, width = 224;
    int threads = 2, prefetch = 2, keep = 1;
    bool dropLast = false;
    PixelLayout layout = PixelLayout::kNormalizedFloatCHW;  // kUint8CHW or kNormalizedFloatCHW
    uint64_t seed = 0, epoch = 0;
  };
  // Buffers the caller provides: keep + prefetch, each of two [B, 3, H, W] arrays.
  static int depthOf(const Options& o) { return o.keep + o.prefetch; }

  // Batches of the samples `order` (indices into `set`), in that order. `set` and the buffers
  // must outlive this. Throws paircast::Error on a bad option or sample.
  ShardBatches(const ShardSet& set, std::vector<size_t> order, const Options& o,
               std::vector<std::array<void*, 2>> buffers);
  ~ShardBatches();

  struct Batch {
    int buffer = 0, size = 0;
    std::vector<std::string> skipped;  // the messages of the pairs dropped from it
  };
  // The next batch, whole; nullopt after the last. Rethrows a worker's error.
  std::optional<Batch> next();

 private:
  bool fill(int64_t item, int slot, int buffer);
  bool drop(int64_t item, const std::string& why);  // records why; false

  const ShardSet& set_;
  std::vector<size_t> order_;
  const Options o_;
  std::vector<std::array<void*, 2>> buffers_;
  std::mutex errorsMu_;
  std::map<int64_t, std::string> errors_;  // by item
  std::unique_ptr<BatchRing> ring_;
};

}  // namespace paircast
