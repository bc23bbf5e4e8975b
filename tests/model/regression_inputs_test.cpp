// Replays the fuzz_checkpoint seeds (torch.save files) and kept findings (fuzz/corpus/,
// tests/regressions/) through the target's own entry point (fuzz/model_inputs.h). A crash here
// is a regression.
#include <gtest/gtest.h>

#include "fuzz/model_inputs.h"
#include "test_paths.h"

namespace paircast {
namespace {

TEST(RegressionInputs, Checkpoint) {
  const std::string dir = testing::scratchDir("ckpt");
  testing::replayFuzzInputs("fuzz_checkpoint",
                            [&](const std::string& b) { return fuzz::runCheckpointInput(b, dir); });
}

}  // namespace
}  // namespace paircast
