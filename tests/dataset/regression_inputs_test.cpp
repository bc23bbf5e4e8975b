// Replays the fuzz targets' seeds and kept findings (fuzz/corpus/<target>/,
// tests/regressions/<target>/) through the targets' own entry points (fuzz/dataset_inputs.h).
// A crash or a sanitizer report here is a regression.
#include <gtest/gtest.h>

#include "fuzz/dataset_inputs.h"
#include "test_paths.h"

namespace paircast {
namespace {

TEST(RegressionInputs, Shard) {
  const std::string dir = testing::scratchDir("shard");
  testing::replayFuzzInputs("fuzz_shard",
                            [&](const std::string& b) { return fuzz::runShardInput(b, dir); });
}

TEST(RegressionInputs, SampleJson) {
  testing::replayFuzzInputs("fuzz_sample_json",
                            [](const std::string& b) { return fuzz::runSampleJsonInput(b); });
}

}  // namespace
}  // namespace paircast
