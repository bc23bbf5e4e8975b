// Replays the fuzz_shard_index seeds and kept findings (fuzz/corpus/, tests/regressions/) through
// the target's own entry point (fuzz/trainer_inputs.h). A crash here is a regression.
#include <gtest/gtest.h>

#include "fuzz/trainer_inputs.h"
#include "test_paths.h"

namespace paircast {
namespace {

TEST(RegressionInputs, ShardIndex) {
  const std::string dir = testing::scratchDir("shard_index");
  testing::replayFuzzInputs("fuzz_shard_index",
                            [&](const std::string& b) { return fuzz::runShardIndexInput(b, dir); });
}

}  // namespace
}  // namespace paircast
