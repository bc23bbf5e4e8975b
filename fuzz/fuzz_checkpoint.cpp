// libFuzzer target: checkpoints through loadCheckpoint (model/checkpoint.h): the zip container
// (LibTorch's PyTorchStreamReader) and our value-only pickle reader.
#include <torch/torch.h>

#include "fuzz/model_inputs.h"

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  torch::set_num_threads(1);  // one thread: reproducible runs, no pool per input
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  paircast::fuzz::runCheckpointInput({reinterpret_cast<const char*>(data), size});
  return 0;
}
