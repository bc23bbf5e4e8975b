// libFuzzer target: fine-tuning checkpoints through loadFinetuned (finetune/finetune.h).
#include <torch/torch.h>

#include "fuzz/finetune_inputs.h"

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  torch::set_num_threads(1);  // one thread: reproducible runs, no pool per input
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  paircast::fuzz::runFinetuneCheckpointInput({reinterpret_cast<const char*>(data), size});
  return 0;
}
