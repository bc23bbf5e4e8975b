// Replays the fuzz_flo and fuzz_exr seeds (members of generate_pairs' shards) and kept findings
// (fuzz/corpus/, tests/regressions/) through the targets' own entry points (fuzz/util_inputs.h),
// in both builds: the trainer-only one reads these members too. A crash here is a regression.
#include <gtest/gtest.h>

#include "fuzz/util_inputs.h"
#include "test_paths.h"

namespace paircast {
namespace {

TEST(RegressionInputs, Flo) {
  testing::replayFuzzInputs("fuzz_flo", [](const std::string& b) { return fuzz::runFloInput(b); });
}

TEST(RegressionInputs, Exr) {
#ifndef PAIRCAST_HAVE_OPENEXR_CORE  // tests/CMakeLists.txt; the full build always has it
  GTEST_SKIP() << "no EXR decoder in this trainer-only build (OpenEXR not found)";
#endif
  testing::replayFuzzInputs("fuzz_exr", [](const std::string& b) { return fuzz::runExrInput(b); });
}

}  // namespace
}  // namespace paircast
