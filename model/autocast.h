// Mixed precision on CUDA: autocast to bf16 (or fp16) for the scope of a guard, plus TF32
// matmuls.
#pragma once

#include <ATen/autocast_mode.h>
#include <torch/torch.h>

#include "model/torch_compat.h"

namespace paircast {

class AutocastGuard {
 public:
  // Does nothing unless `enabled` (callers pass "device is CUDA").
  AutocastGuard(bool enabled, at::ScalarType dtype = at::kBFloat16) : enabled_(enabled) {
    if (enabled_) torch_compat::enableCudaAutocast(dtype);
  }
  ~AutocastGuard() {
    if (!enabled_) return;
    torch_compat::disableCudaAutocast();
    at::autocast::clear_cache();
  }
  AutocastGuard(const AutocastGuard&) = delete;
  AutocastGuard& operator=(const AutocastGuard&) = delete;

 private:
  bool enabled_;
};

// TF32 for float32 matmuls and convolutions on Ampere and later.
inline void allowTf32() {
  at::globalContext().setAllowTF32CuBLAS(true);
  at::globalContext().setAllowTF32CuDNN(true);
}

}  // namespace paircast
