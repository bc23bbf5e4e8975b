#include "sweep/covis_sweep.h"

#include <ATen/CPUGeneratorImpl.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <thread>

#include "dataset/dataset_report.h"
#include "dataset/generate_job.h"
#include "dataset/pair_generator.h"
#include "dataset/shard.h"
#include "dataset/viewpoint_sampler.h"
#include "model/checkpoint.h"
#include "model/croco_net.h"
#include "model/reconstruct.h"
#include "render/ray_caster.h"
#include "render/scene_loader.h"
#include "sweep/depth_probe.h"
#include "sweep/sweep_report.h"
#include "sweep/sweep_stats.h"
#include "trainer/distributed.h"
#include "trainer/pair_dataset.h"
#include "trainer/trainer.h"
#include "util/atomic_file.h"
#include "util/error.h"
#include "util/random.h"
#include "util/timer.h"

namespace paircast {
namespace fs = std::filesystem;

int covisBucket(double covis) {
  return std::clamp(static_cast<int>(std::floor(covis * kCovisBuckets + 1e-9)), 0,
                    kCovisBuckets - 1);
}

std::string centerName(double c) {
  char b[32];
  std::snprintf(b, sizeof b, "%.2f", c);
  return b;
}

namespace {

// k if x is k * 0.05 (within 1e-6), else -1.
int gridIndex(double x) {
  const double k = x * kCovisBuckets;
  return std::abs(k - std::round(k)) < 1e-6 ? static_cast<int>(std::round(k)) : -1;
}

nlohmann::json readJson(const std::string& path) {
  if (!fs::exists(path)) return nullptr;
  try {
    return nlohmann::json::parse(readFile(path));
  } catch (const nlohmann::json::exception& e) {
    throw Error(path,
                std::string("unreadable state file (delete it to redo this stage): ") + e.what());
  }
}

void say(const SweepConfig& c, const std::string& line) {
  if (c.progress) std::fprintf(stderr, "[covis_sweep] %s\n", line.c_str());
}

// A training scene, loaded once.
struct PoolScene {
  std::string path, name;
  std::unique_ptr<Scene> scene;
  std::unique_ptr<RayCaster> caster;
  std::unique_ptr<ViewpointSampler> sampler;
};

std::vector<std::unique_ptr<PoolScene>> loadScenes(const std::vector<std::string>& files,
                                                   const LoadOptions& load,
                                                   const SamplerOptions& so, const char* role) {
  std::vector<std::unique_ptr<PoolScene>> out;
  const std::vector<std::string> names = uniqueSceneNames(files);
  for (size_t i = 0; i < files.size(); ++i) {
    auto s = std::make_unique<PoolScene>();
    s->path = files[i];
    s->name = names[i];
    try {
      s->scene = std::make_unique<Scene>(loadScene(files[i], load));
      s->scene->name = s->name;
      s->caster = std::make_unique<RayCaster>(s->scene->mesh);
      s->sampler = std::make_unique<ViewpointSampler>(*s->scene, *s->caster, so);
    } catch (const Error& e) {
      std::fprintf(stderr, "covis_sweep: warning: %s scene skipped: %s\n", role, e.what());
      continue;
    }
    out.push_back(std::move(s));
  }
  if (out.empty()) throw Error(std::string("no usable ") + role + " scene");
  return out;
}

// The pool: pairs from the training scenes, bucketed by covis, kept in pool/pool-RRRRRR.tar
// (one shard per sampling round) and pool/pool.json (the pairs of the completed rounds).
struct Pool {
  std::vector<std::string> keys;
  std::vector<double> covis;
};

// What pool.json holds: the pool so far, and where its sampling goes on.
struct PoolProgress {
  Pool pool;
  uint64_t nextIndex = 0;  // of the next pair to sample
  int rounds = 0;
  std::vector<int> have = std::vector<int>(kCovisBuckets, 0);  // pairs per bucket

