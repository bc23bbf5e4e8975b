// The downstream models: naver/croco's names and hooks, the DPT head against an independent
// Python forward pass, the pose head's Procrustes layer, the losses, the metrics and the tiling.
#include "model/downstream.h"

#include <gtest/gtest.h>

#include <cstdlib>

#include "finetune/evaluate.h"
#include "finetune/finetune.h"
#include "model/checkpoint.h"
#include "test_errors.h"
#include "test_paths.h"

namespace paircast {
namespace {

DownstreamConfig tinyConfig(const std::string& task, const std::string& head, int size) {
  DownstreamConfig c;
  c.croco = presetConfig("tiny");
  c.croco.img_size = size;
  c.task = task;
  c.head = head;
  return c;
}

TEST(DptHooks, FollowNaverCrocoWhereItHasThemAndSpreadOverOurDecoders) {
  EXPECT_EQ(defaultDptHooks(12, 8), (std::vector<int>{10, 13, 16, 19}));
  EXPECT_EQ(defaultDptHooks(24, 12), (std::vector<int>{23, 27, 31, 35}));
  EXPECT_EQ(defaultDptHooks(12, 0), (std::vector<int>{2, 5, 8, 11}));
  EXPECT_EQ(defaultDptHooks(12, 4), (std::vector<int>{11, 13, 14, 15}));  // small
  EXPECT_EQ(defaultDptHooks(6, 2), (std::vector<int>{5, 5, 6, 7}));       // tiny
}

TEST(DptHead, StateDictHasNaverCrocosNamesAndShapes) {
  torch::manual_seed(0);
  DownstreamNet net(tinyConfig("flow", "dpt", 128));
  const auto sd = net->state();
  for (const char* k :
       {"head.dpt.scratch.layer1_rn.weight", "head.dpt.scratch.layer_rn.0.weight",
        "head.dpt.act_1_postprocess.1.weight", "head.dpt.act_postprocess.0.1.weight",
        "head.dpt.scratch.refinenet4.resConfUnit2.conv2.bias", "head.dpt.head.4.weight",
        "enc_pos_embed", "dec_pos_embed", "decoder_embed.weight", "dec_blocks.1.norm_y.weight"})
    EXPECT_TRUE(sd.count(k)) << k;
  EXPECT_FALSE(sd.count("mask_token"));
  EXPECT_FALSE(sd.count("prediction_head.weight"));
  EXPECT_FALSE(sd.count("head.dpt.scratch.layer1_rn.bias"));  // bias=False, as naver/croco's
  // One tensor under both names.
  EXPECT_EQ(sd.at("head.dpt.scratch.layer2_rn.weight").data_ptr(),
            sd.at("head.dpt.scratch.layer_rn.1.weight").data_ptr());
  EXPECT_EQ(sd.at("head.dpt.act_postprocess.3.1.weight").sizes(),
            (std::vector<int64_t>{768, 768, 3, 3}));
  EXPECT_EQ(sd.at("head.dpt.act_1_postprocess.0.weight").sizes(),
            (std::vector<int64_t>{96, 192, 1, 1}));  // hook 5: an encoder block
  EXPECT_EQ(sd.at("head.dpt.act_2_postprocess.0.weight").sizes(),
            (std::vector<int64_t>{192, 192, 1, 1}));  // hook 5 again
  EXPECT_EQ(sd.at("head.dpt.act_3_postprocess.0.weight").sizes(),
            (std::vector<int64_t>{384, 128, 1, 1}));      // a decoder block
  EXPECT_EQ(sd.at("head.dpt.head.4.weight").size(0), 3);  // flow and confidence
  const auto unique = net->uniqueParameters();
  // Listed twice: layer_rn (4 weights) and act_postprocess (7 convs, weight and bias).
  EXPECT_EQ(unique.size() + 4 + 14, net->named_parameters().size());
  const auto entries = net->checkpointEntries();
  EXPECT_EQ(entries["head_kwargs"]["hooks_idx"], (std::vector<int>{5, 5, 6, 7}));
  EXPECT_EQ(entries["head_kwargs"]["num_channels"], 3);
  EXPECT_FALSE(entries["croco_kwargs"].contains("decoder"));
  EXPECT_EQ(entries["croco_kwargs"]["img_size"], 128);

  DownstreamNet depth(tinyConfig("depth", "dpt", 128));
  const auto dsd = depth->state();
  EXPECT_FALSE(dsd.count("decoder_embed.weight"));
  EXPECT_FALSE(dsd.count("dec_blocks.0.norm1.weight"));
  EXPECT_TRUE(dsd.count("dec_pos_embed"));  // naver/croco registers it before the decoder
  EXPECT_EQ(depth->hooks(), (std::vector<int>{2, 3, 4, 5}));
  EXPECT_EQ(dsd.at("head.dpt.head.4.weight").size(0), 1);
}

TEST(DptHead, RefusesSizesItCannotTake) {
  EXPECT_ERROR_CONTAINS(DownstreamNet(tinyConfig("flow", "dpt", 112)), "divisible by 32");
  auto patch8 = tinyConfig("flow", "dpt", 64);
  patch8.croco.patch_size = 8;
  EXPECT_ERROR_CONTAINS(DownstreamNet{patch8}, "16-pixel patches");
  EXPECT_NO_THROW(DownstreamNet(tinyConfig("flow", "linear", 112)));
  EXPECT_ERROR_CONTAINS(DownstreamNet(tinyConfig("pose", "dpt", 64)),
                        "--task pose takes --head pose");
  auto hooks = tinyConfig("depth", "dpt", 64);
  hooks.hooks = {0, 1, 2, 6};  // the encoder has blocks 0-5
  EXPECT_ERROR_CONTAINS(DownstreamNet{hooks}, "DPT hook 6 is not a block");
}

TEST(Downstream, OutputsHaveTheirShapes) {
  torch::manual_seed(1);
  torch::NoGradGuard ng;
  const auto a = torch::randn({2, 3, 64, 64}), b = torch::randn({2, 3, 64, 64});
  EXPECT_EQ(DownstreamNet(tinyConfig("flow", "dpt", 64))->forward(a, b).sizes(),
            (std::vector<int64_t>{2, 3, 64, 64}));
  EXPECT_EQ(DownstreamNet(tinyConfig("flow", "linear", 64))->forward(a, b).sizes(),
            (std::vector<int64_t>{2, 2, 64, 64}));
  EXPECT_EQ(DownstreamNet(tinyConfig("depth", "linear", 64))->forward(a).sizes(),
            (std::vector<int64_t>{2, 1, 64, 64}));
  const auto pose = DownstreamNet(tinyConfig("pose", "pose", 64))->forward(a, b);
  ASSERT_EQ(pose.sizes(), (std::vector<int64_t>{2, 12}));
  const auto R = pose.narrow(1, 0, 9).view({2, 3, 3});
  EXPECT_LT((torch::matmul(R, R.transpose(1, 2)) - torch::eye(3)).abs().max().item<double>(), 1e-5);
  EXPECT_NEAR(torch::det(R)[0].item<double>(), 1.0, 1e-5);
  EXPECT_ERROR_CONTAINS(
      DownstreamNet(tinyConfig("flow", "dpt", 64))->forward(a, torch::randn({2, 3, 32, 32})),
      "image 2 must be [B, 3, 64, 64]");
}

TEST(Downstream, FlowHeadsRegressInUnitsOfTheFlowScale) {
  // The same weights at flow scale 1 and 4: u and v come out 4 times larger, the DPT head's
  // confidence as it was. The default is img_size / 16; checkpoints keep the scale, and one
  // without it regressed pixels.
  torch::NoGradGuard ng;
  for (const std::string head : {"linear", "dpt"}) {
    SCOPED_TRACE(head);
    const int size = head == "dpt" ? 128 : 64;
    const auto x1 = torch::randn({1, 3, size, size}), x2 = torch::randn({1, 3, size, size});
    DownstreamConfig c = tinyConfig("flow", head, size);
    c.flowScale = 1;
    torch::manual_seed(5);
    const auto pixels = DownstreamNet(c)->forward(x1, x2);
    c.flowScale = 4;
    torch::manual_seed(5);
    const auto scaled = DownstreamNet(c)->forward(x1, x2);
    EXPECT_TRUE(torch::allclose(scaled.narrow(1, 0, 2), 4 * pixels.narrow(1, 0, 2)));
    if (head == "dpt") {
      EXPECT_TRUE(torch::equal(scaled.narrow(1, 2, 1), pixels.narrow(1, 2, 1)));
    }
  }
  DownstreamConfig c = tinyConfig("flow", "linear", 64);
  EXPECT_EQ(c.flowScaleInUse(), 4.0);
  DownstreamNet net(c);
  EXPECT_EQ(net->checkpointEntries()["flow_scale"], 4.0);
  const std::string dir = testing::scratchDir("scale");
  saveCheckpoint(dir + "/with.pth", net->state(), 0, net->checkpointEntries());
  EXPECT_EQ(downstreamConfigOf(loadCheckpoint(dir + "/with.pth"), "with").flowScaleInUse(), 4.0);
  nlohmann::json old = net->checkpointEntries();
  old.erase("flow_scale");
  saveCheckpoint(dir + "/without.pth", net->state(), 0, old);
  EXPECT_EQ(downstreamConfigOf(loadCheckpoint(dir + "/without.pth"), "without").flowScaleInUse(),
            1.0);
  old["flow_scale"] = -2;
  saveCheckpoint(dir + "/bad.pth", net->state(), 0, old);
  EXPECT_ERROR_CONTAINS(downstreamConfigOf(loadCheckpoint(dir + "/bad.pth"), "bad.pth"),
                        "bad.pth: flow_scale is not a positive number: -2");
}

TEST(Downstream, MatchesAnIndependentPythonForwardThroughTorchLoad) {
  if (std::system("/usr/bin/python3 -c 'import torch' > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "python3-torch not installed";
  for (const std::string task : {"flow", "depth"}) {
    SCOPED_TRACE(task);
    const std::string dir = testing::scratchDir(task);
    torch::manual_seed(3);
    DownstreamNet net(tinyConfig(task, "dpt", 64));
    saveCheckpoint(dir + "/model.pth", net->state(), 0, net->checkpointEntries());
    const auto img1 = torch::randn({2, 3, 64, 64}), img2 = torch::randn({2, 3, 64, 64});
    saveTensors(dir + "/inputs.pth", {{"img1", img1}, {"img2", img2}});
    const std::string cmd = "/usr/bin/python3 " + testing::sourceDir() +
                            "/tests/finetune/downstream_ref.py forward " + dir + "/model.pth " +
                            dir + "/inputs.pth " + dir + "/out.pth";
    ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
    torch::NoGradGuard ng;
    const auto ours = net->forward(img1, img2);
    const auto theirs = loadCheckpoint(dir + "/out.pth").model.at("pred");
    ASSERT_EQ(ours.sizes(), theirs.sizes());
    EXPECT_LT((ours - theirs).abs().max().item<double>(), 1e-4);
  }
}

TEST(Procrustes, GivesTheNearestRotationWithDeterminantOne) {
  torch::manual_seed(2);
  const auto q = std::get<0>(torch::linalg_qr(torch::randn({4, 3, 3}, torch::kFloat64)));
  const auto R = q * torch::det(q).view({4, 1, 1});  // proper rotations
  const auto noisy = R + 1e-3 * torch::randn({4, 3, 3}, torch::kFloat64);
  EXPECT_LT((procrustesRotation(noisy) - R).abs().max().item<double>(), 5e-3);
  // A reflection's nearest rotation flips the axis of the smallest singular value.
  const auto reflect = torch::diag(torch::tensor({3.0, 2.0, -1.0}, torch::kFloat64)).unsqueeze(0);
  const auto fixed = procrustesRotation(reflect)[0];
  EXPECT_TRUE(torch::allclose(fixed, torch::eye(3, torch::kFloat64)));
}

// The rotation of an SVD, d = det(U V^T) fixing the sign: what LibTorch's SVD gradient goes
// through.
torch::Tensor svdRotation(const torch::Tensor& m) {
  auto [u, s, vh] = torch::linalg_svd(m, /*full_matrices=*/false);
  const auto d = torch::det(torch::matmul(u, vh));
  const auto ones = torch::ones_like(d);
  return torch::matmul(torch::matmul(u, torch::diag_embed(torch::stack({ones, ones, d}, 1))), vh);
}

TEST(Procrustes, ItsGradientIsLibTorchsWhereThatIsDefinedAndFiniteWhereItIsNot) {
  torch::manual_seed(3);
  // Near the head's start (2 I + small), one reflection among them (det < 0).
  auto m = 2 * torch::eye(3, torch::kFloat64) + 0.3 * torch::randn({6, 3, 3}, torch::kFloat64);
  m[5] = torch::diag(torch::tensor({3.0, 2.0, -1.0}, torch::kFloat64)) +
         0.1 * torch::randn({3, 3}, torch::kFloat64);
  const auto g = torch::randn({6, 3, 3}, torch::kFloat64);
  auto ours = m.clone().requires_grad_(), theirs = m.clone().requires_grad_();
  (procrustesRotation(ours) * g).sum().backward();
  (svdRotation(theirs) * g).sum().backward();
  EXPECT_LT((ours.grad() - theirs.grad()).abs().max().item<double>(), 1e-10);
  EXPECT_GT(ours.grad().abs().max().item<double>(), 0.05);
  // In float32 (the head's type) the same gradient, the SVD still taken in float64.
  auto single = m.to(torch::kFloat32).requires_grad_();
  (procrustesRotation(single) * g.to(torch::kFloat32)).sum().backward();
  EXPECT_EQ(single.grad().scalar_type(), torch::kFloat32);
  EXPECT_LT((single.grad().to(torch::kFloat64) - theirs.grad()).abs().max().item<double>(), 1e-5);
  // At M = 2 I the singular values repeat: LibTorch's gradient is NaN, the closed form is the
  // derivative, as central differences give it.
  const auto twoI = (2 * torch::eye(3, torch::kFloat64)).unsqueeze(0);
  auto at = twoI.clone().requires_grad_(), svdAt = twoI.clone().requires_grad_();
  (procrustesRotation(at) * g[0]).sum().backward();
  (svdRotation(svdAt) * g[0]).sum().backward();
  EXPECT_FALSE(torch::isfinite(svdAt.grad()).all().item<bool>());
  const double h = 1e-6;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      auto step = torch::zeros_like(twoI);
      step[0][i][j] = h;
      const double numeric = ((procrustesRotation(twoI + step) * g[0]).sum() -
                              (procrustesRotation(twoI - step) * g[0]).sum())
                                 .item<double>() /
                             (2 * h);
      EXPECT_NEAR(at.grad()[0][i][j].item<double>(), numeric, 1e-6) << i << ", " << j;
    }
}

TEST(FinetuneLoss, LaplacianLossBoundedOverKnownFlowOnly) {
  auto gt = torch::zeros({1, 2, 1, 3});
  gt[0][0][0][1] = 2.0f;
  gt[0][0][0][2] = std::numeric_limits<float>::infinity();
  gt[0][1][0][2] = std::numeric_limits<float>::infinity();
  auto out = torch::zeros({1, 3, 1, 3});
  out[0][1][0][0] = 1.0f;                 // v error 1 at pixel 0
  const double conf = 3.75 * 0.5 + 0.25;  // sigmoid(0) = 1/2
  const double expected = ((1.0 / conf + std::log(conf)) + (2.0 / conf + std::log(conf))) / 2;
  const auto none = torch::Tensor();
  EXPECT_NEAR(finetuneLoss("flow", "dpt", out, gt, none, none).item<double>(), expected, 1e-6);
  // The linear head's squared error counts pixel 0 alone: pixel 1's flow leaves the frame.
  EXPECT_NEAR(finetuneLoss("flow", "linear", out.narrow(1, 0, 2), gt, none, none).item<double>(),
              0.5, 1e-6);
  auto depth = torch::tensor({0.f, std::exp(1.f), 1.f}).view({1, 1, 1, 3});
  EXPECT_NEAR(
      finetuneLoss("depth", "dpt", torch::zeros({1, 1, 1, 3}), none, depth, none).item<double>(),
      0.5, 1e-6);
  auto pose =
      torch::tensor({1.f, 0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 0.f, 1.f, 0.1f, 0.f, 0.f}).view({1, 12});
  auto pred = pose.clone();
  pred[0][0] = 0.f;
  pred[0][9] = 0.f;
  EXPECT_NEAR(finetuneLoss("pose", "pose", pred, none, none, pose).item<double>(), 1.0 + 100 * 0.01,
              1e-5);
}

TEST(HeldOutMetrics, KnownValues) {
  auto truth = torch::zeros({2, 2, 2});
  truth[0][0][0] = std::numeric_limits<float>::infinity();  // unknown
  auto pred = torch::zeros({2, 2, 2});
  pred[0][0][1] = 3.0f;
  pred[1][0][1] = 4.0f;  // error 5 at (0, 1)
  pred[0][1][0] = 2.0f;  // error 2 at (1, 0)
  auto covisible = torch::tensor({false, true, false, false}).view({2, 2});
  const auto m = flowMetrics(pred, truth, covisible);
  EXPECT_NEAR(m["aepe"].get<double>(), 7.0 / 3, 1e-9);
  EXPECT_NEAR(m["aepe_covisible"].get<double>(), 5.0, 1e-9);
  EXPECT_NEAR(m["px1"].get<double>(), 2.0 / 3, 1e-9);
  EXPECT_NEAR(m["px3"].get<double>(), 1.0 / 3, 1e-9);
  EXPECT_NEAR(m["px5"].get<double>(), 0.0, 1e-9);
  const auto d = depthMetrics(torch::tensor({1.f, 2.f, 9.f}), torch::tensor({1.f, 1.f, 0.f}));
  EXPECT_NEAR(d["delta1"].get<double>(), 0.5, 1e-9);
  EXPECT_NEAR(d["absrel"].get<double>(), 0.5, 1e-9);
  EXPECT_NEAR(d["rmse"].get<double>(), std::sqrt(0.5), 1e-9);
  // 90 degrees about z, and 2 m off.
  const auto truthPose =
      torch::tensor({0.f, -1.f, 0.f, 1.f, 0.f, 0.f, 0.f, 0.f, 1.f, 2.f, 0.f, 0.f});
  const auto identity = torch::tensor({1.f, 0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 0.f});
  const auto p = poseMetrics(identity, truthPose);
  EXPECT_NEAR(p["rot_err"].get<double>(), 90.0, 1e-4);
  EXPECT_NEAR(p["trans_err"].get<double>(), 2.0, 1e-6);
  const auto s = summariseFigures({{{"rot_err", 1.0}, {"aepe", 2.0}},
                                   {{"rot_err", 5.0}, {"aepe", 4.0}},
                                   {{"rot_err", 2.0}, {"aepe", nullptr}}});
  EXPECT_EQ(s["pairs"], 3);
  EXPECT_EQ(s["median_rot_err"], 2.0);
  EXPECT_EQ(s["aepe"], 3.0);
}

TEST(Tiling, EachPixelTakesTheTileWhoseCentreIsNearest) {
  const TileAxis one = tileAxis(128, 128);
  EXPECT_EQ(one.origins, (std::vector<int64_t>{0}));
  const TileAxis a = tileAxis(256, 128);
  EXPECT_EQ(a.origins, (std::vector<int64_t>{0, 64, 128}));
  // Centres 64, 128, 192: boundaries halfway between them.
  EXPECT_EQ(a.owner[95], 0);
  EXPECT_EQ(a.owner[96], 1);
  EXPECT_EQ(a.owner[159], 1);
  EXPECT_EQ(a.owner[160], 2);
  const TileAxis b = tileAxis(300, 128);  // overlaps of at least half a tile
  for (size_t i = 1; i < b.origins.size(); ++i) EXPECT_LE(b.origins[i] - b.origins[i - 1], 64);
  EXPECT_EQ(b.origins.back(), 300 - 128);
}

TEST(Tiling, APredictionOfOneTileIsTheForwardPass) {
  torch::manual_seed(4);
  DownstreamNet net(tinyConfig("flow", "linear", 64));
  net->eval();
  const auto a = torch::randn({1, 3, 64, 64}), b = torch::randn({1, 3, 64, 64});
  torch::NoGradGuard ng;
  EXPECT_TRUE(torch::equal(predict(net, a, b), net->forward(a, b)));
  // Images larger than the tile both ways, 96 x 128: tiles at rows 0, 32 and columns 0, 32, 64,
  // whose centres put the boundaries at row 48 and columns 48 and 80. Each block, up to and
  // including the rows and columns on either side of a boundary, is its own tile's forward pass.
  const auto big1 = torch::randn({1, 3, 96, 128}), big2 = torch::randn({1, 3, 96, 128});
  const TileAxis rows = tileAxis(96, 64), cols = tileAxis(128, 64);
  ASSERT_EQ(rows.origins, (std::vector<int64_t>{0, 32}));
  ASSERT_EQ(cols.origins, (std::vector<int64_t>{0, 32, 64}));
  EXPECT_EQ(rows.owner[47], 0);
  EXPECT_EQ(rows.owner[48], 1);
  EXPECT_EQ(cols.owner[47], 0);
  EXPECT_EQ(cols.owner[48], 1);
  EXPECT_EQ(cols.owner[79], 1);
  EXPECT_EQ(cols.owner[80], 2);
  const auto full = predict(net, big1, big2);
  ASSERT_EQ(full.sizes(), (std::vector<int64_t>{1, 2, 96, 128}));
  const std::vector<std::pair<int64_t, int64_t>> rowBlocks = {{0, 48}, {48, 96}};
  const std::vector<std::pair<int64_t, int64_t>> colBlocks = {{0, 48}, {48, 80}, {80, 128}};
  for (size_t i = 0; i < 2; ++i)
    for (size_t j = 0; j < 3; ++j) {
      const int64_t top = rows.origins[i], left = cols.origins[j];
      const auto [y0, y1] = rowBlocks[i];
      const auto [x0, x1] = colBlocks[j];
      const auto tile = net->forward(big1.narrow(2, top, 64).narrow(3, left, 64),
                                     big2.narrow(2, top, 64).narrow(3, left, 64));
      EXPECT_TRUE(torch::equal(full.narrow(2, y0, y1 - y0).narrow(3, x0, x1 - x0),
                               tile.narrow(2, y0 - top, y1 - y0).narrow(3, x0 - left, x1 - x0)))
          << "tile " << i << ", " << j;
    }
  // Across a boundary the tiles disagree (they see different context), so the check above
  // would fail for a block taken from the wrong tile.
  const auto second = net->forward(big1.narrow(2, 32, 64).narrow(3, 0, 64),
                                   big2.narrow(2, 32, 64).narrow(3, 0, 64));
  EXPECT_FALSE(torch::equal(full.narrow(2, 40, 8).narrow(3, 0, 48),
                            second.narrow(2, 8, 8).narrow(3, 0, 48)));
  EXPECT_ERROR_CONTAINS(predict(net, torch::randn({1, 3, 32, 64}), torch::randn({1, 3, 32, 64})),
                        "smaller than the model's tiles of 64");
}

TEST(Tiling, ConfidenceTilingWeighsOverlappingTilesByTheHeadsConfidence) {
  torch::manual_seed(5);
  const auto config = tinyConfig("flow", "dpt", 64);
  DownstreamNet net(config);
  net->eval();
  torch::NoGradGuard ng;
  // 64 x 96: tiles at columns 0 and 32. Columns 32 to 63 lie in both, the others in one.
  const auto a = torch::randn({1, 3, 64, 96}), b = torch::randn({1, 3, 64, 96});
  const auto left = net->forward(a.narrow(3, 0, 64), b.narrow(3, 0, 64));
  const auto right = net->forward(a.narrow(3, 32, 64), b.narrow(3, 32, 64));
  const auto out = predict(net, a, b, Tiling::kConfidence);
  ASSERT_EQ(out.sizes(), (std::vector<int64_t>{1, 3, 64, 96}));
  EXPECT_TRUE(torch::allclose(out.narrow(3, 0, 32), left.narrow(3, 0, 32)));
  EXPECT_TRUE(torch::allclose(out.narrow(3, 64, 32), right.narrow(3, 32, 32)));
  // In the overlap: the tiles' outputs weighted by 1 / the Laplacian scale of each.
  const auto l = left.narrow(3, 32, 32), r = right.narrow(3, 0, 32);
  const auto wl = 1.0 / (3.75 * torch::sigmoid(l.narrow(1, 2, 1)) + 0.25);
  const auto wr = 1.0 / (3.75 * torch::sigmoid(r.narrow(1, 2, 1)) + 0.25);
  const auto expected = (l * wl + r * wr) / (wl + wr);
  EXPECT_TRUE(torch::allclose(out.narrow(3, 32, 32), expected, 1e-5, 1e-6));
  // The weights differ from an even mean there, so the check above tells the two apart.
  EXPECT_FALSE(torch::allclose(out.narrow(3, 32, 32), 0.5 * (l + r), 1e-5, 1e-6));
  // Nearest tiling takes column 47 from the left tile and 48 from the right one.
  const auto nearest = predict(net, a, b);
  EXPECT_TRUE(torch::equal(nearest.select(3, 47), left.select(3, 47)));
  EXPECT_TRUE(torch::equal(nearest.select(3, 48), right.select(3, 16)));
  // Without a confidence channel (depth) the overlap is the plain mean.
  auto depthConfig = config;
  depthConfig.task = "depth";
  DownstreamNet depth(depthConfig);
  depth->eval();
  const auto dl = depth->forward(a.narrow(3, 0, 64), torch::Tensor());
  const auto dr = depth->forward(a.narrow(3, 32, 64), torch::Tensor());
  EXPECT_TRUE(
      torch::allclose(predict(depth, a, torch::Tensor(), Tiling::kConfidence).narrow(3, 32, 32),
                      0.5 * (dl.narrow(3, 32, 32) + dr.narrow(3, 0, 32)), 1e-5, 1e-6));
  EXPECT_EQ(parseTiling("confidence"), Tiling::kConfidence);
  EXPECT_EQ(parseTiling("nearest"), Tiling::kNearest);
  EXPECT_ERROR_CONTAINS(parseTiling("mean"), "tiling is 'nearest' or 'confidence', not 'mean'");
}

}  // namespace
}  // namespace paircast
