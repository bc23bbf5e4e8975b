#include "sweep/mechanism_probe.h"

#include <ATen/CPUGeneratorImpl.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <optional>

#include "dataset/generate_range.h"
#include "model/reconstruct.h"
#include "sweep/depth_probe.h"
#include "util/error.h"

namespace paircast {

namespace {

// Pairs of one scene, in index order: indices are tried in parallel rounds of `want` until
// `want` pairs are found or 8 * want indices were tried.
std::vector<PairSample> scenePairs(const PairGenerator& gen, uint64_t seed, int want, int threads) {
  std::vector<PairSample> got;
  for (int first = 0; static_cast<int>(got.size()) < want && first < 8 * want; first += want) {
    std::vector<std::optional<PairSample>> round = generateRange(
        [&gen](uint64_t) -> const PairGenerator& { return gen; }, seed, first, want, threads);
    for (auto& s : round)
      if (s && static_cast<int>(got.size()) < want) got.push_back(std::move(*s));
  }
  return got;
}

// 255 where a depth map has depth (finite and > 0), [H, W, 1].
Image8 depthMask(const ImageF& depth) {
  Image8 m(depth.width, depth.height, 1, 0);
  for (size_t i = 0; i < depth.data.size(); ++i)
    m.data[i] = std::isfinite(depth.data[i]) && depth.data[i] > 0 ? 255 : 0;
  return m;
}

torch::Tensor floatTensor(const std::vector<float>& v) {
  return torch::from_blob(const_cast<float*>(v.data()), {static_cast<int64_t>(v.size())},
                          torch::kFloat32)
      .clone();
}

// The batches [i, j) of M pairs.
template <typename F>
void inBatches(int64_t M, int batch, F&& f) {
  for (int64_t i = 0; i < M; i += batch) f(i, std::min<int64_t>(i + batch, M));
}

// Sum of the losses over the masked patches of `select` [B, N] bool.
double maskedSum(const torch::Tensor& losses, const torch::Tensor& select) {
  return losses.masked_select(select).sum().item<double>();
}

}  // namespace

std::vector<int64_t> otherSceneReferences(const std::vector<std::string>& scenes) {
  std::vector<std::string> order;  // scenes by first appearance
  std::map<std::string, std::vector<int64_t>> pairsOf;
  for (size_t i = 0; i < scenes.size(); ++i) {
    if (!pairsOf.count(scenes[i])) order.push_back(scenes[i]);
    pairsOf[scenes[i]].push_back(static_cast<int64_t>(i));
  }
  if (order.size() < 2) return {};
  std::map<std::string, std::string> next;
  for (size_t s = 0; s < order.size(); ++s) next[order[s]] = order[(s + 1) % order.size()];
  std::map<std::string, int64_t> rank;  // of a pair within its scene
  std::vector<int64_t> other(scenes.size());
  for (size_t i = 0; i < scenes.size(); ++i) {
    const auto& candidates = pairsOf.at(next.at(scenes[i]));
    other[i] = candidates[rank[scenes[i]]++ % candidates.size()];
  }
  return other;
}

PairOptions mechanismPairOptions(const MechanismPairOptions& o) {
  PairOptions p;
  p.resolution = o.size;
  p.minCovis = o.minCovis;
  p.maxCovis = o.maxCovis;
  p.keepDepth = true;
  p.covisMasks = true;
  return p;
}

MechanismPairs makeMechanismPairs(const std::vector<const PairGenerator*>& generators,
                                  const std::vector<std::string>& names,
                                  const MechanismPairOptions& o) {
  PAIRCAST_CHECK(generators.size() == names.size() && o.size % o.patch == 0);
  MechanismPairs m;
  std::vector<torch::Tensor> a, b, seen, valid;
  for (size_t s = 0; s < generators.size(); ++s) {
    const PairOptions& po = generators[s]->options();
    PAIRCAST_CHECK(po.resolution == o.size && po.covisMasks && po.keepDepth);
    const std::vector<PairSample> got =
        scenePairs(*generators[s], o.seed, o.pairsPerScene, o.threads);
    if (got.empty())
      throw Error(names[s], "no held-out pair with covis in [" + std::to_string(o.minCovis) + ", " +
                                std::to_string(o.maxCovis) + "] for the mechanism probes");
    for (const PairSample& p : got) {
      a.push_back(imageTensor(p.rgb[0], o.size));
      b.push_back(imageTensor(p.rgb[1], o.size));
      seen.push_back(floatTensor(patchShare(p.covisMask[0], o.patch)).unsqueeze(0));
      valid.push_back(floatTensor(patchShare(depthMask(p.depth[0]), o.patch)).unsqueeze(0));
      m.truth.push_back(truePatchCorrespondence(p.camera[0], p.depth[0], p.camera[1], p.depth[1],
                                                o.patch, po.covis));
      m.covis.push_back(p.covis[1].covis);
      m.scene.push_back(names[s]);
    }
  }
  m.img1 = torch::cat(a);
  m.img2 = torch::cat(b);
  m.seen = torch::cat(seen);
  m.valid = torch::cat(valid);
  const int64_t N = m.seen.size(1);
  auto gen = at::make_generator<at::CPUGeneratorImpl>(o.seed + 11);
  m.mask = torch::argsort(torch::rand({m.size(), N}, gen), 1, false) < o.maskedPatches;
  m.other = otherSceneReferences(m.scene);
  return m;
}

ReferenceUse referenceUse(CroCoNet& model, const MechanismPairs& pairs, int batch) {
  ReferenceUse r;
  if (pairs.other.empty()) return r;  // one scene: no foreign reference
  torch::NoGradGuard ng;
  model->eval();
  const auto other = torch::tensor(pairs.other, torch::kInt64);
  double trueSum[3] = {0, 0, 0}, otherSum[3] = {0, 0, 0};  // all, covisible, hidden
  inBatches(pairs.size(), batch, [&](int64_t i, int64_t j) {
    const auto img1 = pairs.img1.slice(0, i, j), mask = pairs.mask.slice(0, i, j);
    const auto seen = pairs.seen.slice(0, i, j), valid = pairs.valid.slice(0, i, j);
    const torch::Tensor select[3] = {mask, mask & (seen >= 0.5),
                                     mask & (seen == 0) & (valid >= 0.5)};
    auto losses = [&](const torch::Tensor& img2) {
      const CroCoOutput out = model->forward(img1, img2, mask);
      return patchLosses(out.prediction.to(torch::kFloat32), out.target);  // [B, N]
    };
    const auto lt = losses(pairs.img2.slice(0, i, j));
    const auto lo = losses(pairs.img2.index_select(0, other.slice(0, i, j)));
    for (int k = 0; k < 3; ++k) {
      trueSum[k] += maskedSum(lt, select[k]);
      otherSum[k] += maskedSum(lo, select[k]);
    }
  });
  auto gain = [&](int k) { return otherSum[k] > 0 ? 1.0 - trueSum[k] / otherSum[k] : NAN; };
  r.gain = gain(0);
  r.covisible = gain(1);
  r.hidden = gain(2);
  return r;
}

std::vector<int64_t> argmaxMatches(const torch::Tensor& cost) {
  const auto idx = cost.argmax(1).to(torch::kInt64).contiguous();
  return std::vector<int64_t>(idx.data_ptr<int64_t>(), idx.data_ptr<int64_t>() + idx.numel());
}

torch::Tensor reciprocalCost(const torch::Tensor& s12, const torch::Tensor& s21) {
  return s12.to(torch::kFloat32) + s21.to(torch::kFloat32).transpose(1, 2);
}

namespace {

// Scores a batch of cost volumes [B, N1, N2] of pairs i, i + 1, ...
void tallyCosts(const torch::Tensor& cost, const MechanismPairs& pairs, int64_t i,
                std::vector<MatchTally>& out) {
  for (int64_t k = 0; k < cost.size(0); ++k)
    out[i + k].add(argmaxMatches(cost[k]), pairs.truth[i + k]);
}

}  // namespace

std::vector<MatchTally> crossAttentionMatches(CroCoNet& model, const MechanismPairs& pairs,
                                              int batch) {
  torch::NoGradGuard ng;
  model->eval();
  std::vector<MatchTally> out(pairs.size());
  inBatches(pairs.size(), batch, [&](int64_t i, int64_t j) {
    const auto img1 = pairs.img1.slice(0, i, j), img2 = pairs.img2.slice(0, i, j);
    const auto none = torch::zeros({j - i, pairs.mask.size(1)}, torch::kBool);  // view 1 whole
    torch::Tensor s12, s21;                                                     // [B, N, N]
    model->forward(img1, img2, none, &s12);
    model->forward(img2, img1, none, &s21);
    tallyCosts(reciprocalCost(s12, s21), pairs, i, out);
  });
  return out;
}

std::vector<MatchTally> encoderMatches(CroCoNet& model, const MechanismPairs& pairs, int batch) {
  namespace F = torch::nn::functional;
  std::vector<MatchTally> out(pairs.size());
  const auto unit = F::NormalizeFuncOptions().dim(2);
  const auto f1 = F::normalize(encoderFeatures(model, pairs.img1, batch), unit);  // [M, N, D]
  const auto f2 = F::normalize(encoderFeatures(model, pairs.img2, batch), unit);
  inBatches(pairs.size(), batch, [&](int64_t i, int64_t j) {
    tallyCosts(torch::matmul(f1.slice(0, i, j), f2.slice(0, i, j).transpose(1, 2)), pairs, i, out);
  });
  return out;
}

namespace {

MatchTally sum(const std::vector<MatchTally>& tallies, const std::vector<size_t>& which) {
  MatchTally t;
  for (size_t i : which) t.add(tallies[i]);
  return t;
}

// Per covis bin of 0.1 that has pairs: its pairs and the correspondence figures.
nlohmann::json byCovis(const MechanismPairs& pairs, const std::vector<MatchTally>& xattn,
                       const std::vector<MatchTally>& enc) {
  std::map<int, std::vector<size_t>> bins;
  for (size_t i = 0; i < pairs.covis.size(); ++i)
    bins[std::clamp(static_cast<int>(std::floor(pairs.covis[i] * 10 + 1e-9)), 0, 9)].push_back(i);
  nlohmann::json out = nlohmann::json::array();
  for (const auto& [bin, which] : bins) {
    nlohmann::json row = {{"covis_lo", bin / 10.0},
                          {"covis_hi", (bin + 1) / 10.0},
                          {"pairs", which.size()},
                          {"enc_pck1", sum(enc, which).pck1()}};
    const MatchTally x = xattn.empty() ? MatchTally() : sum(xattn, which);
    row["xattn_pck1"] = x.pck1();
    row["xattn_epe"] = x.epe();
    out.push_back(row);
  }
  return out;
}

}  // namespace

nlohmann::json mechanismProbes(CroCoNet& model, const MechanismPairs& pairs,
                               const std::string& task) {
  std::vector<size_t> all(pairs.size());
  for (size_t i = 0; i < all.size(); ++i) all[i] = i;
  const std::vector<MatchTally> enc = encoderMatches(model, pairs);
  std::vector<MatchTally> xattn;
  ReferenceUse ref;
  if (task != "mae") {
    ref = referenceUse(model, pairs);
    if (model->config().decoder == "cross") xattn = crossAttentionMatches(model, pairs);
  }
  const MatchTally x = xattn.empty() ? MatchTally() : sum(xattn, all);
  return {{"ref_gain", ref.gain},
          {"ref_gain_covisible", ref.covisible},
          {"ref_gain_hidden", ref.hidden},
          {"xattn_pck1", x.pck1()},
          {"xattn_epe", x.epe()},
          {"enc_pck1", sum(enc, all).pck1()},
          {"probe_by_covis", byCovis(pairs, xattn, enc)}};
}

}  // namespace paircast
