// Mixed precision for the scope of a guard, on the CPU or CUDA, as Python's torch.autocast: the
// previous state comes back at the end and nested guards share one cache of cast weights, which
// the outermost clears. Plus TF32 matmuls on CUDA.
#pragma once

#include <ATen/autocast_mode.h>
#include <torch/torch.h>

#include "model/precision.h"
#include "model/torch_compat.h"

namespace paircast {

class AutocastGuard {
 public:
  // Autocast on `device` (kCPU or kCUDA) to `dtype` where `enabled`, off where not.
  AutocastGuard(at::DeviceType device, bool enabled, at::ScalarType dtype = at::kBFloat16)
      : device_(device),
        wasEnabled_(torch_compat::isAutocast(device)),
        wasDtype_(torch_compat::autocastDtype(device)) {
    torch_compat::setAutocast(device, enabled, dtype);
    at::autocast::increment_nesting();
  }
  // The precision a run resolved (model/precision.h).
  explicit AutocastGuard(const Precision& p) : AutocastGuard(p.device, p.autocast(), p.dtype()) {}
  ~AutocastGuard() {
    if (at::autocast::decrement_nesting() == 0) at::autocast::clear_cache();
    torch_compat::setAutocast(device_, wasEnabled_, wasDtype_);
  }
  AutocastGuard(const AutocastGuard&) = delete;
  AutocastGuard& operator=(const AutocastGuard&) = delete;

 private:
  at::DeviceType device_;
  bool wasEnabled_;
  at::ScalarType wasDtype_;
};

// TF32 for float32 matmuls and convolutions on Ampere and later.
inline void allowTf32() {
  at::globalContext().setAllowTF32CuBLAS(true);
  at::globalContext().setAllowTF32CuDNN(true);
}

}  // namespace paircast
