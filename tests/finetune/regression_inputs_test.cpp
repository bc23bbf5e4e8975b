// Replays the fuzz_finetune_checkpoint seeds and kept findings (fuzz/corpus/,
// tests/regressions/) through the target's own entry point (fuzz/finetune_inputs.h), and
// fuzz_shard_index's through its entry point with fine-tuning's reader (TruthPairs) compiled in,
// as that target is built beside paircast_finetune (fuzz/trainer_inputs.h). A crash here is a
// regression.
#include <gtest/gtest.h>

#include "fuzz/finetune_inputs.h"
#include "fuzz/trainer_inputs.h"
#include "test_paths.h"

#ifndef PAIRCAST_FUZZ_FINETUNE
#error "tests/CMakeLists.txt sets PAIRCAST_FUZZ_FINETUNE for this file"
#endif

namespace paircast {
namespace {

TEST(RegressionInputs, FinetuneCheckpoint) {
  const std::string dir = testing::scratchDir("ckpt");
  testing::replayFuzzInputs("fuzz_finetune_checkpoint", [&](const std::string& b) {
    return fuzz::runFinetuneCheckpointInput(b, dir);
  });
}

TEST(RegressionInputs, ShardIndexTruthPairs) {
  const std::string dir = testing::scratchDir("shard_index");
  testing::replayFuzzInputs("fuzz_shard_index",
                            [&](const std::string& b) { return fuzz::runShardIndexInput(b, dir); });
}

}  // namespace
}  // namespace paircast
