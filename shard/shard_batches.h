// Pairs of crops from a ShardSet, batched by a BatchRing (util/batch_ring.h) into buffers the
// caller owns and reuses: what paircast.torch.ShardLoader runs on. Each pair's draws are those of
// paircast.torch.ShardPairs, made on the worker threads with NumPy's generator
// (util/numpy_random.h): default_rng([seed, epoch, crc32(scene), index]) draws the other view
// when the sample has more than two, then the top and left of view 1's crop, then of the other's.
// A pair that cannot be used (one view, a JPEG that does not decode) is dropped with its message
// and its batch redone with the pairs after it, so that the batches are those of a reader that
// skips it in order. With Options::flow each pair also gets its exact ground truth, as
// ShardPairs(flow=True) gives it: view 1's flow cut to its crop and moved into view 2's crop,
// where it is known, and view 2's pose in view 1's camera (the pair is then always views 1, 2).
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
#include "util/camera.h"
#include "util/image.h"

namespace paircast {

// One pair: view 0 of `sample` cropped to `first`, view `view` cropped to `second`.
struct PairPlan {
  size_t sample = 0;
  int view = 1;
  CropBox first, second;
};

// ShardPairs' draws for sample `sample` of `set` (throws paircast::Error, naming the sample,
// when the crop is larger than its images). A sample of one view gives view 0 and no draws;
// with `flow` the other view is view 1, without a draw.
PairPlan drawPair(const ShardSet& set, size_t sample, uint64_t seed, uint64_t epoch, int height,
                  int width, bool flow = false);

// The ground truth of a pair (Options::flow), where the caller wants it: a view's flow
// [B, 2, H, W] (pixels, +inf unknown), where it is known [B, H, W] (1 or 0), and the relative
// pose [B, 4, 4] (float64).
struct TruthBuffers {
  float* flow = nullptr;
  uint8_t* valid = nullptr;
  double* pose = nullptr;
};

// View `from`'s flow cut to its crop and moved into the frame of the other view's crop `to`
// (paircast.torch.crop_flow): [2, H, W] and its validity [H, W].
void cropFlow(const ImageF& flow, const CropBox& from, const CropBox& to, float* out,
              uint8_t* valid);
// Camera 2's pose in camera 1's frame, [4, 4] row-major (paircast.torch.relative_pose).
void relativePose(const Camera& camera1, const Camera& camera2, double* out);

class ShardBatches {
 public:
  struct Options {
    int batchSize = 64, height = 224, width = 224;
    int threads = 2, prefetch = 2, keep = 1;
    bool dropLast = false;
    bool flow = false;  // also each pair's ground truth, into `truth`
    PixelLayout layout = PixelLayout::kNormalizedFloatCHW;  // kUint8CHW or kNormalizedFloatCHW
    uint64_t seed = 0, epoch = 0;
  };
  // Buffers the caller provides: keep + prefetch, each of two [B, 3, H, W] arrays.
  static int depthOf(const Options& o) { return o.keep + o.prefetch; }

  // Batches of the samples `order` (indices into `set`), in that order. `set` and the buffers
  // must outlive this. With o.flow, `truth` holds a TruthBuffers per buffer. Throws
  // paircast::Error on a bad option or sample.
  ShardBatches(const ShardSet& set, std::vector<size_t> order, const Options& o,
               std::vector<std::array<void*, 2>> buffers, std::vector<TruthBuffers> truth = {});
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
  std::vector<TruthBuffers> truth_;
  std::mutex errorsMu_;
  std::map<int64_t, std::string> errors_;  // by item
  std::unique_ptr<BatchRing> ring_;
};

}  // namespace paircast
