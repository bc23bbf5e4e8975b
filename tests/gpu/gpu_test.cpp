// The GPU code paths: SDPA attention, the fused AdamW step, the NCCL process group and the
// whole train step on CUDA. The tests make their own shard (synthetic JPEG pairs), so they run
// in the trainer-only build (PAIRCAST_WITH_RENDER=OFF) too, which is what GPU machines build.
// CUDA tests skip without a device; each has a CPU counterpart that runs everywhere.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>

#include "model/croco_net.h"
#include "model/torch_compat.h"
#include "test_paths.h"
#include "test_tar.h"
#include "trainer/distributed.h"
#include "trainer/fused_adamw.h"
#include "trainer/trainer.h"
#include "util/image_io.h"
#include "util/random.h"

namespace paircast {
namespace {

namespace fs = std::filesystem;

// `pairs` pairs of smooth random 64 x 64 images (shifted views of one pattern), as JPEGs in a
// tar shard laid out as generate_pairs writes them: <key>.1.jpg, <key>.2.jpg, <key>.json.
std::string writeShard(const std::string& dir, int pairs) {
  Rng rng(7);
  std::vector<testing::TarMember> members;
  for (int k = 0; k < pairs; ++k) {
    const double fx = 0.05 + 0.2 * rng.uniform(), fy = 0.05 + 0.2 * rng.uniform();
    for (int view = 1; view <= 2; ++view) {
      Image8 img(64, 64, 3);
      for (int y = 0; y < 64; ++y)
        for (int x = 0; x < 64; ++x)
          for (int c = 0; c < 3; ++c)
            img.pixel(x, y)[c] = static_cast<uint8_t>(
                127 + 120 * std::sin(fx * (x + 4 * view) + fy * y + 2.0 * c + k));
      char name[32];
      std::snprintf(name, sizeof name, "s-%08d.%d.jpg", k, view);
      const auto jpeg = encodeImage(img, "jpg", 90);
      members.emplace_back(name, std::string(jpeg.begin(), jpeg.end()));
    }
    char key[32];
    std::snprintf(key, sizeof key, "s-%08d", k);
    members.push_back(testing::recordMember(key, 2, 64, 64));
  }
  const std::string tar = testing::ustar(members), path = dir + "/pairs-000000.tar";
  std::ofstream(path, std::ios::binary).write(tar.data(), static_cast<std::streamsize>(tar.size()));
  return path;
}

TrainConfig tinyRun(const std::string& dir) {
  TrainConfig c;
  c.shards = {writeShard(dir, 16)};
  c.model = presetConfig("tiny");
  c.model.img_size = 32;
  c.model.patch_size = 8;
  c.batchSize = 4;
  c.epochs = 4;
  c.warmupEpochs = 1;
  c.blr = 1.5e-3;
  c.out = dir + "/run";
  c.workers = 1;
  c.saveEvery = 2;
  c.progress = false;
  return c;
}

// Sets environment variables for the scope of a test and restores them after.
class ScopedEnv {
 public:
  void set(const char* name, const std::string& value) {
    const char* old = std::getenv(name);
    saved_.emplace_back(name, old ? std::optional<std::string>(old) : std::nullopt);
    ::setenv(name, value.c_str(), 1);
  }
  ~ScopedEnv() {
    for (auto it = saved_.rbegin(); it != saved_.rend(); ++it) {
      if (it->second)
        ::setenv(it->first.c_str(), it->second->c_str(), 1);
      else
        ::unsetenv(it->first.c_str());
    }
  }

