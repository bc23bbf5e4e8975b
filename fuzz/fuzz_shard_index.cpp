// libFuzzer target: tar shards through the shard codec's index (shard/shard_index.h), as the
// trainer and ShardSet read them.
#include "fuzz/trainer_inputs.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  paircast::fuzz::runShardIndexInput({reinterpret_cast<const char*>(data), size});
  return 0;
}
