// Fine-tuning data: pairs from tar shards written with generate_pairs --save-flow --save-depth,
// with their exact ground truth (views 1 and 2 of each sample: shards keep view 1's flow into
// view 2). Samples are located once through the shard index and decoded when a batch needs them.
//
// Legend: B batch, S crop side, H x W the stored images.
#pragma once

#include <torch/torch.h>

#include <string>
#include <vector>

#include "shard/shard_index.h"
#include "util/camera.h"
#include "util/image.h"

namespace paircast {

// One decoded pair with its ground truth, at the stored size.
struct TruthPair {
  std::string key;
  Image8 rgb1, rgb2;      // [H, W, 3]
  ImageF flow;            // [H, W, 2] view 1 into view 2, pixels, +inf where unknown
  ImageF depth1, depth2;  // [H, W, 1] z-depth, 0 where nothing was hit
  Camera camera1, camera2;
};

class TruthPairs {
 public:
  // Shards (files or glob patterns). Throws paircast::Error naming the shard when a sample has
  // no flow or no depth (write them with generate_pairs --save-flow --save-depth), or when none
  // matches a pattern.
  static TruthPairs fromShards(const std::vector<std::string>& patterns);

  size_t size() const { return items_.size(); }
  // Decodes pair i. Throws paircast::Error naming the shard member on corruption.
  TruthPair load(size_t i) const;
  const std::string& key(size_t i) const;
  // The side of the stored images (all pairs share it).
  int side() const { return side_; }

 private:
  struct Item {
    size_t index;   // of indexes_
    size_t sample;  // in that index
  };
  std::vector<ShardIndex> indexes_;
  std::vector<Item> items_;
  int side_ = 0;
};

// What a training batch holds, on the CPU (finished on the device by the task).
struct TruthBatch {
  torch::Tensor img1, img2;  // [B, 3, S, S] normalised float32
  torch::Tensor flow;        // [B, 2, S, S] pixels, +inf unknown
  torch::Tensor depth;       // [B, 1, S, S] metres, 0 unknown
  torch::Tensor pose;        // [B, 12] view 2 in view 1's camera: R row-major, then t (float32)
  TruthBatch to(const torch::Device& device) const;
};

struct TruthAugment {
  int size = 224;           // the crop, drawn once per pair at the same place in both views
  bool colorJitter = true;  // CroCo's factors in [0.6, 1.4], drawn per image
  bool swap = false;        // pose: the views swapped with probability 1/2 (and the pose inverted)
};

// The batch of `pairs` (pair indices) at slots firstSlot, firstSlot + 1, ... of step `step`, each
// with draws from a stream keyed by (seed, step, slot), so a batch depends only on its position
// and not on how a global batch is split over ranks.
TruthBatch makeTruthBatch(const TruthPairs& data, const std::vector<size_t>& pairs,
                          const TruthAugment& augment, uint64_t seed, int64_t step,
                          size_t firstSlot = 0);

// The pose of view 2 in view 1's camera as [12] (R row-major, t).
torch::Tensor poseVector(const Camera& camera1, const Camera& camera2);
// Image tensors: uint8 [H, W, 3] -> normalised [1, 3, H, W]; float [H, W, C] -> [1, C, H, W].
torch::Tensor normalizedImage(const Image8& rgb);
torch::Tensor planes(const ImageF& image);

}  // namespace paircast
