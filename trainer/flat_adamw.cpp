#include "trainer/flat_adamw.h"

#include <cmath>

#include "model/torch_compat.h"

namespace paircast {
namespace {

using torch::optim::AdamWOptions;
using torch::optim::AdamWParamState;

// Each parameter starts on a 64-byte boundary; the padding between them stays zero in all four
// buffers, and a zero gradient with zero moments updates nothing.
constexpr int64_t kAlign = 16;

int64_t padded(int64_t n) {
  return (n + kAlign - 1) / kAlign * kAlign;
}

AdamWParamState& stateOf(torch::optim::AdamW& opt, const torch::Tensor& p) {
  auto& state = opt.state();
  const auto key = torch_compat::optimizerStateKey(p);
  auto it = state.find(key);
  if (it == state.end()) {  // as AdamW::step makes it on a parameter's first step
    auto fresh = std::make_unique<AdamWParamState>();
    fresh->step(0);
    fresh->exp_avg(torch::zeros_like(p, torch::MemoryFormat::Preserve));
    fresh->exp_avg_sq(torch::zeros_like(p, torch::MemoryFormat::Preserve));
    it = state.emplace(key, std::move(fresh)).first;
  }
  return static_cast<AdamWParamState&>(*it->second);
}

bool viewAt(const torch::Tensor& t, const torch::Tensor& flat, int64_t offset) {
  return t.defined() && t.data_ptr() == static_cast<void*>(flat.data_ptr<float>() + offset);
}

torch::Tensor slot(const torch::Tensor& flat, int64_t offset, const torch::Tensor& like) {
  return flat.narrow(0, offset, like.numel()).view(like.sizes());
}

}  // namespace

bool FlatAdamW::applies(torch::optim::OptimizerParamGroup& group, torch::optim::AdamW& opt) const {
  if (static_cast<const AdamWOptions&>(group.options()).amsgrad()) return false;
  int64_t step = -1;
  for (const auto& p : group.params()) {
    const auto& g = p.grad();
    if (!g.defined() || p.device().type() != torch::kCPU || p.scalar_type() != torch::kFloat32 ||
        p.is_sparse() || g.is_sparse() || !p.is_contiguous() || !g.is_contiguous())
      return false;
    const auto it = opt.state().find(torch_compat::optimizerStateKey(p));
    const int64_t s =
        it == opt.state().end() ? 0 : static_cast<AdamWParamState&>(*it->second).step();
    if (step >= 0 && s != step) return false;
    step = s;
  }
  return !group.params().empty();
}

bool FlatAdamW::inPlace(torch::optim::OptimizerParamGroup& group, const Group& flat,
                        torch::optim::AdamW& opt) const {
  if (flat.offsets.size() != group.params().size()) return false;
  for (size_t i = 0; i < group.params().size(); ++i) {
    const auto& p = group.params()[i];
    const int64_t at = flat.offsets[i];
    const auto it = opt.state().find(torch_compat::optimizerStateKey(p));
    if (it == opt.state().end()) return false;
    const auto& s = static_cast<AdamWParamState&>(*it->second);
    if (!viewAt(p, flat.param, at) || !viewAt(p.grad(), flat.grad, at) ||
        !viewAt(s.exp_avg(), flat.expAvg, at) || !viewAt(s.exp_avg_sq(), flat.expAvgSq, at))
      return false;
  }
  return true;
}

FlatAdamW::Group FlatAdamW::flatten(torch::optim::OptimizerParamGroup& group,
                                    torch::optim::AdamW& opt) const {
  torch::NoGradGuard noGrad;
  Group flat;
  int64_t total = 0;
  for (const auto& p : group.params()) {
    flat.offsets.push_back(total);
    total += padded(p.numel());
  }
  const auto zeros = [&] { return torch::zeros({total}, torch::kFloat32); };
  flat.param = zeros(), flat.grad = zeros(), flat.expAvg = zeros(), flat.expAvgSq = zeros();
  for (size_t i = 0; i < group.params().size(); ++i) {
    auto& p = group.params()[i];
    const int64_t at = flat.offsets[i];
    AdamWParamState& s = stateOf(opt, p);
    const auto grad = slot(flat.grad, at, p), expAvg = slot(flat.expAvg, at, p),
               expAvgSq = slot(flat.expAvgSq, at, p);
    slot(flat.param, at, p).copy_(p);
    grad.copy_(p.grad());
    expAvg.copy_(s.exp_avg());
    expAvgSq.copy_(s.exp_avg_sq());
    p.set_(flat.param.storage(), at, p.sizes(), p.strides());
    p.mutable_grad() = grad;
    s.exp_avg(expAvg);
    s.exp_avg_sq(expAvgSq);
  }
  return flat;
}

bool FlatAdamW::step(torch::optim::AdamW& opt) {
  active_ = false;
  const size_t n = opt.param_groups().size();
  // A group already in its buffers meets applies()' conditions by construction (its tensors
  // are float32 CPU views, its moments stepped together), so only the others are checked.
  std::vector<bool> flat(n);
  for (size_t g = 0; g < n; ++g) {
    auto& group = opt.param_groups()[g];
    flat[g] = g < groups_.size() && inPlace(group, groups_[g], opt);
    if (!flat[g] && !applies(group, opt)) return false;
  }
  groups_.resize(n);
  torch::NoGradGuard noGrad;
  for (size_t g = 0; g < n; ++g) {
    auto& group = opt.param_groups()[g];
    if (!flat[g]) groups_[g] = flatten(group, opt);
    const Group& f = groups_[g];
    const auto& o = static_cast<const AdamWOptions&>(group.options());
    int64_t step = 0;
    for (const auto& p : group.params()) {
      AdamWParamState& s = stateOf(opt, p);
      s.step(s.step() + 1);
      step = s.step();
    }
    // AdamW::step's operators, in its order, on the whole group at once.
    if (o.weight_decay() != 0) f.param.mul_(1 - o.lr() * o.weight_decay());
    const auto [beta1, beta2] = o.betas();
    const double correction1 = 1 - std::pow(beta1, step);
    const double correction2 = 1 - std::pow(beta2, step);
    f.expAvg.mul_(beta1).add_(f.grad, 1 - beta1);
    f.expAvgSq.mul_(beta2).addcmul_(f.grad, f.grad, 1 - beta2);
    const auto denom = (f.expAvgSq.sqrt() / std::sqrt(correction2)).add_(o.eps());
    f.param.addcdiv_(f.expAvg, denom, -o.lr() / correction1);
  }
  active_ = true;
  return true;
}

void FlatAdamW::zeroGrad(torch::optim::AdamW& opt) {
  bool flat = groups_.size() == opt.param_groups().size();
  for (size_t g = 0; flat && g < groups_.size(); ++g)
    flat = inPlace(opt.param_groups()[g], groups_[g], opt);
  if (!flat) return opt.zero_grad();  // LibTorch's own
  torch::NoGradGuard noGrad;
  for (auto& f : groups_) f.grad.zero_();
}

}  // namespace paircast