 private:
  std::vector<std::pair<std::string, std::optional<std::string>>> saved_;
};

std::string freePort() {
  return std::to_string(20000 + ::getpid() % 20000);
}

TEST(TrainerOnly, TrainsAndResumesFromItsOwnShard) {
  TrainConfig c = tinyRun(testing::scratchDir("cpu"));
  c.maxSteps = 2;
  const nlohmann::json first = runPretrain(c);
  EXPECT_EQ(first["steps"], 2);
  EXPECT_TRUE(std::isfinite(first["loss"].get<double>()));
  EXPECT_FALSE(first["fused_adamw"].get<bool>());  // CPU: LibTorch's own step
  c.resume = true;
  c.maxSteps = 4;
  EXPECT_EQ(runPretrain(c)["steps"], 4);
}

TEST(FusedAdamW, DeclinesOnTheCpuAndChangesNothing) {
  auto p = torch::randn({4, 3}, torch::requires_grad());
  p.mutable_grad() = torch::randn({4, 3});
  torch::optim::AdamW opt({p}, torch::optim::AdamWOptions(1e-2));
  const auto before = p.detach().clone();
  EXPECT_FALSE(fusedAdamWStep(opt));
  EXPECT_TRUE(torch::equal(p.detach(), before));
  EXPECT_TRUE(opt.state().empty());
}

TEST(ProcessGroup, GlooGroupOfOneRunsTheCollectives) {
  if (!Distributed::hasGloo()) GTEST_SKIP() << "built without c10d Gloo";
  ScopedEnv env;
  env.set("PAIRCAST_PROCESS_GROUP", "1");
  env.set("WORLD_SIZE", "1");
  env.set("RANK", "0");
  env.set("MASTER_ADDR", "127.0.0.1");
  env.set("MASTER_PORT", freePort());
  auto dist = Distributed::fromEnvironment("cpu");
  ASSERT_TRUE(dist);
  auto t = torch::arange(6, torch::kFloat32).reshape({2, 3});
  const auto expected = t.clone();
  dist->allReduceMean({t});
  dist->broadcast({t});
  dist->barrier();
  EXPECT_TRUE(torch::allclose(t, expected));
}

TEST(Cuda, ForwardMatchesTheCpu) {
  if (!torch::cuda::is_available()) GTEST_SKIP() << "no CUDA device";
  torch::manual_seed(0);
  CroCoConfig cfg = presetConfig("tiny");
  CroCoNet cpu(cfg);
  CroCoNet gpu(cfg);
  {
    torch::NoGradGuard ng;
    auto src = cpu->named_parameters(), dst = gpu->named_parameters();
    for (const auto& kv : src) dst[kv.key()].copy_(kv.value());
  }
  gpu->to(torch::kCUDA);
  auto img1 = torch::randn({2, 3, 224, 224}), img2 = torch::randn({2, 3, 224, 224});
  auto mask = cpu->randomMask(2, torch::kCPU);
  torch::NoGradGuard ng;
  // Float32 without TF32: SDPA's CUDA kernels against the CPU path, within float rounding.
  const bool tf32 = at::globalContext().allowTF32CuBLAS();
  at::globalContext().setAllowTF32CuBLAS(false);
  const auto a = cpu->forward(img1, img2, mask).prediction;
  const auto b = gpu->forward(img1.cuda(), img2.cuda(), mask.cuda()).prediction.to(torch::kCPU);
  at::globalContext().setAllowTF32CuBLAS(tf32);
  EXPECT_LT((a - b).abs().max().item<double>(), 1e-3);
}

TEST(Cuda, FusedAdamWMatchesLibTorchsStep) {
  if (!torch::cuda::is_available()) GTEST_SKIP() << "no CUDA device";
  if (!fusedAdamWCompiled()) GTEST_SKIP() << "LibTorch < 2.1: no fused AdamW";
  torch::manual_seed(1);
  const auto init = torch::randn({64, 33}, torch::kCUDA);
  auto p1 = init.clone().requires_grad_(), p2 = init.clone().requires_grad_();
  auto b1 = torch::zeros({33}, torch::kCUDA).requires_grad_(),
       b2 = torch::zeros({33}, torch::kCUDA).requires_grad_();
  auto options = [] {
    return torch::optim::AdamWOptions(1e-2).betas({0.9, 0.95}).weight_decay(0.05);
  };
  torch::optim::AdamW fused({p1, b1}, options()), plain({p2, b2}, options());
  for (int step = 0; step < 5; ++step) {
    const auto g = torch::randn({64, 33}, torch::kCUDA), gb = torch::randn({33}, torch::kCUDA);
    p1.mutable_grad() = g.clone();
    p2.mutable_grad() = g.clone();
    b1.mutable_grad() = gb.clone();
    b2.mutable_grad() = gb.clone();
    ASSERT_TRUE(fusedAdamWStep(fused));
    plain.step();
  }
  EXPECT_LT((p1 - p2).abs().max().item<double>(), 1e-6);
  EXPECT_LT((b1 - b2).abs().max().item<double>(), 1e-6);
  auto& s = static_cast<torch::optim::AdamWParamState&>(
      *fused.state().at(torch_compat::optimizerStateKey(p1)));
  EXPECT_EQ(s.step(), 5);  // the integer step that checkpoints save
}

TEST(Cuda, TrainStepResumeAndNcclGroupOfOne) {
  if (!torch::cuda::is_available()) GTEST_SKIP() << "no CUDA device";
  TrainConfig c = tinyRun(testing::scratchDir("cuda"));
  c.device = "cuda";
  c.maxSteps = 4;
  const std::string out = c.out;
  for (const char* amp : {"bf16", "fp16", "none"}) {
    c.amp = amp;
    c.out = out + "_" + amp;
    const nlohmann::json s = runPretrain(c);
    EXPECT_EQ(s["steps"], 4) << amp;
    EXPECT_TRUE(std::isfinite(s["loss"].get<double>())) << amp;
    EXPECT_EQ(s["fused_adamw"].get<bool>(), fusedAdamWCompiled()) << amp;
  }
  // Resume on the device: the optimizer state comes back from the CPU checkpoint onto it.
  c.resume = true;
  c.maxSteps = 6;
  EXPECT_EQ(runPretrain(c)["steps"], 6);
  // The multi-GPU code path on one GPU: an NCCL group of one.
  if (!Distributed::hasNccl()) GTEST_SKIP() << "built without NCCL (set PAIRCAST_NCCL_INCLUDE_DIR)";
  ScopedEnv env;
  env.set("PAIRCAST_PROCESS_GROUP", "1");
  env.set("WORLD_SIZE", "1");
  env.set("RANK", "0");
  env.set("LOCAL_RANK", "0");
  env.set("MASTER_ADDR", "127.0.0.1");
  env.set("MASTER_PORT", freePort());
  c.resume = false;
  c.maxSteps = 3;
  c.amp = "bf16";
  c.out = out + "_nccl";
  const nlohmann::json s = runPretrain(c);
  EXPECT_EQ(s["steps"], 3);
  EXPECT_EQ(s["world_size"], 1);
}

}  // namespace
}  // namespace paircast
