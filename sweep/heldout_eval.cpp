#include "sweep/heldout_eval.h"

#include <ATen/CPUGeneratorImpl.h>

#include <cmath>
#include <cstdio>
#include <filesystem>

#include "dataset/generate_job.h"
#include "dataset/pair_generator.h"
#include "model/autocast.h"
#include "model/reconstruct.h"
#include "sweep/sweep_scene.h"
#include "trainer/pair_dataset.h"
#include "trainer/trainer.h"
#include "util/error.h"
#include "util/random.h"

namespace paircast {
namespace fs = std::filesystem;

namespace {

// Held-out views for the depth probe: a reference view each, with RGB and depth at the
// model's input size.
ProbeData probeViews(const SweepConfig& c, const std::vector<std::unique_ptr<SweepScene>>& scenes,
                     int first, int count) {
  std::vector<torch::Tensor> imgs, depths;
  const Camera intr = Camera::fromHfov(c.imgSize, c.imgSize, 60.0);
  RenderOptions ro;
  ro.normals = false;
  ro.ids = false;
  for (int i = first; i < first + count; ++i) {
    const auto& s = *scenes[i % scenes.size()];
    Rng rng(mixSeed(c.seed, "probe/" + s.name, static_cast<uint64_t>(i)));
    Frame f;
    bool ok = false;
    for (int attempt = 0; attempt < 50 && !ok; ++attempt) {
      const Viewpoint v = s.sampler->sampleReference(intr, rng);
      s.caster->render(v.camera, ro, f);
      ok = f.validFraction() >= 0.7;
    }
    if (!ok) throw Error(s.path, "no held-out view with 70 % valid depth for the depth probe");
    imgs.push_back(imageTensor(f.rgb, c.imgSize));
    depths.push_back(torch::from_blob(f.depth.data.data(), {c.imgSize, c.imgSize}, torch::kFloat32)
                         .clone()
                         .unsqueeze(0));
  }
  return {torch::cat(imgs), torch::cat(depths)};
}

// The held-out pairs at covis ~0.5, generated once into heldout/xv; returns that folder.
std::string generateHeldOutPairs(const SweepConfig& c, const std::vector<std::string>& heldout) {
  const fs::path out(c.out);
  GenerateConfig g;
  g.scenes = heldout;
  g.out = (out / "heldout" / "xv").string();
  g.pairsPerScene =
      (c.evalPairs + static_cast<int>(heldout.size()) - 1) / static_cast<int>(heldout.size());
  g.seed = c.seed + 1;
  g.jobs = c.jobs;
  g.load = c.load;
  g.pair.resolution = c.resolution;
  g.pair.minCovis = 0.45;
  g.pair.maxCovis = 0.55;
  g.shardSize = 100000;
  g.progress = false;
  if (!fs::exists(out / "heldout" / "xv" / "summary.json")) runGenerate(g);
  return g.out;
}

// The mechanism probes' pairs, from every held-out scene, at the model's input size.
MechanismPairs mechanismPairs(const SweepConfig& c, const CroCoConfig& mc,
                              const std::vector<std::unique_ptr<SweepScene>>& scenes) {
  MechanismPairOptions o;
  o.pairsPerScene = c.mechanismPairs;
  o.minCovis = c.mechanismMinCovis;
  o.maxCovis = c.mechanismMaxCovis;
  o.size = mc.img_size;
  o.patch = mc.patch_size;
  o.maskedPatches = mc.numMasked();
  o.seed = c.seed + 3;
  o.threads = sweepThreads(c);
  const PairOptions po = mechanismPairOptions(o);
  std::vector<std::unique_ptr<PairGenerator>> gens;
  std::vector<const PairGenerator*> view;
  std::vector<std::string> names;
  for (const auto& s : scenes) {
    gens.push_back(std::make_unique<PairGenerator>(*s->scene, *s->caster, *s->sampler, po));
    view.push_back(gens.back().get());
    names.push_back(s->name);
  }
  MechanismPairs m = makeMechanismPairs(view, names, o);
  if (m.other.empty())
    std::fprintf(stderr,
                 "covis_sweep: warning: the held-out pairs come from one scene, so there is no "
                 "reference from another scene: ref_gain needs at least two held-out scenes\n");
  return m;
}

}  // namespace

HeldOut loadHeldOut(const SweepConfig& c, const CroCoConfig& mc,
                    const std::vector<std::string>& heldout) {
  const std::string xvDir = generateHeldOutPairs(c, heldout);
  HeldOut h;
  {
    const PairDataset xv = PairDataset::fromShards({xvDir + "/pairs-*.tar"});
    std::vector<torch::Tensor> a, b;
    for (size_t i = 0; i < xv.size() && static_cast<int>(i) < c.evalPairs; ++i) {
      auto [x, y] = xv.load(i);
      a.push_back(imageTensor(x, c.imgSize));
      b.push_back(imageTensor(y, c.imgSize));
    }
    h.img1 = torch::cat(a);
    h.img2 = torch::cat(b);
  }
  auto gen = at::make_generator<at::CPUGeneratorImpl>(c.seed + 7);
  h.mask = torch::argsort(torch::rand({h.img1.size(0), mc.numPatches()}, gen), 1, false) <
           mc.numMasked();
  auto heldScenes = loadSweepScenes(heldout, c.load, SamplerOptions(), "held-out");
  const int half = c.probeViews / 2;
  h.probeA = probeViews(c, heldScenes, 0, half);
  h.probeB = probeViews(c, heldScenes, half, c.probeViews - half);
  h.mechanism = mechanismPairs(c, mc, heldScenes);
  h.probeSettings = {{"version", 1},
                     {"pairs_per_scene", c.mechanismPairs},
                     {"covis", {c.mechanismMinCovis, c.mechanismMaxCovis}}};
  // On the CPU, where fp16 has no autocast: a sweep trained in fp16 on CUDA evaluates at auto.
  h.precision = resolvePrecision(c.amp == "fp16" ? "auto" : c.amp, at::kCPU, "covis_sweep");
  // Figures computed in float32 stay valid for float32; bf16 ones are others.
  if (h.precision.autocast()) h.probeSettings["precision"] = h.precision.ran;
  return h;
}

nlohmann::json constantDepthBaseline(const HeldOut& h) {
  auto meanDepth = [](const torch::Tensor& d) {
    return std::exp(torch::log(d.masked_select(d > 0)).mean().item<double>());
  };
  const DepthMetrics m =
      depthMetrics(torch::cat({torch::full_like(h.probeB.depth, meanDepth(h.probeA.depth)),
                               torch::full_like(h.probeA.depth, meanDepth(h.probeB.depth))}),
                   torch::cat({h.probeB.depth, h.probeA.depth}));
  return {{"probe_delta1", m.delta1}, {"probe_absrel", m.absRel}, {"probe_rmse", m.rmse}};
}

nlohmann::json evaluate(CroCoNet& model, const HeldOut& h, const std::string& task) {
  torch::NoGradGuard ng;
  const AutocastGuard autocast(h.precision);
  model->eval();
  double lossSum = 0;
  int64_t n = 0;
  for (int64_t i = 0; i < h.img1.size(0); i += 16) {
    const int64_t j = std::min<int64_t>(i + 16, h.img1.size(0));
    auto out = pretrainForward(model, task, h.img1.slice(0, i, j), h.img2.slice(0, i, j),
                               h.mask.slice(0, i, j));
    lossSum += maskedMse(out.prediction.to(torch::kFloat32), out.mask, out.target).item<double>() *
               (j - i);
    n += j - i;
  }
  const DepthMetrics m = crossFitProbe(model, h.probeA, h.probeB);
  nlohmann::json ev = {{"xv_loss", lossSum / n},
                       {"probe_delta1", m.delta1},
                       {"probe_absrel", m.absRel},
                       {"probe_rmse", m.rmse}};
  ev.update(mechanismProbes(model, h.mechanism, task));
  ev["probe_settings"] = h.probeSettings;
  return ev;
}

bool evaluatedWith(const nlohmann::json& ev, const HeldOut& h) {
  return ev.is_object() && ev.value("probe_settings", nlohmann::json()) == h.probeSettings;
}

}  // namespace paircast
