#include "trainer/op_profile.h"

#include <ATen/record_function.h>
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <map>
#include <thread>

namespace paircast {
namespace {

std::map<std::string, nlohmann::json> byName(const nlohmann::json& rows, const char* key) {
  std::map<std::string, nlohmann::json> out;
  for (const auto& r : rows) out[r[key].get<std::string>()] = r;
  return out;
}

TEST(OperatorKind, NamesTheKindsTheProfileReports) {
  EXPECT_EQ(operatorKind("aten::addmm"), "matmul");
  EXPECT_EQ(operatorKind("aten::bmm"), "matmul");
  EXPECT_EQ(operatorKind("aten::linear"), "matmul");
  EXPECT_EQ(operatorKind("aten::_softmax"), "softmax and attention");
  EXPECT_EQ(operatorKind("aten::native_layer_norm_backward"), "layer norm");
  EXPECT_EQ(operatorKind("aten::gelu_backward"), "gelu");
  EXPECT_EQ(operatorKind("aten::_to_copy"), "casts and copies");
  EXPECT_EQ(operatorKind("aten::copy_"), "casts and copies");
  EXPECT_EQ(operatorKind("aten::t"), "views");
  EXPECT_EQ(operatorKind("aten::tanh"), "elementwise and other");
  EXPECT_EQ(operatorKind("aten::mkldnn_convolution"), "convolution");
  EXPECT_EQ(operatorKind("AddmmBackward0"), "autograd nodes");
}

TEST(OpProfile, CountsEachOperatorsCallsAndStagesOnTheProfiledThreadOnly) {
  const auto a = torch::randn({64, 64}), b = torch::randn({64, 64});
  OpProfile profile;
  profile.resume();
  const int steps = 3;
  for (int s = 0; s < steps; ++s) {
    {
      RECORD_USER_SCOPE(kStageForward);
      auto c = torch::mm(a, b);  // 2 mm a step in this stage
      c = torch::mm(c, b).softmax(1);
    }
    {
      RECORD_USER_SCOPE(kStageOptimizer);
      auto d = a.mul(2.0);  // an elementwise op: counted as the optimizer's
    }
  }
  std::thread([&] { torch::mm(a, b); }).join();  // another thread: not counted
  profile.pause();
  torch::mm(a, b);  // paused: not counted
  const nlohmann::json r = profile.report(steps);
  const auto ops = byName(r["ops"], "op");
  ASSERT_TRUE(ops.count("aten::mm"));
  EXPECT_EQ(ops.at("aten::mm")["calls_per_step"].get<double>(), 2.0);
  EXPECT_EQ(ops.at("aten::mm")["kind"], "matmul");
  const auto stages = byName(r["stages"], "stage");
  ASSERT_TRUE(stages.count("forward") && stages.count("optimizer"));
  EXPECT_EQ(stages.count("other"), 0u);
  const auto kinds = byName(r["kinds"], "kind");
  ASSERT_TRUE(kinds.count("optimizer"));
  EXPECT_EQ(kinds.at("optimizer")["calls_per_step"].get<double>(),
            stages.at("optimizer")["calls_per_step"].get<double>());
  // Self times: the shares add up to one, and no op counts its children's time twice.
  double share = 0, ms = 0;
  for (const auto& k : r["kinds"])
    share += k["share"].get<double>(), ms += k["ms_per_step"].get<double>();
  EXPECT_NEAR(share, 1.0, 1e-9);
  EXPECT_NEAR(ms, r["ms_per_step"].get<double>(), 1e-9);
}

TEST(OpProfile, OneAtATime) {
  OpProfile first;
  EXPECT_THROW(OpProfile second, std::exception);
}

}  // namespace
}  // namespace paircast
