#include "sweep/mechanism_probe.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numeric>
#include <random>

#include "sweep/patch_correspondence.h"
#include "test_errors.h"

namespace paircast {
namespace {

constexpr int kPatch = 8, kGrid = 4, kSide = kPatch * kGrid;

// A camera of side x side pixels at `x` metres along x, looking down +z, and the z-depth of a
// wall at `wall` metres that fills its view.
struct WallView {
  Camera camera;
  ImageF depth;
};
WallView wallView(double x, float wall, int side = kSide) {
  WallView v{Camera::fromHfov(side, side, 60.0), ImageF(side, side, 1, wall)};
  v.camera.t_cam2world = Eigen::Vector3d(x, 0, 0);
  return v;
}

// The sideways move that shifts a wall at `wall` metres by k patches: f t / z = k p.
double shiftOf(int k, double wall, int side = kSide) {
  return k * kPatch * wall / Camera::fromHfov(side, side, 60.0).K(0, 0);
}

TEST(PatchCorrespondence, ASidewaysShiftOfKPatchesGivesK) {
  for (int k = 0; k <= 3; ++k) {
    const WallView a = wallView(0, 2.0f), b = wallView(shiftOf(k, 2.0), 2.0f);
    const PatchCorrespondence t =
        truePatchCorrespondence(a.camera, a.depth, b.camera, b.depth, kPatch);
    ASSERT_EQ(t.grid, kGrid);
    for (int r = 0; r < kGrid; ++r)
      for (int c = 0; c < kGrid; ++c) {
        const int i = r * kGrid + c;
        // The camera moves right, so the wall moves left by k patches in view 2.
        EXPECT_NEAR(t.x[i], c + 0.5 - k, 1e-4) << k << " " << i;
        EXPECT_NEAR(t.y[i], r + 0.5, 1e-4);
        EXPECT_EQ(t.seen[i], c >= k) << k << " " << i;  // the rest leaves view 2's frame
      }
    // Matching every patch to the one k to its left is exact; matching it to itself is k off.
    std::vector<int64_t> shifted(kGrid * kGrid), same(kGrid * kGrid);
    for (int i = 0; i < kGrid * kGrid; ++i) shifted[i] = i - k, same[i] = i;
    MatchTally right, copied;
    right.add(shifted, t);
    copied.add(same, t);
    EXPECT_EQ(right.patches, (kGrid - k) * kGrid);
    EXPECT_DOUBLE_EQ(right.pck1(), 1.0);
    EXPECT_NEAR(right.epe(), 0.0, 1e-4);
    EXPECT_NEAR(copied.epe(), k, 1e-4);
    EXPECT_DOUBLE_EQ(copied.pck1(), k <= 1 ? 1.0 : 0.0);
  }
}

TEST(PatchCorrespondence, OccludedPatchesAndMissesAreNotSeen) {
  WallView a = wallView(0, 3.0f), b = wallView(0, 3.0f);
  // View 2 sees something nearer over its left half: the wall is hidden there.
  for (int y = 0; y < kSide; ++y)
    for (int x = 0; x < kSide / 2; ++x) *b.depth.pixel(x, y) = 1.0f;
  // View 1 has no depth in its first row of patches.
  for (int y = 0; y < kPatch; ++y)
    for (int x = 0; x < kSide; ++x) *a.depth.pixel(x, y) = 0.0f;
  const PatchCorrespondence t =
      truePatchCorrespondence(a.camera, a.depth, b.camera, b.depth, kPatch);
  for (int r = 0; r < kGrid; ++r)
    for (int c = 0; c < kGrid; ++c)
      EXPECT_EQ(t.seen[r * kGrid + c], r > 0 && c >= kGrid / 2) << r << " " << c;
  EXPECT_EQ(t.seenCount(), (kGrid - 1) * kGrid / 2);
  // Bad sizes are refused.
  EXPECT_ERROR_CONTAINS(
      truePatchCorrespondence(a.camera, a.depth, b.camera, ImageF(8, 8, 1), kPatch),
      "view 2: camera and depth must be 32x32");
}

TEST(PatchCorrespondence, AnIdentityCostVolumeOnTheSameViewHasPckOne) {
  const WallView a = wallView(0, 2.5f);
  const PatchCorrespondence t =
      truePatchCorrespondence(a.camera, a.depth, a.camera, a.depth, kPatch);
  MatchTally copy;
  copy.add(argmaxMatches(torch::eye(kGrid * kGrid)), t);
  EXPECT_EQ(copy.patches, kGrid * kGrid);
  EXPECT_DOUBLE_EQ(copy.pck1(), 1.0);
  EXPECT_NEAR(copy.epe(), 0.0, 1e-5);
  EXPECT_TRUE(std::isnan(MatchTally().pck1()));
}

TEST(PatchCorrespondence, PatchShareCountsTheMaskedPixels) {
  Image8 mask(kSide, kSide, 1, 0);
  for (int y = 0; y < kPatch / 2; ++y)
    for (int x = 0; x < kPatch / 2; ++x) *mask.pixel(x + kPatch, y) = 255;  // patch 1's corner
  for (int y = 0; y < kSide; ++y) *mask.pixel(kSide - 1, y) = 255;          // the last column
  const std::vector<float> share = patchShare(mask, kPatch);
  ASSERT_EQ(share.size(), static_cast<size_t>(kGrid * kGrid));
  EXPECT_FLOAT_EQ(share[0], 0.f);
  EXPECT_FLOAT_EQ(share[1], 0.25f);
  EXPECT_FLOAT_EQ(share[kGrid - 1], 1.f / kPatch);
}

TEST(OtherSceneReferences, NeverTheSameSceneAndFixed) {
  std::mt19937 rng(3);
  for (int trial = 0; trial < 50; ++trial) {
    const int scenes = 2 + trial % 4;
    std::vector<std::string> names;
    for (int i = 0; i < 5 + trial; ++i) names.push_back("s" + std::to_string(rng() % scenes));
    std::sort(names.begin(), names.end());
    if (names.front() == names.back()) continue;
    const std::vector<int64_t> other = otherSceneReferences(names);
    ASSERT_EQ(other.size(), names.size());
    for (size_t i = 0; i < names.size(); ++i) {
      ASSERT_GE(other[i], 0);
      ASSERT_LT(other[i], static_cast<int64_t>(names.size()));
      EXPECT_NE(names[other[i]], names[i]) << trial << " " << i;
    }
    EXPECT_EQ(otherSceneReferences(names), other);
  }
  EXPECT_TRUE(otherSceneReferences({"a", "a", "a"}).empty());
  // The k-th pair of a scene takes the k-th (cyclically) of the next scene's.
  EXPECT_EQ(otherSceneReferences({"a", "a", "a", "b", "b"}), (std::vector<int64_t>{3, 4, 3, 0, 1}));
}

// Pairs of random images for a 32-pixel model; pair i's foreign reference is `other`.
MechanismPairs randomPairs(int64_t M, const CroCoConfig& c, std::vector<int64_t> other) {
  torch::manual_seed(5);
  MechanismPairs p;
  p.img1 = torch::randn({M, 3, c.img_size, c.img_size});
  p.img2 = torch::randn({M, 3, c.img_size, c.img_size});
  p.mask = torch::argsort(torch::rand({M, c.numPatches()}), 1, false) < c.numMasked();
  p.seen = (torch::arange(c.numPatches()) % 2).to(torch::kFloat32).expand({M, -1}).contiguous();
  p.valid = torch::ones({M, c.numPatches()});
  p.other = std::move(other);
  const WallView a = wallView(0, 2.0f);
  for (int64_t i = 0; i < M; ++i) {
    p.truth.push_back(truePatchCorrespondence(a.camera, a.depth, a.camera, a.depth, kPatch));
    p.covis.push_back(0.35 + 0.1 * (i % 3));
    p.scene.push_back(i < M / 2 ? "a" : "b");
  }
  return p;
}

CroCoConfig tinyConfig() {
  CroCoConfig c = presetConfig("tiny");
  c.img_size = kSide;
  c.patch_size = kPatch;
  c.validate();
  return c;
}

TEST(ReferenceUse, IsZeroWhenTheForeignReferenceIsTheTrueOne) {
  const CroCoConfig c = tinyConfig();
  torch::manual_seed(1);
  CroCoNet model(c);
  const ReferenceUse same = referenceUse(model, randomPairs(6, c, {0, 1, 2, 3, 4, 5}), 4);
  EXPECT_NEAR(same.gain, 0.0, 1e-12);
  EXPECT_NEAR(same.covisible, 0.0, 1e-12);
  EXPECT_NEAR(same.hidden, 0.0, 1e-12);
  const MechanismPairs pairs =
      randomPairs(6, c, otherSceneReferences({"a", "a", "a", "b", "b", "b"}));
  const ReferenceUse other = referenceUse(model, pairs, 4);
  EXPECT_TRUE(std::isfinite(other.gain));
  EXPECT_NE(other.gain, 0.0);
  // Patches without depth are not "hidden": with none, there is no hidden figure.
  MechanismPairs noDepth = pairs;
  noDepth.valid = torch::zeros_like(pairs.valid);
  const ReferenceUse sky = referenceUse(model, noDepth, 4);
  EXPECT_TRUE(std::isnan(sky.hidden));
  EXPECT_DOUBLE_EQ(sky.covisible, other.covisible);
  // No foreign reference (one scene): no figure.
  EXPECT_TRUE(std::isnan(referenceUse(model, randomPairs(6, c, {}), 4).gain));
}

TEST(MechanismProbes, AnEncoderMatchesAViewWithItselfAndMaeHasNoReferenceFigures) {
  const CroCoConfig c = tinyConfig();
  torch::manual_seed(2);
  CroCoNet model(c);
  MechanismPairs pairs = randomPairs(4, c, {2, 3, 0, 1});
  pairs.img2 = pairs.img1.clone();  // a model that copies: view 2 is view 1
  const nlohmann::json mae = mechanismProbes(model, pairs, "mae");
  EXPECT_DOUBLE_EQ(mae["enc_pck1"].get<double>(), 1.0);
  for (const char* k : {"ref_gain", "ref_gain_covisible", "ref_gain_hidden", "xattn_pck1"})
    EXPECT_TRUE(std::isnan(mae[k].get<double>())) << k;  // written as null
  const nlohmann::json croco = mechanismProbes(model, pairs, "croco");
  EXPECT_DOUBLE_EQ(croco["enc_pck1"].get<double>(), 1.0);
  EXPECT_GE(croco["xattn_pck1"].get<double>(), 0.0);
  EXPECT_GE(croco["xattn_epe"].get<double>(), 0.0);
  // Three covis bins: [0.3, 0.4), [0.4, 0.5) and [0.5, 0.6).
  ASSERT_EQ(croco["probe_by_covis"].size(), 3u);
  EXPECT_NEAR(croco["probe_by_covis"][0]["covis_lo"].get<double>(), 0.3, 1e-12);
  EXPECT_EQ(croco["probe_by_covis"][0]["pairs"], 2);
}

TEST(MechanismProbes, TheReciprocalCostAddsTheSwappedScoresTransposed) {
  // One pair of 2 view-1 patches against 3 view-2 patches.
  const auto s12 = torch::tensor({1.f, 0.f, 0.f, 0.f, 0.f, 0.f}).view({1, 2, 3});
  const auto s21 = torch::tensor({0.f, 0.f, 0.f, 5.f, 0.f, 2.f}).view({1, 3, 2});
  const auto cost = reciprocalCost(s12, s21);
  ASSERT_EQ(cost.sizes(), (std::vector<int64_t>{1, 2, 3}));
  // View-1 patch 0: 1 from S12 at view-2 patch 0; patch 1: 5 from S21 (view-2 patch 1 -> 1).
  EXPECT_EQ(argmaxMatches(cost[0]), (std::vector<int64_t>{0, 1}));
  EXPECT_FLOAT_EQ(cost[0][1][2].item<float>(), 2.f);
}

// ---- the cross-attention probe end to end, on a model built to match ----

constexpr int kShiftGrid = 8, kShiftSide = kPatch * kShiftGrid;  // 64 patches of 8 x 8 pixels
constexpr int kShift = 2;                                        // k: patches view 2 moves by
constexpr int kWallColumns = kShiftGrid + kShift;  // cells of the wall the two views see

// Sylvester's Hadamard matrix, [n, n] for n a power of 2: entries +-1, rows pairwise orthogonal
// (h_a . h_b = n for a == b, else 0), and every row but the first sums to 0.
torch::Tensor hadamard(int n) {
  std::vector<float> h(static_cast<size_t>(n) * n);
  for (int a = 0; a < n; ++a)
    for (int b = 0; b < n; ++b) h[a * n + b] = __builtin_popcount(a & b) % 2 ? -1.f : 1.f;
  return torch::tensor(h).view({n, n});
}

// M pairs of views of a wall, view 2's camera moved right so that view 1's patch (r, c) lies at
// view 2's (r, c - k) (unseen for c < k), with blank images: one scene, so no foreign reference.
MechanismPairs wallPairs(int64_t M) {
  const int N = kShiftGrid * kShiftGrid;
  const WallView a = wallView(0, 2.0f, kShiftSide);
  const WallView b = wallView(shiftOf(kShift, 2.0, kShiftSide), 2.0f, kShiftSide);
  const PatchCorrespondence truth =
      truePatchCorrespondence(a.camera, a.depth, b.camera, b.depth, kPatch);
  MechanismPairs p;
  p.img1 = torch::zeros({M, 3, kShiftSide, kShiftSide});
  p.img2 = torch::zeros({M, 3, kShiftSide, kShiftSide});
  p.truth.assign(M, truth);
  p.covis.assign(M, 0.75);
  p.scene.assign(M, "wall");
  const auto seen = torch::tensor(std::vector<float>(truth.seen.begin(), truth.seen.end()));
  p.seen = seen.expand({M, -1}).contiguous();
  p.valid = torch::ones({M, N});
  p.mask = torch::zeros({M, N}, torch::kBool);
  return p;
}

// Wall pairs whose images show what the views see: the wall has G x (G + k) cells, view 1's
// patch (r, c) shows cell (r, c) and view 2's shows cell (r, c + k). A cell is one lit pixel (1,
// the rest of its patch 0) at its own slot of the patch's 3 p p values: cell (r, w) at slot
// w G + perm_w(r), perm_w a random order of wall column w's cells in each pair, so that the slot
// tells the column.
MechanismPairs shiftedWallPairs(int64_t M, uint64_t seed) {
  const int G = kShiftGrid, pp = kPatch * kPatch;
  std::mt19937 rng(seed);
  MechanismPairs p = wallPairs(M);
  for (int64_t m = 0; m < M; ++m)
    for (int w = 0; w < kWallColumns; ++w) {
      std::vector<int> perm(G);
      std::iota(perm.begin(), perm.end(), 0);
      std::shuffle(perm.begin(), perm.end(), rng);
      for (int r = 0; r < G; ++r) {
        const int slot = w * G + perm[r];
        const int64_t ch = slot / pp, y = r * kPatch + slot % pp / kPatch, x = slot % kPatch;
        if (w < G) p.img1[m][ch][y][w * kPatch + x] = 1.f;
        if (w >= kShift) p.img2[m][ch][y][(w - kShift) * kPatch + x] = 1.f;
      }
    }
  return p;
}

CroCoConfig shiftConfig() {
  CroCoConfig c = presetConfig("tiny");  // 192 wide encoder, 128 wide decoder of 2 blocks
  c.img_size = kShiftSide;
  c.patch_size = kPatch;
  c.validate();
  return c;
}

void zeroLinear(torch::nn::Linear& l) {
  l->weight.zero_();
  l->bias.zero_();
}

void identityLinear(torch::nn::Linear& l) {
  l->weight.copy_(torch::eye(l->weight.size(0), l->weight.size(1)));
  l->bias.zero_();
}

// A model whose cross-attention matches patches by content. Every residual branch (attention,
// cross-attention output, MLP) writes zeros and the position embeddings are zero, so a patch's
// decoder token is its patch embedding through the layer norms. patch_embed maps slot s to
// code h_{s+1} of hadamard(128) (on the first 128 of 192 channels; zero-mean, so the norms only
// scale it), decoder_embed keeps those 128 channels, and projq and projk are identities: a
// query scores 128 / (H sqrt(Dh)) against the key of its own cell and 0 against the rest.
// projq's bias adds eps * (the key cell's wall column) to every score: it leaves the argmax of
// the right cost (S12 + S21^T: 2 x 128 against a bias of at most 2 eps (G + k)) alone, but makes
// a wrong one fail one way: S12 + S12^T, or S12 + S21 untransposed, scores view 1's patch (r, c)
// 128 at view 2's (r, c - k), the truth, and also at (r, c + k), its mirror, whose bias is
// larger by 2 k eps or 4 k eps.
CroCoNet contentMatcher(const CroCoConfig& c) {
  constexpr double kEps = 4.0;
  torch::manual_seed(0);
  CroCoNet model(c);
  torch::NoGradGuard ng;
  const int Dd = c.dec_embed_dim, G = c.gridSize();
  const auto h = hadamard(Dd);  // [Dd, Dd]
  for (auto& m : *model->enc_blocks) {
    auto& blk = *m->as<BlockImpl>();
    zeroLinear(blk.attn->proj);
    zeroLinear(blk.mlp->fc2);
  }
  auto bias = torch::zeros({Dd});  // bias . h_{s+1} = eps * (slot s's wall column)
  for (int s = 0; s < G * kWallColumns; ++s) bias += kEps * (s / G) * h[s + 1] / Dd;
  for (auto& m : *model->dec_blocks) {
    auto& blk = *m->as<DecoderBlockImpl>();
    zeroLinear(blk.attn->proj);
    zeroLinear(blk.mlp->fc2);
    zeroLinear(blk.cross_attn->proj);
    identityLinear(blk.cross_attn->projq);
    blk.cross_attn->projq->bias.copy_(bias);
    identityLinear(blk.cross_attn->projk);
  }
  model->enc_pos_embed.zero_();
  model->dec_pos_embed.zero_();
  auto& embed = model->patch_embed->proj;
  embed->weight.zero_();
  embed->bias.zero_();
  const auto slots = embed->weight.view({c.enc_embed_dim, -1});  // [D, 3 p p]
  for (int s = 0; s < G * kWallColumns; ++s) slots.select(1, s).slice(0, 0, Dd).copy_(h[s + 1]);
  identityLinear(model->decoder_embed);
  return model;
}

TEST(MechanismProbes, CrossAttentionOfAModelBuiltToMatchScoresPerfectly) {
  const CroCoConfig c = shiftConfig();
  CroCoNet model = contentMatcher(c);
  const MechanismPairs pairs = shiftedWallPairs(4, 1);
  ASSERT_EQ(pairs.truth[0].seenCount(), (kShiftGrid - kShift) * kShiftGrid);
  // One direction alone already finds every cell; the probe's reciprocal cost must keep that.
  torch::NoGradGuard ng;
  torch::Tensor s12;
  model->forward(pairs.img1, pairs.img2, pairs.mask, &s12);
  for (int64_t m = 0; m < pairs.size(); ++m) {
    MatchTally one;
    one.add(argmaxMatches(s12[m]), pairs.truth[m]);
    ASSERT_DOUBLE_EQ(one.pck1(), 1.0) << m;
  }
  const nlohmann::json probes = mechanismProbes(model, pairs, "croco");
  EXPECT_DOUBLE_EQ(probes["xattn_pck1"].get<double>(), 1.0);
  EXPECT_NEAR(probes["xattn_epe"].get<double>(), 0.0, 1e-4);  // the truth is float projections
  EXPECT_DOUBLE_EQ(probes["enc_pck1"].get<double>(), 1.0);    // the codes are the features
  EXPECT_TRUE(std::isnan(probes["ref_gain"].get<double>()));  // one scene
  const std::vector<MatchTally> tallies = crossAttentionMatches(model, pairs, 3);
  ASSERT_EQ(tallies.size(), 4u);
  for (const MatchTally& t : tallies) EXPECT_EQ(t.hits, (kShiftGrid - kShift) * kShiftGrid);
}

// What matching every seen view-1 patch to a view-2 patch drawn uniformly at random, each
// independently, scores: the expected hits (PCK@1: within one patch unit of the truth) and
// their variance (a Poisson binomial), and the expected end-point error, the mean over the
// patches, with its variance.
struct Chance {
  int64_t patches = 0;
  double hits = 0, hitsVariance = 0;
  double epe = 0, epeVariance = 0;
};
Chance chanceOf(const std::vector<PatchCorrespondence>& truths) {
  Chance out;
  for (const PatchCorrespondence& t : truths) {
    const int G = t.grid, N = G * G;
    for (int i = 0; i < N; ++i) {
      if (!t.seen[i]) continue;
      double near = 0, sum = 0, squares = 0;
      for (int j = 0; j < N; ++j) {
        const double e = std::hypot(j % G + 0.5 - t.x[i], j / G + 0.5 - t.y[i]);
        near += e <= 1.0;
        sum += e;
        squares += e * e;
      }
      const double p = near / N, mean = sum / N;
      ++out.patches;
      out.hits += p;
      out.hitsVariance += p * (1 - p);
      out.epe += mean;
      out.epeVariance += squares / N - mean * mean;
    }
  }
  out.epe /= out.patches;
  out.epeVariance /= static_cast<double>(out.patches) * out.patches;
  return out;
}

TEST(MechanismProbes, CrossAttentionOfRandomWeightsScoresTheChanceRate) {
  // Random weights without position embeddings: the network is then equivariant under any
  // reordering of either view's patches, so on images of independent random values each view-1
  // patch's match is uniform over view 2's patches, whatever the truth. The matches of one
  // pair's patches share view 2, so they are not quite independent; over model seeds 0-29 the
  // hits spread as the binomial's (standard deviation 7.1 against 7.1).
  const CroCoConfig c = shiftConfig();
  MechanismPairs pairs = wallPairs(16);
  torch::manual_seed(2);
  pairs.img1.normal_();
  pairs.img2.normal_();
  const Chance chance = chanceOf(pairs.truth);
  ASSERT_EQ(chance.patches, 16 * (kShiftGrid - kShift) * kShiftGrid);
  for (uint64_t seed : {3, 4, 5}) {
    torch::manual_seed(seed);
    CroCoNet scrambled(c);
    scrambled->enc_pos_embed.zero_();
    scrambled->dec_pos_embed.zero_();
    const nlohmann::json probes = mechanismProbes(scrambled, pairs, "croco");
    const double hits = probes["xattn_pck1"].get<double>() * chance.patches;
    // Within 4 standard deviations (a two-sided chance of 6e-5 each).
    EXPECT_NEAR(hits, chance.hits, 4 * std::sqrt(chance.hitsVariance)) << seed;
    EXPECT_NEAR(probes["xattn_epe"].get<double>(), chance.epe, 4 * std::sqrt(chance.epeVariance))
        << seed;
  }
}

TEST(CroCoNet, CrossScoresAreQueriesTimesKeysOverTheRootOfTheHeadWidth) {
  CroCoConfig c = tinyConfig();
  c.dec_depth = 1;
  ASSERT_FALSE(c.rope());
  torch::manual_seed(6);
  CroCoNet model(c);
  model->eval();
  torch::NoGradGuard ng;
  const auto a = torch::randn({2, 3, kSide, kSide}), b = torch::randn({2, 3, kSide, kSide});
  torch::Tensor scores;
  model->forward(a, b, torch::zeros({2, c.numPatches()}, torch::kBool), &scores);
  // The one decoder block's queries and keys, by hand: image 1's tokens after self-attention,
  // image 2's as they enter; the scores averaged over the heads.
  auto tokens = [&](const torch::Tensor& img) {
    return torch::linear(model->encode(img, torch::Tensor()), model->decoder_embed->weight,
                         model->decoder_embed->bias) +
           model->dec_pos_embed;
  };
  auto& blk = *model->dec_blocks->ptr<DecoderBlockImpl>(0);
  auto x = tokens(a);
  x = x + blk.attn(blk.norm1(x), torch::Tensor());
  const int64_t H = c.dec_num_heads, Dh = c.dec_embed_dim / H, N = c.numPatches();
  const auto q = blk.cross_attn->projq(blk.norm2(x)).view({2, N, H, Dh}).transpose(1, 2);
  const auto y = blk.norm_y ? blk.norm_y(tokens(b)) : tokens(b);
  const auto k = blk.cross_attn->projk(y).view({2, N, H, Dh}).transpose(1, 2);
  const auto expected = (torch::matmul(q, k.transpose(-2, -1)) / std::sqrt(double(Dh))).mean(1);
  EXPECT_TRUE(torch::allclose(scores, expected, 1e-4, 1e-5))
      << (scores - expected).abs().max().item<float>();
}

TEST(CroCoNet, CrossScoresAreItsCrossAttentionBeforeTheSoftmax) {
  const CroCoConfig c = tinyConfig();
  torch::manual_seed(4);
  CroCoNet model(c);
  model->eval();
  torch::NoGradGuard ng;
  const auto a = torch::randn({2, 3, kSide, kSide}), b = torch::randn({2, 3, kSide, kSide});
  const auto none = torch::zeros({2, c.numPatches()}, torch::kBool);
  torch::Tensor scores;
  const CroCoOutput withScores = model->forward(a, b, none, &scores);
  EXPECT_EQ(scores.sizes(), (std::vector<int64_t>{2, c.numPatches(), c.numPatches()}));
  EXPECT_TRUE(torch::equal(withScores.prediction, model->forward(a, b, none).prediction));
  // Asking twice gives the same scores (nothing accumulates across calls).
  torch::Tensor again = scores;
  model->forward(a, b, none, &again);
  EXPECT_TRUE(torch::allclose(again, scores));
  EXPECT_ERROR_CONTAINS(model->forward(a, torch::Tensor(), none, &scores),
                        "cross-attention scores need the cross decoder and a second image");
}

}  // namespace
}  // namespace paircast
