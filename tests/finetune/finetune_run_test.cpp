// finetune end to end on a shipped scene: shards with flow and depth from generate_pairs, short
// fine-tunes that beat their trivial baselines on held-out pairs, exact resume, refusals,
// bad flags, and --predict.
#include "finetune/finetune.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <sstream>
#include <tuple>

#include "finetune/finetune_data.h"
#include "model/checkpoint.h"
#include "test_errors.h"
#include "test_paths.h"
#include "test_process.h"
#include "util/atomic_file.h"
#include "util/flo_io.h"
#include "util/image_io.h"

namespace paircast {
namespace {
namespace fs = std::filesystem;

std::string tool(const std::string& name) {
  return std::string(PAIRCAST_BINARY_DIR) + "/tools/" + name;
}

// Pairs of a shipped scene at 64 pixels with flow and depth, made once and reused: by default 80,
// the first shard's 64 to train on and the second's 16 held out.
std::string truthShards(const std::string& scene, int shard, int pairs = 80, int shardSize = 64) {
  const std::string out =
      fs::path(::testing::TempDir()) / "paircast" /
      ("truth-" + scene + "-" + std::to_string(pairs) + "-" + std::to_string(shardSize));
  if (!fs::exists(out + "/summary.json")) {
    const int status = testing::runProcess(
        {tool("generate_pairs"), "--scenes", testing::sourceDir() + "/scenes/" + scene, "--out",
         out, "--pairs-per-scene", std::to_string(pairs), "--shard-size", std::to_string(shardSize),
         "--resolution", "64", "--save-flow", "--save-depth", "--seed", "3", "--quiet", "--jobs",
         "2"});
    EXPECT_EQ(status, 0) << "generate_pairs on " << scene;
  }
  return out + "/pairs-00000" + std::to_string(shard) + ".tar";
}

FinetuneConfig smallRun(const std::string& task, const std::string& out) {
  FinetuneConfig c;
  c.data = {truthShards("apartment", 0)};
  c.evalData = {truthShards("apartment", 1)};
  c.model.croco = presetConfig("tiny");
  c.model.croco.img_size = 64;
  c.model.task = task;
  c.model.head = task == "pose" ? "pose" : "linear";
  c.train.out = out;
  c.train.batchSize = 8;
  c.train.epochs = 40;
  c.train.warmupEpochs = 1;
  c.train.blr = 1e-2;
  c.train.progress = false;
  c.train.saveEvery = 1000;
  c.train.amp = "none";  // the figures below were measured in float32
  return c;
}

double heldOut(const nlohmann::json& s, const char* who, const char* metric) {
  return s.at("heldout").at(who).at(metric).get<double>();
}

TEST(FinetuneData, ShardsHoldTheFlowThatTheDepthAndCamerasGive) {
  const TruthPairs data = TruthPairs::fromShards({truthShards("apartment", 1)});
  ASSERT_GT(data.size(), 4u);
  for (size_t i = 0; i < 4; ++i) {
    const TruthPair p = data.load(i);
    ASSERT_EQ(p.flow.width, 64);
    size_t known = 0;
    for (int v = 0; v < 64; v += 7)
      for (int u = 0; u < 64; u += 7) {
        const float z = p.depth1.data[v * 64 + u];
        const float* f = p.flow.pixel(u, v);
        if (!(z > 0)) {
          EXPECT_TRUE(std::isinf(f[0]) && std::isinf(f[1]));
          continue;
        }
        // The pixel's point, seen from camera 2, lands at the pixel plus the flow.
        const Eigen::Vector3d world =
            p.camera1.worldFromCamera() *
            (z * (p.camera1.K.inverse() * Eigen::Vector3d(u + 0.5, v + 0.5, 1)));
        const Eigen::Vector3d c2 = p.camera2.cameraFromWorld() * world;
        if (c2.z() <= 0) continue;
        const Eigen::Vector3d q = p.camera2.K * c2 / c2.z();
        EXPECT_NEAR(u + 0.5 + f[0], q.x(), 2e-3);
        EXPECT_NEAR(v + 0.5 + f[1], q.y(), 2e-3);
        ++known;
      }
    EXPECT_GT(known, 20u);
  }
}

TEST(FinetuneData, ShardsWithoutFlowAreRefusedNamingThem) {
  const std::string out = testing::scratchDir("noflow");
  ASSERT_EQ(testing::runProcess(
                {tool("generate_pairs"), "--scenes", testing::sourceDir() + "/scenes/room", "--out",
                 out, "--pairs-per-scene", "2", "--resolution", "32", "--save-depth", "--quiet"}),
            0);
  EXPECT_ERROR_CONTAINS(TruthPairs::fromShards({out + "/pairs-*.tar"}), "pairs-000000.tar",
                        "has no flow (generate_pairs --save-flow)");
  EXPECT_ERROR_CONTAINS(TruthPairs::fromShards({out + "/nothing-*.tar"}), "no shard matches");
}

// Flow and depth fine-tuned at this budget (40 epochs of 64 wide pairs of the apartment) learn
// their training pairs by margins far outside the spread of data draws and seeds, measured below
// (2026-12-07, float32, an AMD EPYC with AVX2; generate_pairs --seed 3 is the test's data, 4-6
// other draws). On 16 held-out pairs of the same scene they do not learn at this budget: over
// those draws held-out flow AEPE ranged from 0.955 to 1.065 of zero flow's, and depth's delta1
// from 0.10 below the constant's to 0.13 above, so no held-out figure is asserted here. The
// held-out learning of flow is the learning test's (tests/learning/flow_learns.sh: at most 0.7 of
// zero flow's, at the budget of docs/finetune.md's pilot), too long for the suite.
FinetuneConfig onTrainingPairs(FinetuneConfig c) {
  c.evalData = c.data;
  return c;
}

TEST(FinetuneRun, FlowLearnsItsTrainingPairs) {
  const nlohmann::json s =
      runFinetune(onTrainingPairs(smallRun("flow", testing::scratchDir("flow"))));
  std::printf("flow on its training pairs %s\n", s["heldout"].dump().c_str());
  EXPECT_EQ(heldOut(s, "model", "pairs"), 64);
  // AEPE over zero flow's: 0.694, 0.683, 0.693 with seeds 0, 1, 2; 0.705, 0.753, 0.694 with seed
  // 0 on the other draws (covisible pixels within 0.005 of these). px5 over zero flow's:
  // 0.680-0.762. The bound, 0.85, lies 0.1 above the worst, beyond the whole range (0.07).
  EXPECT_LT(heldOut(s, "model", "aepe"), 0.85 * heldOut(s, "baseline", "aepe"));
  EXPECT_LT(heldOut(s, "model", "aepe_covisible"), 0.85 * heldOut(s, "baseline", "aepe_covisible"));
  EXPECT_LT(heldOut(s, "model", "px5"), 0.88 * heldOut(s, "baseline", "px5"));
}

TEST(FinetuneRun, DepthLearnsItsTrainingPairs) {
  const nlohmann::json s =
      runFinetune(onTrainingPairs(smallRun("depth", testing::scratchDir("depth"))));
  std::printf("depth on its training pairs %s\n", s["heldout"].dump().c_str());
  // delta1 over the constant's: +0.222, +0.155, +0.163 with seeds 0, 1, 2; +0.269, +0.121,
  // +0.251 on the other draws (bound +0.06, half the smallest). RMSE over the constant's: 0.707,
  // 0.759, 0.758; 0.680, 0.776, 0.733 (bound 0.88, 0.1 above the worst). AbsRel: 0.45-0.56 of
  // the constant's.
  EXPECT_GT(heldOut(s, "model", "delta1"), heldOut(s, "baseline", "delta1") + 0.06);
  EXPECT_LT(heldOut(s, "model", "rmse"), 0.88 * heldOut(s, "baseline", "rmse"));
  EXPECT_LT(heldOut(s, "model", "absrel"), 0.75 * heldOut(s, "baseline", "absrel"));
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

// 1,000 pairs of the apartment to train on and 80 others held out; 20 epochs of 16 pairs from
// random weights at --blr 2e-3 (at 1e-2 the pose head learns nothing: docs/finetune.md).
TEST(FinetuneRun, PoseBeatsTheIdentityOnHeldOutPairs) {
  FinetuneConfig c = smallRun("pose", testing::scratchDir("pose"));
  c.data = {truthShards("apartment", 0, 1080, 1000)};
  c.evalData = {truthShards("apartment", 1, 1080, 1000)};
  c.train.batchSize = 16;
  c.train.epochs = 20;
  c.train.blr = 2e-3;
  const nlohmann::json s = runFinetune(c);
  std::printf("held-out pose %s\n", s["heldout"].dump().c_str());
  // The identity's errors are each pair's rotation angle and baseline, from its cameras.
  const TruthPairs eval = TruthPairs::fromShards(c.evalData);
  ASSERT_EQ(eval.size(), 80u);
  std::vector<double> angles, baselines;
  for (size_t i = 0; i < eval.size(); ++i) {
    const TruthPair p = eval.load(i);
    const Eigen::AngleAxisd turn(p.camera1.R_cam2world.transpose() * p.camera2.R_cam2world);
    angles.push_back(turn.angle() * 180.0 / M_PI);
    baselines.push_back((p.camera2.t_cam2world - p.camera1.t_cam2world).norm());
  }
  EXPECT_NEAR(heldOut(s, "baseline", "median_rot_err"), median(angles), 1e-3);
  EXPECT_NEAR(heldOut(s, "baseline", "median_trans_err"), median(baselines), 1e-5);
  // Measured with seeds 0, 1, 2: 23.75, 21.88 and 26.72 degrees against the identity's 28.29,
  // 0.819, 0.771 and 0.798 m against its 0.904. The seeds spread over 4.8 degrees and 0.048 m,
  // as much as the worst seed gains: pose learns weakly at this budget, and the bounds (0.97 and
  // 0.95 of the identity's) lie about a third of a spread beyond the worst seed. On a CPU whose
  // renders draw other pairs (AVX2, 2026-12-07), seed 0: 27.43 against 33.86 degrees (0.81),
  // 0.968 against 1.136 m (0.85).
  EXPECT_LT(heldOut(s, "model", "median_rot_err"), 0.97 * heldOut(s, "baseline", "median_rot_err"));
  EXPECT_LT(heldOut(s, "model", "median_trans_err"),
            0.95 * heldOut(s, "baseline", "median_trans_err"));
}

TEST(FinetuneRun, ResumesExactly) {
  FinetuneConfig whole = smallRun("flow", testing::scratchDir("whole"));
  whole.evalData.clear();
  whole.train.maxSteps = 6;
  runFinetune(whole);
  FinetuneConfig half = whole;
  half.train.out = testing::scratchDir("half");
  half.train.stopAfter = 3;  // as a kill would: the schedule still spans the 6 steps
  EXPECT_TRUE(runFinetune(half)["interrupted"].get<bool>());
  half.train.stopAfter = -1;
  half.train.resume = true;
  EXPECT_EQ(runFinetune(half)["steps"], 6);
  const Checkpoint a = loadCheckpoint(whole.train.out + "/checkpoint-last.pth");
  const Checkpoint b = loadCheckpoint(half.train.out + "/checkpoint-last.pth");
  ASSERT_EQ(a.model.size(), b.model.size());
  for (const auto& [k, t] : a.model) EXPECT_TRUE(torch::equal(t, b.model.at(k))) << k;
}

TEST(FinetuneRun, TheScheduleSpansTheStepsTakenAndCurvesGoIntoTheLog) {
  // 12 steps of a 40-epoch configuration (8 steps an epoch): the warm-up (1 epoch asked, at most
  // a tenth of the run: 1.2 steps) and the cosine fit into the 12 steps, so the peak lr is
  // reached and the last step runs near 0. Every 4 steps the held-out figures go into log.jsonl.
  FinetuneConfig c = smallRun("flow", testing::scratchDir("curves"));
  c.train.maxSteps = 12;
  c.evalEvery = 4;
  c.evalPairs = 4;
  const nlohmann::json s = runFinetune(c);
  EXPECT_DOUBLE_EQ(s["schedule"]["epochs"].get<double>(), 1.5);
  EXPECT_DOUBLE_EQ(s["schedule"]["warmup_epochs"].get<double>(), 0.15);
  const double peak = 1e-2 * 8 / 256;
  EXPECT_DOUBLE_EQ(s["schedule"]["peak_lr"].get<double>(), peak);
  std::vector<double> lr;
  std::vector<std::pair<int64_t, nlohmann::json>> curve;
  std::istringstream log(readFile(c.train.out + "/log.jsonl"));
  for (std::string line; std::getline(log, line);) {
    const auto j = nlohmann::json::parse(line);
    if (j.contains("loss")) lr.push_back(j["lr"].get<double>());
    if (j.contains("heldout")) curve.emplace_back(j["step"].get<int64_t>(), j["heldout"]);
  }
  ASSERT_EQ(lr.size(), 12u);
  EXPECT_GT(*std::max_element(lr.begin(), lr.end()), 0.9 * peak);
  // Step 11 of 12: (11/8 - 0.15) / 1.35 of the cosine, 0.021 of the peak.
  EXPECT_NEAR(lr.back(), peak * 0.5 * (1 + std::cos(M_PI * (11.0 / 8 - 0.15) / 1.35)), 1e-12);
  EXPECT_LT(lr.back(), 0.03 * peak);
  ASSERT_EQ(curve.size(), 3u);
  EXPECT_EQ(curve[0].first, 3);
  EXPECT_EQ(curve[2].first, 11);
  for (const auto& [step, figures] : curve) EXPECT_EQ(figures["pairs"], 4) << step;
  // The last point is measured on the final weights, as the summary's.
  EXPECT_DOUBLE_EQ(curve[2].second["aepe"].get<double>(), heldOut(s, "model", "aepe"));
  c.evalData.clear();
  EXPECT_ERROR_CONTAINS(runFinetune(c), "--eval-every needs --eval-data");
}

TEST(FinetuneRun, RefusesCheckpointsOfAnotherTaskOrModel) {
  FinetuneConfig flow = smallRun("flow", testing::scratchDir("ck"));
  flow.evalData.clear();
  flow.train.maxSteps = 1;
  runFinetune(flow);
  FinetuneConfig depth = smallRun("depth", flow.train.out);
  depth.evalData.clear();
  depth.train.resume = true;
  EXPECT_ERROR_CONTAINS(runFinetune(depth), "checkpoint-last.pth",
                        "checkpoint of task flow (head linear), not depth");
  FinetuneConfig bigger = flow;
  bigger.train.resume = true;
  bigger.model.croco = presetConfig("small");
  bigger.model.croco.img_size = 64;
  EXPECT_ERROR_CONTAINS(runFinetune(bigger), "checkpoint of another model");
  // --init takes pre-training checkpoints, of the same widths.
  FinetuneConfig init = smallRun("flow", testing::scratchDir("init"));
  init.init = flow.train.out + "/checkpoint-last.pth";
  EXPECT_ERROR_CONTAINS(runFinetune(init), "is a fine-tuning checkpoint (task flow)");
  const std::string pre = testing::scratchDir("pre") + "/small.pth";
  CroCoConfig small = presetConfig("small");
  small.img_size = 64;
  CroCoNet net(small);
  saveCheckpoint(pre, net, 0);
  init.init = pre;
  EXPECT_ERROR_CONTAINS(runFinetune(init), "small.pth",
                        "checkpoint of another model: enc_embed_dim 384, not 192");
  // A tiny model with 8-pixel patches (pretrain --patch-size 8) needs finetune --patch-size 8.
  CroCoConfig fine = presetConfig("tiny");
  fine.img_size = 64;
  fine.patch_size = 8;
  const std::string pre8 = testing::scratchDir("pre8") + "/tiny8.pth";
  CroCoNet net8(fine);
  saveCheckpoint(pre8, net8, 0);
  init.init = pre8;
  EXPECT_ERROR_CONTAINS(runFinetune(init), "tiny8.pth", "patch_size 8, not 16",
                        "--patch-size it was trained with");
  init.model.croco.patch_size = 8;
  init.train.maxSteps = 1;
  init.evalData.clear();
  EXPECT_EQ(runFinetune(init)["initialised"], "encoder+decoder");
}

TEST(FinetuneRun, MaeInitKeepsTheSeedsRandomDecoderAndCrossViewCopiesIt) {
  CroCoConfig tiny = presetConfig("tiny");
  tiny.img_size = 64;
  torch::manual_seed(11);
  CroCoNet pre(tiny);
  const std::string dir = testing::scratchDir("mae");
  saveCheckpoint(dir + "/mae.pth", pre, 0, {{"task", "mae"}});
  saveCheckpoint(dir + "/croco.pth", pre, 0, {{"task", "croco"}});
  DownstreamConfig c;
  c.croco = tiny;
  c.task = "flow";
  c.head = "linear";
  torch::manual_seed(5);
  DownstreamNet fresh(c);
  torch::manual_seed(5);
  DownstreamNet mae(c);
  EXPECT_EQ(mae->initFromPretrained(loadCheckpoint(dir + "/mae.pth"), "mae.pth"), "encoder");
  torch::manual_seed(5);
  DownstreamNet cross(c);
  EXPECT_EQ(cross->initFromPretrained(loadCheckpoint(dir + "/croco.pth"), "croco.pth"),
            "encoder+decoder");
  const auto f = fresh->state(), m = mae->state(), x = cross->state(), p = stateDict(pre);
  EXPECT_TRUE(
      torch::equal(m.at("dec_blocks.1.mlp.fc2.weight"), f.at("dec_blocks.1.mlp.fc2.weight")));
  EXPECT_TRUE(torch::equal(m.at("decoder_embed.weight"), f.at("decoder_embed.weight")));
  EXPECT_TRUE(
      torch::equal(m.at("enc_blocks.3.attn.qkv.weight"), p.at("enc_blocks.3.attn.qkv.weight")));
  EXPECT_TRUE(
      torch::equal(x.at("dec_blocks.1.mlp.fc2.weight"), p.at("dec_blocks.1.mlp.fc2.weight")));
  EXPECT_FALSE(
      torch::equal(f.at("dec_blocks.1.mlp.fc2.weight"), p.at("dec_blocks.1.mlp.fc2.weight")));
}

int runTool(const std::vector<std::string>& args, std::string* err) {
  const std::string log = testing::scratchDir("log") + "/stderr.txt";
  std::string cmd = tool("finetune");
  for (const auto& a : args) cmd += " '" + a + "'";
  const int status = std::system((cmd + " 2> " + log).c_str());
  *err = readFile(log);
  return WEXITSTATUS(status);
}

TEST(FinetuneCli, BadFlagsExit2WithOneLine) {
  const std::string data = truthShards("apartment", 1), out = testing::scratchDir("cli");
  std::string err;
  EXPECT_EQ(runTool({"--data", data, "--out", out, "--task", "segmentation"}, &err), 2) << err;
  EXPECT_EQ(runTool({"--data", data, "--out", out, "--img-size", "112"}, &err), 2);
  EXPECT_NE(err.find("finetune: error: --img-size: the DPT head needs an image side divisible by "
                     "32"),
            std::string::npos)
      << err;
  EXPECT_EQ(runTool({"--data", data, "--out", out, "--task", "pose", "--head", "dpt"}, &err), 2);
  EXPECT_NE(err.find("--task pose takes --head pose"), std::string::npos) << err;
  EXPECT_EQ(runTool({"--out", out}, &err), 2);
  EXPECT_NE(err.find("--data: give shards written with generate_pairs --save-flow"),
            std::string::npos)
      << err;
  EXPECT_EQ(runTool({"--data", data, "--out", out, "--img-size", "128"}, &err), 1);
  EXPECT_NE(err.find("pairs-000001.tar: pairs of 64 pixels are smaller than the training size "
                     "128"),
            std::string::npos)
      << err;
  EXPECT_EQ(runTool({"--predict", "--out", out + "/x.flo"}, &err), 2);
  EXPECT_NE(err.find("--checkpoint is required"), std::string::npos) << err;
  EXPECT_EQ(runTool({"--batch-size", "0", "--out", out}, &err), 2);
}

TEST(FinetuneCli, EachTaskHasTheRateTheDocsRecommend) {
  // Without --blr, flow and depth train at blr 1e-2 and pose at 2e-3 (docs/finetune.md); --blr
  // still sets it. The summary gives the peak lr: blr x batch / 256.
  const std::string data = truthShards("apartment", 1);
  for (const auto& [task, head, flags, blr] :
       {std::tuple{"flow", "linear", std::vector<std::string>{}, 1e-2},
        std::tuple{"pose", "pose", std::vector<std::string>{}, 2e-3},
        std::tuple{"pose", "pose", std::vector<std::string>{"--blr", "5e-4"}, 5e-4}}) {
    const std::string out = testing::scratchDir(std::string("rate-") + task + head);
    std::vector<std::string> args = {"--data",      data, "--out",      out,  "--task",       task,
                                     "--head",      head, "--img-size", "64", "--batch-size", "4",
                                     "--max-steps", "1",  "--quiet"};
    args.insert(args.end(), flags.begin(), flags.end());
    std::string err;
    ASSERT_EQ(runTool(args, &err), 0) << err;
    const auto s = nlohmann::json::parse(readFile(out + "/summary.json"))["schedule"];
    EXPECT_DOUBLE_EQ(s["blr"].get<double>(), blr) << task;
    EXPECT_DOUBLE_EQ(s["peak_lr"].get<double>(), blr * 4 / 256) << task;
  }
}

TEST(FinetuneCli, PredictWritesFloAndAPicture) {
  const std::string dir = testing::scratchDir("predict");
  std::string err;
  ASSERT_EQ(runTool({"--data", truthShards("apartment", 0), "--out", dir + "/run", "--img-size",
                     "64", "--head", "linear", "--max-steps", "1", "--quiet"},
                    &err),
            0)
      << err;
  // Two views of the studio, larger than the model's tiles: written as images.
  const TruthPair p = TruthPairs::fromShards({truthShards("apartment", 1)}).load(0);
  writeImage(dir + "/a.png", p.rgb1);
  writeImage(dir + "/b.png", p.rgb2);
  ASSERT_EQ(runTool({"--predict", "--checkpoint", dir + "/run/checkpoint-last.pth", "--image1",
                     dir + "/a.png", "--image2", dir + "/b.png", "--out", dir + "/flow.flo"},
                    &err),
            0)
      << err;
  const ImageF flow = readFlo(dir + "/flow.flo");
  EXPECT_EQ(flow.width, 64);
  EXPECT_EQ(flow.channels, 2);
  EXPECT_TRUE(fs::exists(dir + "/flow.png"));
  EXPECT_EQ(runTool({"--predict", "--checkpoint", dir + "/run/checkpoint-last.pth", "--image1",
                     dir + "/a.png", "--image2", dir + "/missing.png", "--out", dir + "/x.flo"},
                    &err),
            1);
  EXPECT_NE(err.find("missing.png"), std::string::npos) << err;
}

}  // namespace
}  // namespace paircast
