#include "model/precision.h"

#include <gtest/gtest.h>

#include "model/autocast.h"
#include "model/croco_net.h"
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
TEST(AutocastGuard, CroCoNetTrainsUnderCpuBf16) {
  torch::manual_seed(0);
  CroCoConfig c = presetConfig("tiny");
  c.img_size = 32;
  c.patch_size = 8;
  CroCoNet net(c);
  const auto img1 = torch::randn({2, 3, 32, 32}), img2 = torch::randn({2, 3, 32, 32});
  torch::Tensor loss;
  {
    const AutocastGuard autocast(at::kCPU, true, at::kBFloat16);
    const CroCoOutput out = net->forward(img1, img2);
    EXPECT_EQ(out.prediction.scalar_type(), at::kBFloat16);
    loss = maskedMse(out.prediction.to(torch::kFloat32), out.mask, out.target);
  }
  loss.backward();
  EXPECT_TRUE(std::isfinite(loss.item<double>()));
  for (const auto& p : net->parameters()) {
    EXPECT_EQ(p.scalar_type(), at::kFloat);
    if (p.grad().defined()) EXPECT_EQ(p.grad().scalar_type(), at::kFloat);
  }
}

}  // namespace
}  // namespace paircast
