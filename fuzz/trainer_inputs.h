// Fuzz entry point for trainer/: tar shards through the trainer's own index (PairDataset reads
// the ustar headers itself, then each pair's JPEGs with pread). See fuzz_inputs.h.
#pragma once

#include "fuzz/fuzz_inputs.h"
#include "trainer/pair_dataset.h"

namespace paircast::fuzz {

inline bool runShardIndexInput(std::string_view bytes, const std::string& dir = scratchDir()) {
  const std::string path = writeInput(bytes, dir, "input.tar");
  return acceptedOrRefused([&] {
    const PairDataset ds = PairDataset::fromShards({path});
    // A member that does not decode is refused pair by pair, as the trainer's loader does.
    for (size_t i = 0; i < ds.size(); ++i) acceptedOrRefused([&] { ds.load(i); });
  });
}

}  // namespace paircast::fuzz
