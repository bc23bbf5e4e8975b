// libFuzzer target: tar shards through the trainer's index (trainer/pair_dataset.h).
#include "fuzz/trainer_inputs.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  paircast::fuzz::runShardIndexInput({reinterpret_cast<const char*>(data), size});
  return 0;
}
