#include "model/precision.h"

#include <gtest/gtest.h>

#include "model/autocast.h"
#include "model/croco_net.h"
#include "model/downstream.h"
#include "test_errors.h"

namespace paircast {
namespace {

const CpuFlags kBf16Cpu = {"avx2",     "fma",      "avx512f",    "avx512bw",
                           "avx512vl", "avx512dq", "avx512_bf16"};
const CpuFlags kAmxCpu = {"avx512f", "avx512_bf16", "amx_bf16", "amx_tile"};
const CpuFlags kPlainCpu = {"avx2", "fma", "avx512f", "avx512bw", "avx512vl", "avx512dq"};

TEST(Precision, AutoFollowsTheCpusBf16Units) {
  const Precision bf16 = resolvePrecision("auto", at::kCPU, kBf16Cpu);
  EXPECT_EQ(bf16.ran, "bf16");
  EXPECT_TRUE(bf16.autocast());
  EXPECT_EQ(bf16.dtype(), at::kBFloat16);
  EXPECT_EQ(bf16.why, "auto: the CPU has avx512_bf16");
  EXPECT_EQ(resolvePrecision("auto", at::kCPU, kAmxCpu).why, "auto: the CPU has amx_bf16");
  const Precision plain = resolvePrecision("auto", at::kCPU, kPlainCpu);
  EXPECT_EQ(plain.ran, "float32");
  EXPECT_FALSE(plain.autocast());
  EXPECT_NE(plain.why.find("no bf16 units"), std::string::npos);
  EXPECT_EQ(resolvePrecision("auto", at::kCUDA, kPlainCpu).ran, "bf16");
  EXPECT_EQ(resolvePrecision("auto", at::kCPU, CpuFlags{}).ran, "float32");  // no flags: not x86
}

TEST(Precision, ForcedValuesAndTheirLimits) {
  for (const CpuFlags& f : {kBf16Cpu, kPlainCpu}) {
    EXPECT_EQ(resolvePrecision("none", at::kCPU, f).ran, "float32");
    EXPECT_EQ(resolvePrecision("bf16", at::kCPU, f).ran, "bf16");
  }
  EXPECT_FALSE(resolvePrecision("bf16", at::kCPU, kBf16Cpu).slow);
  EXPECT_TRUE(resolvePrecision("bf16", at::kCPU, kPlainCpu).slow);  // runs, and says so
  const Precision fp16 = resolvePrecision("fp16", at::kCUDA, kPlainCpu);
  EXPECT_EQ(fp16.ran, "fp16");
  EXPECT_EQ(fp16.dtype(), at::kHalf);
  EXPECT_EQ(resolvePrecision("none", at::kCUDA, kPlainCpu).ran, "float32");
  EXPECT_ERROR_CONTAINS(resolvePrecision("fp16", at::kCPU, kBf16Cpu),
                        "fp16 autocast runs on CUDA only");
  EXPECT_ERROR_CONTAINS(resolvePrecision("fp8", at::kCPU, kBf16Cpu),
                        "mixed precision must be auto, bf16, fp16 or none, not 'fp8'");
  const nlohmann::json j = resolvePrecision("auto", at::kCPU, kBf16Cpu).toJson();
  EXPECT_EQ(j["requested"], "auto");
  EXPECT_EQ(j["ran"], "bf16");
}

// As Python's torch.autocast: a guard restores what was before it, nested or not.
TEST(AutocastGuard, NestsAndRestoresTheCpuState) {
  ASSERT_FALSE(torch_compat::isAutocast(at::kCPU));
  const auto w = torch::randn({8, 8}), x = torch::randn({4, 8});
  {
    const AutocastGuard outer(at::kCPU, true, at::kBFloat16);
    EXPECT_TRUE(torch_compat::isAutocast(at::kCPU));
    EXPECT_EQ(torch_compat::autocastDtype(at::kCPU), at::kBFloat16);
    EXPECT_EQ(torch::matmul(x, w).scalar_type(), at::kBFloat16);
    {
      const AutocastGuard inner(at::kCPU, false);
      EXPECT_FALSE(torch_compat::isAutocast(at::kCPU));
      EXPECT_EQ(torch::matmul(x, w).scalar_type(), at::kFloat);
    }
    EXPECT_TRUE(torch_compat::isAutocast(at::kCPU));
    EXPECT_EQ(torch::matmul(x, w).scalar_type(), at::kBFloat16);
  }
  EXPECT_FALSE(torch_compat::isAutocast(at::kCPU));
  EXPECT_EQ(torch::matmul(x, w).scalar_type(), at::kFloat);
}

// The model runs under CPU autocast, forward and backward, and its float32 weights get float32
// gradients.
// Both position embeddings: with RoPE there is no float32 table to promote the bf16 patch
// embedding, and LibTorch 1.13's CPU LayerNorm refused it ("expected scalar type BFloat16 but
// found Float") until the residual stream was kept in float32 (residualStream).
class CpuBf16 : public ::testing::TestWithParam<std::string> {};

TEST_P(CpuBf16, CroCoNetTrainsAndAgreesWithFloat32) {
  CroCoConfig c = presetConfig("tiny");
  c.img_size = 32;
  c.patch_size = 8;
  c.pos_embed = GetParam();
  torch::manual_seed(0);
  CroCoNet net(c);
  torch::manual_seed(1);
  const auto img1 = torch::randn({2, 3, 32, 32}), img2 = torch::randn({2, 3, 32, 32});
  const auto mask = net->randomMask(2, torch::kCPU);
  const CroCoOutput exact = net->forward(img1, img2, mask);
  torch::Tensor loss;
  {
    const AutocastGuard autocast(at::kCPU, true, at::kBFloat16);
    const CroCoOutput out = net->forward(img1, img2, mask);
    EXPECT_EQ(out.prediction.scalar_type(), at::kBFloat16);
    // bf16 keeps 8 bits of mantissa (relative rounding 2^-9 a value); through 8 blocks of
    // width 192 the prediction's errors stay within a few percent of its spread.
    const double spread = exact.prediction.std().item<double>();
    const double error =
        (out.prediction.to(torch::kFloat32) - exact.prediction).abs().mean().item<double>();
    EXPECT_LT(error, 0.05 * spread) << c.pos_embed;
    loss = maskedMse(out.prediction.to(torch::kFloat32), out.mask, out.target);
  }
  loss.backward();
  EXPECT_TRUE(std::isfinite(loss.item<double>()));
  for (const auto& p : net->parameters()) {
    EXPECT_EQ(p.scalar_type(), at::kFloat);
    if (p.grad().defined()) {
      EXPECT_EQ(p.grad().scalar_type(), at::kFloat);
    }
  }
}

TEST_P(CpuBf16, FlowModelTrainsAndAgreesWithFloat32) {
  DownstreamConfig c;
  c.croco = presetConfig("tiny");
  c.croco.img_size = 32;
  c.croco.patch_size = 8;
  c.croco.pos_embed = GetParam();
  c.head = "linear";
  torch::manual_seed(0);
  DownstreamNet net(c);
  torch::manual_seed(1);
  const auto img1 = torch::randn({2, 3, 32, 32}), img2 = torch::randn({2, 3, 32, 32});
  const auto exact = net->forward(img1, img2);
  torch::Tensor loss;
  {
    const AutocastGuard autocast(at::kCPU, true, at::kBFloat16);
    const auto out = net->forward(img1, img2).to(torch::kFloat32);
    const double spread = exact.std().item<double>();
    EXPECT_LT((out - exact).abs().mean().item<double>(), 0.05 * spread) << c.croco.pos_embed;
    loss = out.pow(2).mean();
  }
  loss.backward();
  EXPECT_TRUE(std::isfinite(loss.item<double>()));
}

INSTANTIATE_TEST_SUITE_P(PositionEmbeddings, CpuBf16, ::testing::Values("cosine", "RoPE100"));

}  // namespace
}  // namespace paircast
