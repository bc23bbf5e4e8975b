// libFuzzer target: a sample's JSON record through parseSampleRecord (dataset/shard.h).
#include "fuzz/dataset_inputs.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  paircast::fuzz::runSampleJsonInput({reinterpret_cast<const char*>(data), size});
  return 0;
}
