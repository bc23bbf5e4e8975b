#include "trainer/fused_adamw.h"

#include <map>
#include <memory>
#include <vector>

#include "model/torch_compat.h"

namespace paircast {

bool fusedAdamWCompiled() {
  return torch_compat::kHasFusedAdamW;
}

bool fusedAdamWStep(torch::optim::AdamW& opt) {
  if (!torch_compat::kHasFusedAdamW) return false;
  using torch::optim::AdamWOptions;
  using torch::optim::AdamWParamState;
  for (auto& group : opt.param_groups()) {
    if (static_cast<const AdamWOptions&>(group.options()).amsgrad()) return false;
    for (const auto& p : group.params())
      if (p.grad().defined() && (!p.is_cuda() || p.scalar_type() != torch::kFloat32)) return false;
  }
  torch::NoGradGuard noGrad;
  auto& state = opt.state();
  for (auto& group : opt.param_groups()) {
    const auto& o = static_cast<const AdamWOptions&>(group.options());
    std::vector<torch::Tensor> params, grads, expAvg, expAvgSq, steps;
    std::map<int64_t, torch::Tensor> stepTensors;  // one 0-d tensor per distinct step value
    for (auto& p : group.params()) {
      if (!p.grad().defined()) continue;
      const auto key = torch_compat::optimizerStateKey(p);
      if (state.find(key) == state.end()) {
        auto fresh = std::make_unique<AdamWParamState>();
        fresh->step(0);
        fresh->exp_avg(torch::zeros_like(p, torch::MemoryFormat::Preserve));
        fresh->exp_avg_sq(torch::zeros_like(p, torch::MemoryFormat::Preserve));
        state[key] = std::move(fresh);
      }
      auto& s = static_cast<AdamWParamState&>(*state[key]);
      if (s.exp_avg().device() != p.device()) {  // restored from a checkpoint on the CPU
        s.exp_avg(s.exp_avg().to(p.device()));
        s.exp_avg_sq(s.exp_avg_sq().to(p.device()));
      }
      s.step(s.step() + 1);  // the kernel reads the incremented step, as Python's _fused_adamw
      auto& t = stepTensors[s.step()];
      if (!t.defined())
        t = torch::scalar_tensor(static_cast<double>(s.step()), p.options().dtype(torch::kFloat32));
      params.push_back(p);
      grads.push_back(p.grad());
      expAvg.push_back(s.exp_avg());
      expAvgSq.push_back(s.exp_avg_sq());
      steps.push_back(t);
    }
    if (params.empty()) continue;
    torch_compat::fusedAdamW(params, grads, expAvg, expAvgSq, steps, o.lr(), std::get<0>(o.betas()),
                             std::get<1>(o.betas()), o.weight_decay(), o.eps());
  }
  return true;
}

}  // namespace paircast