  void add(const std::string& key, double covis) {
    pool.keys.push_back(key);
    pool.covis.push_back(covis);
    have[covisBucket(pool.covis.back())]++;
  }
  // Pairs still needed per bucket.
  std::vector<int> deficit(const std::vector<int>& demand) const {
    std::vector<int> d(kCovisBuckets);
    for (int b = 0; b < kCovisBuckets; ++b) d[b] = std::max(0, demand[b] - have[b]);
    return d;
  }
};

int total(const std::vector<int>& counts) {
  int n = 0;
  for (int v : counts) n += v;
  return n;
}

// The settings a pool was sampled with: a pool.json of other settings is not resumed.
nlohmann::json poolSettings(const SweepConfig& c, const std::vector<std::string>& sceneFiles,
                            const std::vector<int>& demand) {
  nlohmann::json settings = {{"scenes", sceneFiles},
                             {"seed", c.seed},
                             {"resolution", c.resolution},
                             {"demand", demand},
                             {"min_walk_scale", c.minWalkScale}};
  // Only a non-default axis is named, so that pools sampled before --up existed still resume.
  if (c.load.up != UpAxis::Y) settings["up"] = c.load.up == UpAxis::Z ? "z" : "auto";
  return settings;
}

// pool.json's progress; none (an empty pool) when there is no such file.
PoolProgress readPoolProgress(const std::string& statePath, const nlohmann::json& settings) {
  PoolProgress p;
  if (const nlohmann::json state = readJson(statePath); state.is_object()) {
    if (state.value("settings", nlohmann::json()) != settings)
      throw Error(statePath,
                  "was sampled with other settings (scenes, seed, resolution or set sizes); use "
                  "another --out or delete the pool folder");
    for (const auto& pair : state.at("pairs"))
      p.add(pair.at("key").get<std::string>(), pair.at("covis").get<double>());
    p.nextIndex = state.at("next_index").get<uint64_t>();
    p.rounds = state.at("rounds").get<int>();
  }
  return p;
}

void writePoolProgress(const std::string& statePath, const nlohmann::json& settings,
                       const PoolProgress& p) {
  nlohmann::json pairs = nlohmann::json::array();
  for (size_t i = 0; i < p.pool.keys.size(); ++i)
    pairs.push_back({{"key", p.pool.keys[i]}, {"covis", p.pool.covis[i]}});
  writeFileAtomic(statePath, nlohmann::json({{"settings", settings},
                                             {"pairs", pairs},
                                             {"next_index", p.nextIndex},
                                             {"rounds", p.rounds}})
                                     .dump() +
                                 "\n");
}

// One sampling round: pairs nextIndex .. nextIndex + m - 1, each from the scenes in turn, of which
// those whose bucket still needs them (`need`) are kept, in index order, in pool-<round>.tar.
// Returns the kept pairs' keys and covis.
nlohmann::json samplePoolRound(const SweepConfig& c,
                               const std::vector<std::unique_ptr<PoolScene>>& scenes,
                               const SamplerOptions& so, const std::vector<int>& need, int m,
                               uint64_t nextIndex, int round, const fs::path& dir) {
  PairOptions po;
  po.resolution = c.resolution;
  po.keepDepth = false;
  po.sampler = so;
  po.maxReferences = 4;  // rare buckets: many cheap tries over more indices
  po.maxAttempts = 25;
  po.accept = [need](double v) { return need[covisBucket(v)] > 0; };
  std::vector<std::unique_ptr<PairGenerator>> gens;
  for (auto& s : scenes)
    gens.push_back(std::make_unique<PairGenerator>(*s->scene, *s->caster, *s->sampler, po));
  std::vector<std::optional<PairSample>> got(m);
  const int threads = c.jobs > 0 ? c.jobs : omp_get_num_procs();
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
  for (int i = 0; i < m; ++i) {
    const uint64_t idx = nextIndex + i;
    got[i] = gens[idx % gens.size()]->generate(c.seed, idx);
  }
  // Keep, in index order, the pairs whose bucket still needs them.
  char name[64];
  std::snprintf(name, sizeof name, "pool-%06d.tar", round);
  ShardWriter writer((dir / name).string());
  std::vector<int> left = need;
  nlohmann::json added = nlohmann::json::array();
  for (int i = 0; i < m; ++i) {
    if (!got[i]) continue;
    const int b = covisBucket(got[i]->covis[1].covis);
    if (left[b] <= 0) continue;
    --left[b];
    const EncodedPair enc = encodePair(*got[i], false, 90);
    writer.add(enc);
    added.push_back({{"key", enc.key}, {"covis", got[i]->covis[1].covis}});
  }
  if (!added.empty()) writer.close();  // an empty round leaves no shard
  return added;
}

// The buckets still short, with what they have of what they need: " [0.05,0.10): 3/16".
std::string shortBuckets(const PoolProgress& p, const std::vector<int>& demand) {
  const std::vector<int> after = p.deficit(demand);
  std::string shortList;
  for (int b = 0; b < kCovisBuckets; ++b)
    if (after[b] > 0)
      shortList += " [" + centerName(b * 0.05) + "," + centerName((b + 1) * 0.05) +
                   "): " + std::to_string(p.have[b]) + "/" + std::to_string(demand[b]);
  return shortList;
}

// Samples rounds until every bucket holds its demand, resuming from pool.json.
Pool buildPool(const SweepConfig& c, const std::vector<std::string>& sceneFiles,
               const std::vector<int>& demand) {
  const fs::path dir = fs::path(c.out) / "pool";
  makeDirs(dir.string());
  const std::string statePath = (dir / "pool.json").string();
  const nlohmann::json settings = poolSettings(c, sceneFiles, demand);
  PoolProgress p = readPoolProgress(statePath, settings);
  if (total(p.deficit(demand)) == 0) return p.pool;

  SamplerOptions so;
  so.minWalkScale = c.minWalkScale;
  auto scenes = loadScenes(sceneFiles, c.load, so, "training");
  const auto start = SteadyClock::now();
  int idle = 0;
  while (true) {
    const std::vector<int> need = p.deficit(demand);
    const int missing = total(need);
    if (missing == 0) break;
    const int m = std::max(8, missing + missing / 4);
    const nlohmann::json added =
        samplePoolRound(c, scenes, so, need, m, p.nextIndex, p.rounds, dir);
    p.nextIndex += m;
    ++p.rounds;
    for (const auto& a : added) p.add(a["key"], a["covis"]);
    writePoolProgress(statePath, settings, p);
    say(c, "pool round " + std::to_string(p.rounds) + ": " + std::to_string(p.pool.keys.size()) +
               " pairs, " + std::to_string(total(p.deficit(demand))) + " still needed (" +
               std::to_string(static_cast<int>(secondsSince(start))) + " s)");
    idle = added.empty() ? idle + 1 : 0;
    if (idle >= 3 || p.rounds >= 400)
      throw Error(statePath, "cannot fill the covis buckets:" + shortBuckets(p, demand) +
                                 " (the scenes rarely give such pairs; drop those centres or "
                                 "lower --pairs-per-set)");
  }
  return p.pool;
}

// Held-out views for the depth probe: a reference view each, with RGB and depth at the
// model's input size.
ProbeData probeViews(const SweepConfig& c, const std::vector<std::unique_ptr<PoolScene>>& scenes,
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

struct HeldOut {
  torch::Tensor img1, img2, mask;  // cross-view completion pairs at covis ~0.5
  ProbeData probeA, probeB;        // the depth probe's two halves (crossFitProbe)
};

// A model's held-out figures: its completion loss on its own task (with the reference view for
// "croco", without for "mae") over the held-out pairs and their fixed masks, and the depth probe.
nlohmann::json evaluate(CroCoNet& model, const HeldOut& h, const std::string& task) {
  torch::NoGradGuard ng;
  model->eval();
  double lossSum = 0;
  int64_t n = 0;
  for (int64_t i = 0; i < h.img1.size(0); i += 16) {
    const int64_t j = std::min<int64_t>(i + 16, h.img1.size(0));
    auto out = pretrainForward(model, task, h.img1.slice(0, i, j), h.img2.slice(0, i, j),
                               h.mask.slice(0, i, j));
    lossSum += maskedMse(out.prediction, out.mask, out.target).item<double>() * (j - i);
    n += j - i;
  }
  const DepthMetrics m = crossFitProbe(model, h.probeA, h.probeB);
  return {{"xv_loss", lossSum / n},
          {"probe_delta1", m.delta1},
          {"probe_absrel", m.absRel},
          {"probe_rmse", m.rmse}};
}

CroCoConfig modelConfig(const SweepConfig& c) {
  CroCoConfig m = presetConfig(c.preset);
  m.img_size = c.imgSize;
  m.patch_size = c.patchSize;
  m.validate();
  return m;
}

// Pre-trains (or resumes) one run, unless it is complete. Every rank of a multi-process sweep
// calls it for every run, in the same order: runPretrain is data-parallel.
void trainRun(const SweepConfig& c, const CroCoConfig& mc, const SweepRun& run, Distributed* dist) {
  const fs::path out(c.out);
  const nlohmann::json done = readJson((run.dir / "summary.json").string());
  if (done.is_object() && done.value("steps", int64_t{0}) >= c.steps &&
      !done.value("interrupted", false))
    return;
  TrainConfig t;
  t.shards = {(out / "pool" / "pool-*.tar").string()};
  t.keysFile = (out / "sets" / (run.keysSet + ".keys")).string();
  t.model = mc;
  t.task = run.task;
  t.batchSize = c.batchSize;
  t.device = c.device;
  // --batch-size is per process, as in pretrain: epochs count the global batch.
  const int world = dist ? dist->worldSize() : 1;
  const int64_t perEpoch = std::max(1, c.pairsPerSet / (c.batchSize * world));
  t.epochs = static_cast<int>((c.steps + perEpoch - 1) / perEpoch);
  t.warmupEpochs = std::max(0.1 * t.epochs, 1.0 / perEpoch);
  t.maxSteps = c.steps;
  t.blr = c.blr;
  t.seed = run.seed;
  t.workers = c.workers;
  t.saveEvery = std::max<int64_t>(25, c.steps / 4);
  t.out = run.dir.string();
  t.resume = true;
  t.progress = false;
  say(c, "training " + run.label() + " (" + std::to_string(c.steps) + " steps)");
  const nlohmann::json r = runPretrain(t, dist);
  if (r.value("interrupted", false))
    throw Error(run.dir.string(), "interrupted; run covis_sweep again to resume");
}

// What every rank must agree on before training: the sets, and how they are trained.
nlohmann::json rankSettings(const SweepConfig& c) {
  return {{"scenes", c.scenes},         {"heldout", c.heldout},   {"modes", c.modes},
          {"centers", c.centers},       {"pairs", c.pairsPerSet}, {"steps", c.steps},
          {"preset", c.preset},         {"img_size", c.imgSize},  {"patch_size", c.patchSize},
          {"batch", c.batchSize},       {"blr", c.blr},           {"seed", c.seed},
          {"resolution", c.resolution}, {"device", c.device},     {"seeds", c.seeds},
          {"baselines", c.baselines}};
}

// Ranks other than 0 wait for rank 0 to write `ready.json` (the pool, the sets and the held-out
// data are done, on a folder all ranks share), then train every set with it.
nlohmann::json followSweep(const SweepConfig& c, const CroCoConfig& mc,
                           const std::vector<SweepRun>& runs, int rank) {
  const std::string ready = (fs::path(c.out) / "ready.json").string();
  const char* env = std::getenv("PAIRCAST_SWEEP_WAIT");
  const double limit = env && *env ? std::atof(env) : 24 * 3600.0;
  const auto start = SteadyClock::now();
  double said = 0;
  while (true) {
    std::error_code ec;
    if (fs::exists(ready, ec)) {
      const nlohmann::json j = nlohmann::json::parse(readFile(ready), nullptr, false);
      if (j.is_object() && j.value("settings", nlohmann::json()) == rankSettings(c)) break;
    }
    const double waited = secondsSince(start);
    if (waited > limit)
      throw Error(ready, "rank " + std::to_string(rank) + " waited " +
                             std::to_string(static_cast<int>(waited)) +
                             " s for rank 0 to prepare the sets (PAIRCAST_SWEEP_WAIT); is rank 0 "
                             "running the same command on the same --out?");
    if (waited >= said) {
      say(c, "rank " + std::to_string(rank) + ": waiting for rank 0's pool and sets");
      said = waited + 60;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
  }
  const auto dist = Distributed::fromEnvironment(c.device);
  for (const auto& run : runs) trainRun(c, mc, run, dist.get());
  return {{"rank", rank}, {"runs_trained", runs.size()}};
}

// ---- the stages of runCovisSweep, in order ----

// Every mode at every centre, mode by mode.
std::vector<SweepSet> planSets(const SweepConfig& c) {
  std::vector<SweepSet> sets;
  for (const auto& mode : c.modes)
    for (double x : c.centers) sets.push_back(makeSweepSet(mode, x));
  return sets;
}

// The scene files, expanded from the lists; no held-out scene is a training scene.
struct SceneFiles {
  std::vector<std::string> train, heldout;
};

SceneFiles sceneFiles(const SweepConfig& c) {
  SceneFiles f{expandSceneList(c.scenes), expandSceneList(c.heldout)};
  // Held-out scenes never appear in training: by file and by scene name.
  std::set<std::string> trainIds;
  for (const auto& t : f.train) {
    trainIds.insert(fs::weakly_canonical(t).string());
    trainIds.insert("name:" + sanitizeName(fs::path(t).stem().string()));
  }
  for (const auto& h : f.heldout)
    if (trainIds.count(fs::weakly_canonical(h).string()) ||
        trainIds.count("name:" + sanitizeName(fs::path(h).stem().string())))
      throw Error(h, "is both a training and a held-out scene");
  return f;
}

// A check on the pool as sampled: none of its pairs comes from a held-out scene.
void checkPoolExcludes(const Pool& pool, const std::vector<std::string>& heldout) {
  std::set<std::string> heldNames;
  for (const auto& f : heldout) heldNames.insert(sanitizeName(fs::path(f).stem().string()));
  for (const auto& key : pool.keys)
    PAIRCAST_CHECK_MSG(
        !heldNames.count(key.substr(0, key.rfind('-'))),  // sampleKey's "<scene>-<index>"
        "a held-out scene's pair is in the training pool");
}

// sets/<name>/report.html, the dataset report of one set, unless a previous run wrote it.
void writeSetReport(const SweepConfig& c, const SweepSet& set, const std::string& keysFile) {
  const fs::path out(c.out), reportDir = out / "sets" / set.name;
  if (fs::exists(reportDir / "report.html")) return;
  ReportOptions ro;
  ro.dir = (out / "pool").string();
  ro.keysFile = keysFile;
  ro.out = reportDir.string();
  ro.title = "covis_sweep set " + set.name;
  ro.samplesPerBin = 3;
  writeDatasetReport(ro);
}

// Draws the sets from the pool and writes their keys (sets/<name>.keys) and, with `reports`,
// their dataset reports. Returns each set's pairs and mean covis, by name.
nlohmann::json writeSets(const SweepConfig& c, const std::vector<SweepSet>& sets,
                         const Pool& pool) {
  const fs::path out(c.out);
  const auto drawn = drawSets(pool.covis, sets, c.pairsPerSet);
  makeDirs((out / "sets").string());
  nlohmann::json setInfo = nlohmann::json::object();
  for (size_t s = 0; s < sets.size(); ++s) {
    std::string keys;
    double mean = 0;
    for (size_t i : drawn[s]) keys += pool.keys[i] + "\n", mean += pool.covis[i];
    const std::string keysFile = (out / "sets" / (sets[s].name + ".keys")).string();
    writeFileAtomic(keysFile, keys);
    setInfo[sets[s].name] = {{"pairs", drawn[s].size()}, {"mean_covis", mean / drawn[s].size()}};
    if (c.reports) writeSetReport(c, sets[s], keysFile);
  }
  say(c, std::to_string(sets.size()) + " sets of " + std::to_string(c.pairsPerSet) +
             " pairs from a pool of " + std::to_string(pool.keys.size()));
  return setInfo;
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

// The evaluation data: the first evalPairs held-out pairs with one mask for every model, and
// the probe's views in two halves.
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
  auto heldScenes = loadScenes(heldout, c.load, SamplerOptions(), "held-out");
  const int half = c.probeViews / 2;
  h.probeA = probeViews(c, heldScenes, 0, half);
  h.probeB = probeViews(c, heldScenes, half, c.probeViews - half);
  return h;
}

// A floor for the probe: one half's mean log depth, everywhere in the other half (and back).
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

// The random-encoder baseline of each seed: the weights that seed's runs start from
// (runs/random/seed-<k>/eval.json).
nlohmann::json randomEncoderRuns(const SweepConfig& c, const CroCoConfig& mc, const HeldOut& h) {
  nlohmann::json runs = nlohmann::json::array();
  for (int k = 0; k < c.seeds; ++k) {
    const fs::path dir = fs::path(c.out) / "runs" / "random" / seedFolder(k);
    nlohmann::json ev = readJson((dir / "eval.json").string());
    if (!ev.is_object()) {
      torch::manual_seed(runSeed(c, k));  // as runPretrain initialises the model
      CroCoNet model(mc);
      ev = evaluate(model, h, "croco");
      makeDirs(dir.string());
      writeFileAtomic((dir / "eval.json").string(), ev.dump(1) + "\n");
    }
    ev.update({{"set", "random_encoder"},
               {"mode", "random"},
               {"task", "croco"},
               {"seed_index", k},
               {"seed", runSeed(c, k)}});
    runs.push_back(ev);
  }
  return runs;
}

// Tells the other ranks (WORLD_SIZE > 1) that the sets are ready: they start training from
// here, in one process group for all runs.
void releaseOtherRanks(const SweepConfig& c) {
  writeFileAtomic((fs::path(c.out) / "ready.json").string(),
                  nlohmann::json({{"settings", rankSettings(c)}}).dump(1) + "\n");
}

// One run's evaluation (<run>/eval.json), after training it, unless a previous sweep did.
nlohmann::json trainAndEvaluate(const SweepConfig& c, const CroCoConfig& mc, const SweepRun& run,
                                const HeldOut& h, Distributed* dist) {
  nlohmann::json ev = readJson((run.dir / "eval.json").string());
  if (ev.is_object()) return ev;
  trainRun(c, mc, run, dist);
  CroCoNet model(mc);
  const std::string checkpoint = (run.dir / "checkpoint-last.pth").string();
  loadStateDictStrict(model, loadCheckpoint(checkpoint).model, checkpoint);
  ev = evaluate(model, h, run.task);
  const nlohmann::json sum = readJson((run.dir / "summary.json").string());
  ev["train_loss"] = sum.is_object() ? numberOrNan(sum, "loss") : NAN;
  writeFileAtomic((run.dir / "eval.json").string(), ev.dump(1) + "\n");
  return ev;
}

// A run's row of results_runs.csv: its set (with the set's size and mean covis), its seed and
// its evaluation. A baseline's centre is null.
nlohmann::json runRow(const std::vector<SweepSet>& sets, const SweepRun& run,
                      const nlohmann::json& setInfo, const nlohmann::json& ev) {
  nlohmann::json row = {{"set", run.name},
                        {"task", run.task},
                        {"mode", run.name},  // a set's mode below; a baseline's name
                        {"center", nullptr},
                        {"trained_on", run.keysSet},
                        {"seed_index", run.seedIndex},
                        {"seed", run.seed},
                        {"pairs", setInfo.at(run.keysSet).at("pairs")},
                        {"mean_covis", setInfo.at(run.keysSet).at("mean_covis")}};
  for (const auto& set : sets)
    if (set.name == run.name) row["mode"] = set.mode, row["center"] = set.center;
  row.update(ev);
  return row;
}

// results.json's content: the runs, their rows per set, both baselines, and what the sweep was
// run with.
nlohmann::json collectResults(const SweepConfig& c, const std::vector<SweepSet>& sets,
                              const SceneFiles& scenes, const Pool& pool, const HeldOut& h,
                              const nlohmann::json& runs, const nlohmann::json& randomRuns,
                              const nlohmann::json& constant) {
  nlohmann::json results = {{"rows", aggregateRuns(runs)},
                            {"runs", runs},
                            {"random_encoder", aggregateRuns(randomRuns).at(0)},
                            {"random_runs", randomRuns},
                            {"constant_depth", constant},
                            {"config",
                             {{"scenes", scenes.train},
                              {"heldout", scenes.heldout},
                              {"modes", c.modes},
                              {"centers", c.centers},
                              {"seeds", c.seeds},
                              {"baselines", c.baselines},
                              {"pairs_per_set", c.pairsPerSet},
                              {"steps", c.steps},
                              {"preset", c.preset},
                              {"img_size", c.imgSize},
                              {"batch_size", c.batchSize},
                              {"blr", c.blr},
                              {"seed", c.seed},
                              {"eval_pairs", h.img1.size(0)},
                              {"probe_views", c.probeViews}}},
                            {"pool_pairs", pool.keys.size()},
                            {"reference_set", referenceSet(sets)}};
  results["verdicts"] = sweepVerdicts(results);
  return results;
}

}  // namespace

SweepSet makeSweepSet(const std::string& mode, double center) {
  SweepSet s;
  s.mode = mode;
  s.center = center;
  s.name = mode + "_" + centerName(center);
  if (mode == "bin") {
    const int lo = gridIndex(center - 0.05);
    if (lo < 0 || lo + 1 >= kCovisBuckets || center < 0.05 - 1e-9)
      throw Error("bin centre " + centerName(center) +
                  " must be a multiple of 0.05 in [0.05, 0.95] (bins [x - 0.05, x + 0.05))");
    s.buckets = {lo, lo + 1};
  } else if (mode == "uniform") {
    const int lo = gridIndex(center);
    if (lo < 0 || lo >= kCovisBuckets)
      throw Error("uniform centre " + centerName(center) +
                  " must be a multiple of 0.05 in [0, 0.95]");
    for (int b = lo; b < kCovisBuckets; ++b) s.buckets.push_back(b);
  } else {
    throw Error("unknown sweep mode '" + mode + "' (use bin or uniform)");
  }
  return s;
}

std::vector<int> bucketDemand(const std::vector<SweepSet>& sets, int n) {
  std::vector<int> demand(kCovisBuckets, 0);
  for (const auto& s : sets) {
    const int k = static_cast<int>(s.buckets.size());
    for (int i = 0; i < k; ++i)
      demand[s.buckets[i]] = std::max(demand[s.buckets[i]], n / k + (i < n % k ? 1 : 0));
  }
  return demand;
}

std::vector<std::vector<size_t>> drawSets(const std::vector<double>& poolCovis,
                                          const std::vector<SweepSet>& sets, int n) {
  std::vector<std::vector<size_t>> byBucket(kCovisBuckets);
  for (size_t i = 0; i < poolCovis.size(); ++i) byBucket[covisBucket(poolCovis[i])].push_back(i);
  std::vector<std::vector<size_t>> out;
  for (const auto& s : sets) {
    std::vector<size_t> picked;
    const int k = static_cast<int>(s.buckets.size());
    for (int i = 0; i < k; ++i) {
      const int want = n / k + (i < n % k ? 1 : 0);
      const auto& have = byBucket[s.buckets[i]];
      if (static_cast<int>(have.size()) < want)
        throw Error("set " + s.name + " needs " + std::to_string(want) + " pairs with covis in [" +
                    centerName(s.buckets[i] * 0.05) + ", " + centerName((s.buckets[i] + 1) * 0.05) +
                    "), the pool has " + std::to_string(have.size()));
      picked.insert(picked.end(), have.begin(), have.begin() + want);
    }
    std::sort(picked.begin(), picked.end());
    out.push_back(std::move(picked));
  }
  return out;
}

nlohmann::json runCovisSweep(const SweepConfig& c) {
  c.validate();
  const CroCoConfig mc = modelConfig(c);
  const std::vector<SweepSet> sets = planSets(c);
  const std::vector<SweepRun> runs = planRuns(c, sets);
  const SceneFiles scenes = sceneFiles(c);
  const int rank = environmentRole().rank;
  if (rank != 0) return followSweep(c, mc, runs, rank);
  makeDirs(c.out);
  const auto start = SteadyClock::now();

  // 1. One pool, bucketed; equal sets drawn from it.
  const Pool pool = buildPool(c, scenes.train, bucketDemand(sets, c.pairsPerSet));
  checkPoolExcludes(pool, scenes.heldout);
  const nlohmann::json setInfo = writeSets(c, sets, pool);

  // 2. Held-out data: pairs at covis ~0.5, views with depth for the probe, and the probe's floor.
  const HeldOut h = loadHeldOut(c, mc, scenes.heldout);
  const nlohmann::json constant = constantDepthBaseline(h);

  // 3. The random-encoder baseline, once per seed.
  const nlohmann::json randomRuns = randomEncoderRuns(c, mc, h);

  // 4. Train and evaluate every run (each set and baseline with each seed), with the other ranks.
  releaseOtherRanks(c);
  const auto dist = Distributed::fromEnvironment(c.device);
  nlohmann::json rows = nlohmann::json::array();
  for (const SweepRun& run : runs) {
    const nlohmann::json ev = trainAndEvaluate(c, mc, run, h, dist.get());
    rows.push_back(runRow(sets, run, setInfo, ev));
    say(c, run.label() + ": xv_loss " + std::to_string(numberOrNan(ev, "xv_loss")) +
               ", probe delta1 " + std::to_string(numberOrNan(ev, "probe_delta1")));
  }

  // 5. Results: results.csv (a row per set, with intervals), results_runs.csv, results.json,
  //    the plots and summary.html.
  nlohmann::json results = collectResults(c, sets, scenes, pool, h, rows, randomRuns, constant);
  writeSweepReport(c, results);
  results["seconds_this_run"] = secondsSince(start);
  return results;
}

std::string seedFolder(int seedIndex) {
  return "seed-" + std::to_string(seedIndex);
}

uint64_t runSeed(const SweepConfig& c, int seedIndex) {
  return c.seed + seedIndex;
}

std::string SweepRun::label() const {
  return name + " seed " + std::to_string(seedIndex);
}

std::string referenceSet(const std::vector<SweepSet>& sets) {
  PAIRCAST_CHECK(!sets.empty());
  auto distance = [](const SweepSet& s) { return std::abs(s.center - 0.5) + (s.mode != "bin"); };
  return std::min_element(
             sets.begin(), sets.end(),
             [&](const SweepSet& a, const SweepSet& b) { return distance(a) < distance(b); })
      ->name;
}

std::vector<SweepRun> planRuns(const SweepConfig& c, const std::vector<SweepSet>& sets) {
  std::vector<SweepRun> runs;
  const fs::path root = fs::path(c.out) / "runs";
  for (int k = 0; k < c.seeds; ++k) {
    auto add = [&](const std::string& name, const std::string& task, const std::string& keys) {
      runs.push_back({name, task, keys, k, runSeed(c, k), root / name / seedFolder(k)});
    };
    for (const SweepSet& set : sets) add(set.name, "croco", set.name);
    for (const std::string& b : c.baselines) add(b, "mae", referenceSet(sets));
  }
  return runs;
}

void SweepConfig::validate() const {
  if (out.empty()) throw OptionError("out", "an output folder is required");
  if (scenes.empty()) throw OptionError("scenes", "give the training scenes");
  if (heldout.empty()) throw OptionError("heldout", "give at least one held-out scene");
  if (modes.empty() || centers.empty())
    throw OptionError("modes", "give at least one mode and one centre");
  if (pairsPerSet < batchSize)
    throw OptionError("pairs_per_set", "pairs per set must be at least one batch (" +
                                           std::to_string(batchSize) + ")");
  if (steps < 1) throw OptionError("steps", "training steps must be >= 1");
  if (evalPairs < 1) throw OptionError("eval_pairs", "held-out pairs must be >= 1");
  if (probeViews < 4) throw OptionError("probe_views", "the depth probe needs at least 4 views");
  if (seeds < 1 || seeds > 1000) throw OptionError("seeds", "seeds must be in 1..1000");
  for (size_t i = 0; i < baselines.size(); ++i) {
    if (baselines[i] != "mae")
      throw OptionError("baseline", "unknown baseline '" + baselines[i] + "' (use mae)");
    if (std::find(baselines.begin(), baselines.begin() + i, baselines[i]) != baselines.begin() + i)
      throw OptionError("baseline", "baseline '" + baselines[i] + "' is given twice");
  }
}

}  // namespace paircast
