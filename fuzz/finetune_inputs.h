// Fuzz entry point for finetune/: fine-tuning checkpoints through loadFinetuned, as finetune
// --predict and --evaluate read them: the container and pickle (loadCheckpoint), the
// configuration (croco_kwargs, task, head, head_kwargs) checked against the file's tensors, the
// DownstreamNet it builds, and the strict load of its weights. See fuzz_inputs.h.
#pragma once

#include "finetune/finetune.h"
#include "fuzz/fuzz_inputs.h"

namespace paircast::fuzz {

inline bool runFinetuneCheckpointInput(std::string_view bytes,
                                       const std::string& dir = scratchDir()) {
  const std::string path = writeInput(bytes, dir, "input.pth");
  return acceptedOrRefused([&] { loadFinetuned(path); });
}

}  // namespace paircast::fuzz
