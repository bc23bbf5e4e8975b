#include "model/croco_net.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>

#include "model/checkpoint.h"
#include "test_errors.h"
#include "test_paths.h"
#include "util/atomic_file.h"
#include "util/error.h"

namespace paircast {
namespace {

CroCoConfig tinyConfig(int img = 64) {
  CroCoConfig c = presetConfig("tiny");
  c.img_size = img;
  return c;
}

TEST(CroCoNet, ShapesOfTheForwardPass) {
  torch::manual_seed(0);
  CroCoNet net(tinyConfig());
  auto img1 = torch::randn({2, 3, 64, 64}), img2 = torch::randn({2, 3, 64, 64});
  const CroCoOutput out = net->forward(img1, img2);
  EXPECT_EQ(out.prediction.sizes(), (std::vector<int64_t>{2, 16, 768}));
  EXPECT_EQ(out.mask.sizes(), (std::vector<int64_t>{2, 16}));
  EXPECT_EQ(out.target.sizes(), (std::vector<int64_t>{2, 16, 768}));
  EXPECT_ERROR_CONTAINS(net->forward(torch::randn({2, 3, 32, 32}), img2),
                        "CroCo input must be [B, 3, 64, 64]");
}

// Auto-completion (no img2): the decoder gets no reference, so what stands in img2's place
// cannot matter, and skipping the cross-attention is the same as a cross-attention whose output
// projection is zero (one that adds nothing to its residual stream).
TEST(CroCoNet, WithoutAReferenceTheDecoderSeesNoSecondImage) {
  for (const char* decoder : {"cross", "cat"})
    for (const char* pos : {"cosine", "RoPE100"}) {
      SCOPED_TRACE(std::string(decoder) + " decoder, " + pos);
      torch::manual_seed(0);
      CroCoConfig c = tinyConfig();
      c.decoder = decoder;
      c.pos_embed = pos;
      CroCoNet net(c);
      net->eval();
      torch::NoGradGuard ng;
      const auto img1 = torch::randn({2, 3, 64, 64});
      const auto mask = net->randomMask(2, torch::kCPU);
      const auto alone = net->forward(img1, torch::Tensor(), mask).prediction;
      const auto withA = net->forward(img1, torch::randn({2, 3, 64, 64}), mask).prediction;
      const auto withB = net->forward(img1, torch::randn({2, 3, 64, 64}), mask).prediction;
      EXPECT_FALSE(torch::allclose(withA, withB)) << decoder << ": the reference must matter";
      EXPECT_FALSE(torch::allclose(alone, withA)) << decoder;
      EXPECT_EQ(alone.sizes(), withA.sizes());
      if (std::string(decoder) != "cross") continue;
      for (auto& blk : *net->dec_blocks) {
        auto& proj = blk->as<DecoderBlock>()->cross_attn->proj;
        proj->weight.zero_();
        proj->bias.zero_();
      }
      EXPECT_TRUE(torch::allclose(net->forward(img1, torch::randn({2, 3, 64, 64}), mask).prediction,
                                  alone, 1e-5, 1e-6));
    }
}

TEST(CroCoNet, ParameterCountsOfThePresets) {
  // The official CroCoNet (CrossBlock, base) has 120,076,288 parameters.
  struct Case {
    std::string preset, decoder;
    int64_t params;
  };
  for (const Case& c : {Case{"base", "cross", 120076288}}) {
    CroCoConfig cfg = presetConfig(c.preset);
    cfg.decoder = c.decoder;
    CroCoNet net(cfg);
    EXPECT_EQ(countParameters(*net), c.params) << c.preset;
  }
  CroCoConfig cat = presetConfig("base");
  cat.decoder = "cat";
  CroCoNet catNet(cat);
  EXPECT_NEAR(countParameters(*catNet) / 1e6, 111.0, 1.0);  // the paper's 111M
  CroCoNet small(presetConfig("small")), tiny(presetConfig("tiny"));
  EXPECT_LT(countParameters(*tiny), countParameters(*small));
  EXPECT_ERROR_CONTAINS(presetConfig("huge"), "unknown preset 'huge'");
}

TEST(CroCoNet, StateDictHasTheOfficialNames) {
  CroCoNet net(tinyConfig());
  const auto sd = stateDict(net);
  for (const char* k :
       {"patch_embed.proj.weight", "enc_blocks.0.attn.qkv.weight", "enc_blocks.0.mlp.fc1.bias",
        "enc_norm.weight", "decoder_embed.weight", "dec_blocks.0.cross_attn.projq.weight",
        "dec_blocks.0.norm_y.weight", "dec_norm.bias", "prediction_head.weight", "mask_token",
        "enc_pos_embed", "dec_pos_embed", "dec_blocks.1.norm3.weight"})
    EXPECT_TRUE(sd.count(k)) << k;
}

TEST(PosEmbed, MatchesTheFormula) {
  const int D = 16, G = 3;
  auto e = sincosPosEmbed(D, G);
  ASSERT_EQ(e.sizes(), (std::vector<int64_t>{9, 16}));
  for (int r = 0; r < G; ++r)
    for (int c = 0; c < G; ++c)
      for (int i = 0; i < D / 4; ++i) {
        const double w = 1.0 / std::pow(10000.0, static_cast<double>(i) / (D / 4));
        const int n = r * G + c;
        EXPECT_NEAR(e[n][i].item<float>(), std::sin(c * w), 1e-6);  // column first
        EXPECT_NEAR(e[n][D / 4 + i].item<float>(), std::cos(c * w), 1e-6);
        EXPECT_NEAR(e[n][D / 2 + i].item<float>(), std::sin(r * w), 1e-6);  // then the row
        EXPECT_NEAR(e[n][3 * D / 4 + i].item<float>(), std::cos(r * w), 1e-6);
      }
}

TEST(RandomMask, CountAndOrder) {
  CroCoNet net(tinyConfig());
  torch::manual_seed(3);
  auto m = net->randomMask(5, torch::kCPU);
  for (int b = 0; b < 5; ++b) EXPECT_EQ(m[b].sum().item<int64_t>(), static_cast<int>(0.9 * 16));
  // Masking keeps the visible tokens in their order: encode with a known mask equals encoding
  // the visible patches' features picked by hand.
  auto mask = torch::zeros({1, 16}, torch::kBool);
  mask.index_put_({0, torch::tensor({0, 2, 3, 5, 7, 8, 9, 11, 12, 13, 15})}, true);
  auto img = torch::randn({1, 3, 64, 64});
  torch::NoGradGuard ng;
  auto x = net->patch_embed(img) + net->enc_pos_embed.unsqueeze(0);
  auto vis = x.index({0, torch::tensor({1, 4, 6, 10, 14})}).unsqueeze(0);
  auto pos = patchPositions(4).index({torch::tensor({1, 4, 6, 10, 14})}).unsqueeze(0);
  for (auto& blk : *net->enc_blocks) vis = blk->as<Block>()->forward(vis, pos);
  EXPECT_TRUE(torch::allclose(net->encode(img, mask), net->enc_norm(vis), 1e-5, 1e-5));
}

TEST(MaskedMse, HandComputedCase) {
  // One image, two patches of 4 values; patch 1 masked. target [1,2,3,4]: mean 2.5, unbiased
  // var 5/3; normalised t = (x - 2.5) / sqrt(5/3 + 1e-6).
  auto target = torch::tensor({1.f, 2.f, 3.f, 4.f, 0.f, 0.f, 0.f, 1.f}).view({1, 2, 4});
  auto pred = torch::zeros({1, 2, 4});
  auto mask = torch::tensor({true, false}).view({1, 2});
  const double s = std::sqrt(5.0 / 3.0 + 1e-6);
  double expected = 0;
  for (double v : {1.0, 2.0, 3.0, 4.0}) expected += std::pow((v - 2.5) / s, 2) / 4;
  EXPECT_NEAR(maskedMse(pred, mask, target).item<double>(), expected, 1e-6);
  EXPECT_NEAR(maskedMse(pred, mask, target, false).item<double>(), (1 + 4 + 9 + 16) / 4.0, 1e-6);
}

TEST(Patchify, RoundTripAndLayout) {
  auto img = torch::arange(2 * 3 * 8 * 8, torch::kFloat32).view({2, 3, 8, 8});
  auto p = patchify(img, 4);
  EXPECT_EQ(p.sizes(), (std::vector<int64_t>{2, 4, 48}));
  // Patch (0, 1), pixel (0, 0), channel 2 sits at index (0 * 4 + 0) * 3 + 2.
  EXPECT_EQ(p[0][1][2].item<float>(), img[0][2][0][4].item<float>());
  EXPECT_TRUE(torch::equal(unpatchify(p, 4), img));
}

TEST(Checkpoint, RoundTripGivesTheSameOutputs) {
  const std::string dir = testing::scratchDir("ck");
  torch::manual_seed(1);
  CroCoNet a(tinyConfig());
  saveCheckpoint(dir + "/c.pth", a, 7, {{"step", 42}});
  const Checkpoint ck = loadCheckpoint(dir + "/c.pth");
  EXPECT_EQ(ck.epoch, 7);
  EXPECT_EQ(ck.extra["step"], 42);
  ASSERT_TRUE(ck.hasArgs);
  const CroCoConfig cfg = configFromJson(ck.args, "c.pth");
  EXPECT_EQ(cfg.img_size, 64);
  torch::manual_seed(99);
  CroCoNet b(cfg);
  loadStateDictStrict(b, ck.model, "c.pth");
  auto img1 = torch::randn({2, 3, 64, 64}), img2 = torch::randn({2, 3, 64, 64});
  auto mask = a->randomMask(2, torch::kCPU);
  torch::NoGradGuard ng;
  EXPECT_TRUE(torch::equal(a->forward(img1, img2, mask).prediction,
                           b->forward(img1, img2, mask).prediction));
}

TEST(Checkpoint, StrictLoadNamesWrongKeysAndShapes) {
  CroCoNet net(tinyConfig());
  auto sd = stateDict(net);
  auto renamed = sd;
  renamed["enc_blocks.0.attn.qkv.weightX"] = renamed["enc_blocks.0.attn.qkv.weight"];
  renamed.erase("enc_blocks.0.attn.qkv.weight");
  try {
    loadStateDictStrict(net, renamed, "x.pth");
    FAIL();
  } catch (const Error& e) {
    const std::string w = e.what();
    EXPECT_NE(w.find("x.pth"), std::string::npos);
    EXPECT_NE(w.find("missing keys [enc_blocks.0.attn.qkv.weight]"), std::string::npos) << w;
    EXPECT_NE(w.find("unexpected keys [enc_blocks.0.attn.qkv.weightX]"), std::string::npos) << w;
  }
  auto reshaped = sd;
  reshaped["dec_norm.weight"] = torch::zeros({7});
  try {
    loadStateDictStrict(net, reshaped, "y.pth");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("dec_norm.weight"), std::string::npos) << e.what();
  }
  auto nan = sd;
  nan["enc_norm.bias"] = torch::full({192}, NAN);
  EXPECT_ERROR_CONTAINS(loadStateDictStrict(net, nan, "z.pth"),
                        "z.pth: state_dict entry 'enc_norm.bias' holds NaN or inf");
}

TEST(Checkpoint, BadFilesAreClearErrors) {
  const std::string dir = testing::scratchDir("bad");
  EXPECT_ERROR_CONTAINS(loadCheckpoint(dir + "/none.pth"), dir + "/none.pth: no such checkpoint");
  writeFileAtomic(dir + "/junk.pth", "this is not a checkpoint");
  EXPECT_ERROR_CONTAINS(loadCheckpoint(dir + "/junk.pth"), dir + "/junk.pth: not a zip checkpoint");
  CroCoNet net(tinyConfig());
  saveCheckpoint(dir + "/ok.pth", net, 0);
  const std::string bytes = readFile(dir + "/ok.pth");
  writeFileAtomic(dir + "/cut.pth", bytes.substr(0, bytes.size() / 2));
  try {
    loadCheckpoint(dir + "/cut.pth");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("cut.pth"), std::string::npos);
  }
}

