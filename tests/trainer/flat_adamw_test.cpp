#include "trainer/flat_adamw.h"

#include <gtest/gtest.h>

#include "model/torch_compat.h"

namespace paircast {
namespace {

using torch::optim::AdamW;
using torch::optim::AdamWOptions;
using torch::optim::AdamWParamState;

struct Net : torch::nn::Module {
  Net() {
    a = register_module("a", torch::nn::Linear(7, 33));
    norm = register_module("norm", torch::nn::LayerNorm(torch::nn::LayerNormOptions({33})));
    b = register_module("b", torch::nn::Linear(33, 5));
  }
  torch::Tensor forward(const torch::Tensor& x) { return b(norm(a(x)).relu()); }
  torch::nn::Linear a{nullptr}, b{nullptr};
  torch::nn::LayerNorm norm{nullptr};
};

// Two groups as the training loop makes them: weights with decay, biases and norms without.
std::unique_ptr<AdamW> optimizerOf(Net& net, bool amsgrad = false) {
  std::vector<torch::Tensor> decay, plain;
  for (const auto& p : net.named_parameters())
    (p.key().find("weight") != std::string::npos && p.key().rfind("norm", 0) != 0 ? decay : plain)
        .push_back(p.value());
  AdamWOptions o(1e-2);
  o.betas({0.9, 0.95}).weight_decay(0.05).amsgrad(amsgrad);
  std::vector<torch::optim::OptimizerParamGroup> groups;
  groups.emplace_back(decay, std::make_unique<AdamWOptions>(o));
  groups.emplace_back(plain, std::make_unique<AdamWOptions>(AdamWOptions(o).weight_decay(0)));
  return std::make_unique<AdamW>(groups, o);
}

void copyWeights(Net& from, Net& to) {
  torch::NoGradGuard noGrad;
  auto src = from.parameters(), dst = to.parameters();
  for (size_t i = 0; i < src.size(); ++i) dst[i].copy_(src[i]);
}

void backward(Net& net, int step) {
  torch::manual_seed(100 + step);
  const auto x = torch::randn({16, 7});
  net.forward(x).pow(2).mean().backward();
}

double largestDifference(Net& x, Net& y) {
  double worst = 0;
  auto px = x.parameters(), py = y.parameters();
  for (size_t i = 0; i < px.size(); ++i)
    worst = std::max(worst, (px[i] - py[i]).abs().max().item<double>());
  return worst;
}

// Steps [first, last) of both: LibTorch's AdamW on `reference`, FlatAdamW on `flat`, the same
// gradients for each.
void stepBoth(Net& reference, AdamW& refOpt, Net& flat, AdamW& flatOpt, FlatAdamW& flatStep,
              int first, int last) {
  for (int step = first; step < last; ++step) {
    backward(reference, step);
    backward(flat, step);
    refOpt.step();
    ASSERT_TRUE(flatStep.step(flatOpt));
    EXPECT_TRUE(flatStep.active());
    refOpt.zero_grad();
    flatStep.zeroGrad(flatOpt);
  }
}

TEST(FlatAdamW, StepsAsLibTorchsAdamWOnTheSameState) {
  torch::manual_seed(0);
  Net reference, flat;
  copyWeights(reference, flat);
  auto refOpt = optimizerOf(reference), flatOpt = optimizerOf(flat);
  FlatAdamW flatStep;
  stepBoth(reference, *refOpt, flat, *flatOpt, flatStep, 0, 6);
  // The same operators on the same values: equal to float rounding (an element's vector or
  // scalar path may differ between the flat buffer and a tensor of its own), within 1e-6 of
  // weights of order 0.1-1 after six steps of 1e-2.
  EXPECT_LT(largestDifference(reference, flat), 1e-6);
  for (const auto& p : flat.parameters())
    EXPECT_EQ(
        static_cast<AdamWParamState&>(*flatOpt->state().at(torch_compat::optimizerStateKey(p)))
            .step(),
        6);
}

TEST(FlatAdamW, GradientsAccumulateIntoTheFlatBuffersAndZeroInPlace) {
  torch::manual_seed(0);
  Net net;
  auto opt = optimizerOf(net);
  FlatAdamW flat;
  backward(net, 0);
  ASSERT_TRUE(flat.step(*opt));
  flat.zeroGrad(*opt);
  std::vector<void*> where;
  for (const auto& p : net.parameters()) {
    EXPECT_EQ(p.grad().abs().sum().item<double>(), 0.0);
    where.push_back(p.grad().data_ptr());
  }
  backward(net, 1);
  for (size_t i = 0; i < where.size(); ++i) {
    EXPECT_EQ(net.parameters()[i].grad().data_ptr(), where[i])
        << "autograd replaced gradient " << i;
    EXPECT_GT(net.parameters()[i].grad().abs().sum().item<double>(), 0.0);
  }
}

TEST(FlatAdamW, StateReplacedByACheckpointIsTakenIntoNewBuffers) {
  torch::manual_seed(0);
  Net reference, flat;
  copyWeights(reference, flat);
  auto refOpt = optimizerOf(reference), flatOpt = optimizerOf(flat);
  FlatAdamW flatStep;
  stepBoth(reference, *refOpt, flat, *flatOpt, flatStep, 0, 2);
  // As --resume restores: new tensors for the moments and the weights copied in.
  for (auto& p : flat.parameters()) {
    auto& s =
        static_cast<AdamWParamState&>(*flatOpt->state().at(torch_compat::optimizerStateKey(p)));
    s.exp_avg(s.exp_avg().clone());
    s.exp_avg_sq(s.exp_avg_sq().clone());
  }
  backward(reference, 2);
  backward(flat, 2);
  refOpt->step();
  ASSERT_TRUE(flatStep.step(*flatOpt));
  EXPECT_LT(largestDifference(reference, flat), 1e-6);
}

TEST(FlatAdamW, LeavesToLibTorchWhatItDoesNotCover) {
  torch::manual_seed(0);
  Net net;
  FlatAdamW flat;
  auto amsgrad = optimizerOf(net, /*amsgrad=*/true);
  backward(net, 0);
  EXPECT_FALSE(flat.step(*amsgrad));
  EXPECT_FALSE(flat.active());
  // A parameter without a gradient among others with one: LibTorch skips it, so flat does not
  // step that optimizer at all.
  Net partial;
  auto opt = optimizerOf(partial);
  torch::manual_seed(1);
  partial.a(torch::randn({4, 7})).sum().backward();
  const auto before = partial.b->weight.clone();
  EXPECT_FALSE(flat.step(*opt));
  EXPECT_TRUE(torch::equal(before, partial.b->weight));
}

}  // namespace
}  // namespace paircast
