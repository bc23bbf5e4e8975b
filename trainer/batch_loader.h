// The pre-trainer's batches: pairs from shards, CroCo folders and the live stream, read by worker
// threads a window ahead of the training step, each pair cropped (only the crop is decoded),
// jittered, normalised and masked with random streams keyed by its position, so that a batch
// depends only on its position, whatever the number of workers.
//
// Legend: B batch, S crop side, N patches.
#pragma once

#include <torch/torch.h>

#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "model/croco_config.h"
#include "trainer/trainer.h"

namespace paircast {

class PairDataset;

struct Batch {
  torch::Tensor img1, img2;  // [B, 3, S, S] normalised float32, or uint8 crops (see jitter)
  torch::Tensor mask;        // [B, N] bool, true = masked
  // For uint8 batches: each image's colour jitter, [B, 4] float32 (the order of brightness,
  // contrast and saturation packed as 100 a + 10 b + c, then the three factors), applied by
  // finishBatch. Undefined for float32 batches.
  torch::Tensor jitter1, jitter2;
  bool isUint8() const { return jitter1.defined(); }
};

// The batch on `device`, float32 and normalised: a float32 batch is copied; a uint8 one is
// copied (a quarter of the bytes) and jittered and normalised there (jitterAndNormalizeBatch).
// non_blocking copies: the buffers are pinned on CUDA, and the caller's next synchronisation
// (the loss's .item()) comes before the loader may fill them again.
Batch finishBatch(const Batch& batch, const torch::Device& device);

// Whether `c` asks for uint8 batches (batchFormat, "auto" on `device`). Throws paircast::Error
// on an unknown format.
bool uint8Batches(const TrainConfig& c);

// CroCo's RandomMask (argsort(noise) < num_mask) with the noise drawn from a stream keyed by
// the sample, so that masks do not depend on how samples are split over batches and ranks.
torch::Tensor sampleMask(const CroCoConfig& m, uint64_t seed, const std::string& stream,
                         uint64_t key);
// The same into `out` (numPatches() bools).
void sampleMaskInto(const CroCoConfig& m, uint64_t seed, const std::string& stream, uint64_t key,
                    bool* out);

// One weighted data source: a dataset on disk, or the live stream (dataset == nullptr).
struct Source {
  const PairDataset* dataset = nullptr;
  double weight = 1.0;
  std::string name;
};

// Batches in a fixed order. With one disk source, batch b of epoch e holds the pairs
// perm_e[b B .. (b+1) B). With several sources, slot g of the run draws its source with the
// weights and its pair uniformly, from a stream keyed by g. Workers prefetch a window ahead;
// live slots are filled in order by get(), from a stream that resumes at `livePosition`.
class BatchLoader {
 public:
  // Rank `rank` of `world` reads slice `rank` of each global batch of world x batchSize pairs.
  BatchLoader(std::vector<Source> sources, const TrainConfig& c, int64_t startIter, int rank,
              int world, uint64_t livePosition = 0);
  ~BatchLoader();
  BatchLoader(const BatchLoader&) = delete;
  BatchLoader& operator=(const BatchLoader&) = delete;

  int64_t perEpoch() const;
  // Pairs drawn from each source by get() so far, by source name.
  nlohmann::json counts() const;
  // The batch of iteration `iter` (iterations are taken in order). Rethrows a worker's error.
  Batch get(int64_t iter);
  // Where the live stream stands, for checkpoints (0 without one).
  uint64_t livePosition() const;

 private:
  class Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace paircast
