// Fuzz entry point for model/: checkpoints through loadCheckpoint. See fuzz_inputs.h.
#pragma once

#include "fuzz/fuzz_inputs.h"
#include "model/checkpoint.h"

namespace paircast::fuzz {

inline bool runCheckpointInput(std::string_view bytes, const std::string& dir = scratchDir()) {
  const std::string path = writeInput(bytes, dir, "input.pth");
  return acceptedOrRefused([&] { loadCheckpoint(path); });
}

}  // namespace paircast::fuzz
