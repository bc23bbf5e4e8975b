// AdamW's update as one fused CUDA kernel per parameter group: at::_fused_adamw_, the kernel
// behind Python's torch.optim.AdamW(fused=True). LibTorch's C++ AdamWOptions has no fused
// flag, and its AdamW::step launches about ten small kernels per parameter (some 1,500 per step
// for the base model).
#pragma once

#include <torch/torch.h>

namespace paircast {

// Whether this LibTorch has the fused kernel (2.1 and later).
bool fusedAdamWCompiled();

// Steps `opt` with the fused kernel, on the optimizer's own state (exp_avg, exp_avg_sq and the
// integer step of AdamWParamState), so checkpoints and --resume see no difference; the update
// is AdamW's (decoupled weight decay, bias corrections, eps outside the square root). Returns
// false, having changed nothing, where it does not apply: LibTorch older than 2.1, a parameter
// that is not a float32 CUDA tensor, or amsgrad. The caller then calls opt.step().
bool fusedAdamWStep(torch::optim::AdamW& opt);

}  // namespace paircast
