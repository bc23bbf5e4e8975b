// AdamW's step on the CPU over flat buffers. LibTorch's AdamW::step runs about ten ATen
// operators per parameter (some 1,300 a step for the tiny model, 4,000 with its gradient
// zeroing and bookkeeping), each a dispatch and a pass over a small tensor; the operator
// profile (trainer/op_profile.h) put them at a quarter of a 64-pixel step. Here each parameter
// group's parameters, gradients and both moments become views into one contiguous buffer each,
// so that a step is the same update as a dozen operators per group, and zeroing the gradients
// one fill.
#pragma once

#include <vector>

#include <torch/torch.h>

namespace paircast {

class FlatAdamW {
 public:
  // Steps `opt` over flat buffers, with the arithmetic of LibTorch's AdamW::step (decoupled
  // weight decay, the bias corrections, eps outside the square root) on the optimizer's own
  // state, so checkpoints and --resume see no difference. The first step, and any after the
  // tensors were replaced (a restored checkpoint), moves them into the buffers. Returns false,
  // having changed nothing, where it does not apply: amsgrad; a parameter that is not a dense,
  // contiguous float32 CPU tensor; a group whose parameters do not all have gradients, or whose
  // moments are at different steps. The caller then calls opt.step().
  bool step(torch::optim::AdamW& opt);

  // Zeroes the gradients: where every group is flat, one fill per group, in place (as LibTorch
  // 1.13's zero_grad does; LibTorch 2's would set them undefined and undo the views); else
  // opt.zero_grad().
  void zeroGrad(torch::optim::AdamW& opt);

  // Whether the last step() ran over flat buffers.
  bool active() const { return active_; }

 private:
  struct Group {
    torch::Tensor param, grad, expAvg, expAvgSq;  // [total] each
    std::vector<int64_t> offsets;                 // each parameter's first element
  };
  bool applies(torch::optim::OptimizerParamGroup& group, torch::optim::AdamW& opt) const;
  bool inPlace(torch::optim::OptimizerParamGroup& group, const Group& flat,
               torch::optim::AdamW& opt) const;
  Group flatten(torch::optim::OptimizerParamGroup& group, torch::optim::AdamW& opt) const;

  std::vector<Group> groups_;
  bool active_ = false;
};

}  // namespace paircast
