// Fuzz entry point for the shard codec's index (shard/shard_index.h), as its readers use it: the
// trainer's PairDataset (then each pair's JPEGs), ShardSet (each view's crop decoded straight
// into its layout and its .flo flow, as paircast.torch.ShardPairs does), and, where
// PAIRCAST_FUZZ_FINETUNE is set (paircast_finetune linked), fine-tuning's TruthPairs (JPEGs, flow
// and EXR depth of each pair). See fuzz_inputs.h.
#pragma once

#include "fuzz/fuzz_inputs.h"
#include "shard/shard_set.h"
#include "trainer/pair_dataset.h"
#ifdef PAIRCAST_FUZZ_FINETUNE
#include "finetune/finetune_data.h"
#endif

namespace paircast::fuzz {

inline bool runShardIndexInput(std::string_view bytes, const std::string& dir = scratchDir()) {
  const std::string path = writeInput(bytes, dir, "input.tar");
  acceptedOrRefused([&] {
    const ShardSet set = ShardSet::open({path});
    std::vector<float> out;
    for (size_t i = 0; i < set.size(); ++i) {
      for (int k = 0; k < set[i].record.views; ++k) {
        const Camera& c = set[i].record.camera[k];
        if (static_cast<size_t>(c.width) * c.height > (1u << 22)) continue;  // bounded memory
        out.resize(3 * static_cast<size_t>(c.width) * c.height);
        acceptedOrRefused([&] {
          set.decodeView(i, k, CropBox{0, 0, c.height, c.width}, PixelLayout::kNormalizedFloatCHW,
                         out.data());
        });
      }
      acceptedOrRefused([&] { set.decodeFlow(i, 0); });
    }
  });
#ifdef PAIRCAST_FUZZ_FINETUNE
  // The whole shard is refused when a sample lacks flow or depth; a pair, when a member is bad.
  acceptedOrRefused([&] {
    const TruthPairs pairs = TruthPairs::fromShards({path});
    for (size_t i = 0; i < pairs.size(); ++i) acceptedOrRefused([&] { pairs.load(i); });
  });
#endif
  return acceptedOrRefused([&] {
    const PairDataset ds = PairDataset::fromShards({path});
    // A member that does not decode is refused pair by pair, as the trainer's loader does.
    for (size_t i = 0; i < ds.size(); ++i) acceptedOrRefused([&] { ds.load(i); });
  });
}

}  // namespace paircast::fuzz