TEST(CroCoNet, TinyModelOverfitsOnePair) {
  torch::manual_seed(0);
  CroCoConfig cfg = tinyConfig(32);
  cfg.patch_size = 8;
  CroCoNet net(cfg);
  auto img1 = torch::rand({1, 3, 32, 32}), img2 = img1.roll(3, 3);
  auto mask = net->randomMask(1, torch::kCPU);
  torch::optim::AdamW opt(net->parameters(), torch::optim::AdamWOptions(1e-3).weight_decay(0.0));
  double first = 0, last = 0;
  for (int step = 0; step < 300; ++step) {
    auto out = net->forward(img1, img2, mask);
    auto loss = maskedMse(out.prediction, out.mask, out.target);
    opt.zero_grad();
    loss.backward();
    opt.step();
    if (step == 0) first = loss.item<double>();
    last = loss.item<double>();
  }
  EXPECT_LT(last, first / 10) << "loss " << first << " -> " << last;
}

TEST(CroCoNet, MatchesAPythonReimplementationThroughTorchLoad) {
  if (std::system("/usr/bin/python3 -c 'import torch' > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "python3-torch not installed";
  const std::string dir = testing::scratchDir("py");
  torch::manual_seed(5);
  CroCoNet net(tinyConfig());
  saveCheckpoint(dir + "/model.pth", net, 3);
  auto img1 = torch::randn({2, 3, 64, 64}), img2 = torch::randn({2, 3, 64, 64});
  auto mask = net->randomMask(2, torch::kCPU);
  // Tagless, as our checkpoints: the torch.load defaults of torch >= 2.6 refuse TorchScript's
  // type tags, which torch::pickle_save writes.
  saveTensors(dir + "/inputs.pth", {{"img1", img1}, {"img2", img2}, {"mask", mask}});
  const std::string cmd = "/usr/bin/python3 " + testing::sourceDir() +
                          "/tests/model/croco_ref.py forward " + dir + "/model.pth " + dir +
                          "/inputs.pth " + dir + "/out.pth";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  // Python wrote an OrderedDict: our reader must see it (LibTorch's own turns it into None).
  const Checkpoint out = loadCheckpoint(dir + "/out.pth");
  ASSERT_TRUE(out.model.count("pred"));
  torch::NoGradGuard ng;
  const CroCoOutput ours = net->forward(img1, img2, mask);
  EXPECT_LT((ours.prediction - out.model.at("pred")).abs().max().item<double>(), 1e-4);
  EXPECT_NEAR(maskedMse(ours.prediction, ours.mask, ours.target).item<double>(),
              out.model.at("loss")[0].item<double>(), 1e-4);

  // An official-style file: {'model': OrderedDict, 'args': argparse.Namespace, 'optimizer': ...}.
  const std::string off = "/usr/bin/python3 " + testing::sourceDir() +
                          "/tests/model/croco_ref.py officialize " + dir + "/model.pth " + dir +
                          "/official.pth";
  ASSERT_EQ(std::system(off.c_str()), 0) << off;
  const Checkpoint official = loadCheckpoint(dir + "/official.pth");
  EXPECT_EQ(official.epoch, 5);
  ASSERT_TRUE(official.hasArgs);
  EXPECT_EQ(official.args["enc_embed_dim"], 192);
  EXPECT_TRUE(official.extraTensors.count("optimizer/state/0/exp_avg"));
  CroCoNet again(configFromJson(official.args, "official.pth"));
  loadStateDictStrict(again, official.model, "official.pth");
  EXPECT_TRUE(torch::equal(again->forward(img1, img2, mask).prediction, ours.prediction));
}

}  // namespace
}  // namespace paircast
