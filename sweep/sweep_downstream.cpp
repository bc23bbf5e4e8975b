#include "sweep/sweep_downstream.h"

#include <algorithm>
#include <cmath>

#include "dataset/generate_job.h"
#include "shard/shard_index.h"
#include "sweep/sweep_report.h"
#include "sweep/sweep_scene.h"
#include "trainer/distributed.h"
#include "trainer/pair_dataset.h"
#include "util/atomic_file.h"
#include "util/error.h"

namespace paircast {
namespace fs = std::filesystem;

namespace {

// What the fine-tuning data is made with: ds/ is made again when it changes.
nlohmann::json dataSettings(const SweepConfig& c) {
  return {{"scenes", c.scenes},
          {"heldout", c.heldout},
          {"up", static_cast<int>(c.load.up)},
          {"scale", c.load.scale},
          {"pairs", c.finetunePairs},
          {"eval_pairs", c.finetuneEvalPairs},
          {"resolution", c.resolution},
          {"seed", c.seed},
          {"flow_motion", c.finetuneFlowMotion}};
}

// What a fine-tune is made with: one made otherwise is made again. The world size sets the
// epochs' length, and so the data order and the schedule.
nlohmann::json jobSettings(const SweepConfig& c, const FinetuneJob& job, int world) {
  return {{"data", dataSettings(c)},
          {"task", job.task},
          {"run", job.run},
          {"seed", job.seed},
          {"steps", c.finetuneSteps},
          {"batch", c.finetuneBatch},
          {"blr", c.finetuneBlr},
          {"preset", c.preset},
          {"img_size", c.imgSize},
          {"patch_size", c.patchSize},
          {"world_size", world},
          // The flow scale the fine-tune takes and a schedule that spans the steps taken.
          {"flow_scale", job.task == "flow" ? defaultFlowScale(c.imgSize) : 1.0},
          {"schedule", "spans-run"}};
}

// Removes `dir` when it was made with other settings than `settings` (its settings.json differs,
// or it has files but no settings.json: a removal cut short), and says so; then writes
// `settings` there, before anything else goes in. The folder is renamed before it is removed, so
// that a kill during the removal leaves no part of it under its name.
void keepOnlyIfMadeWith(const SweepConfig& c, const fs::path& dir, const nlohmann::json& settings) {
  const nlohmann::json had = readSweepState((dir / "settings.json").string());
  std::error_code ec;
  const bool stale =
      had.is_null() ? fs::exists(dir, ec) && !fs::is_empty(dir, ec) : had != settings;
  if (stale) {
    sweepSay(c, dir.string() + " was made with other settings; making it again");
    const fs::path doomed = dir.string() + ".removing";
    fs::remove_all(doomed);
    fs::rename(dir, doomed);
    fs::remove_all(doomed);
  }
  makeDirs(dir.string());
  writeFileAtomic((dir / "settings.json").string(), settings.dump(1) + "\n");
}

// ds/<part>: pairs of `scenes` with flow and depth, covis in [lo, hi], the second view drawn by
// `motion`, unless already there.
std::string generateTruth(const SweepConfig& c, const std::string& part,
                          const std::vector<std::string>& scenes, int pairs, double lo, double hi,
                          uint64_t seed,
                          SamplerOptions::Motion motion = SamplerOptions::Motion::kWalk) {
  GenerateConfig g;
  g.scenes = scenes;
  g.out = (fs::path(c.out) / "ds" / part).string();
  const int n = static_cast<int>(scenes.size());
  g.pairsPerScene = (pairs + n - 1) / n;
  g.seed = seed;
  g.jobs = c.jobs;
  g.load = c.load;
  g.pair.resolution = c.resolution;
  g.pair.minCovis = lo;
  g.pair.maxCovis = hi;
  g.pair.sampler.motion = motion;
  g.saveFlow = true;
  g.saveDepth = true;
  g.progress = false;
  if (!fs::exists(fs::path(g.out) / "summary.json")) {
    sweepSay(c, "downstream data: " + std::to_string(g.pairsPerScene * n) + " " + part +
                    " pairs with flow and depth");
    runGenerate(g);
  }
  return g.out;
}

// Each sample's key and covis in the shards of a pattern; `samples` counts them.
std::map<std::string, double> covisByKey(const std::string& pattern, size_t* samples = nullptr) {
  std::map<std::string, double> covis;
  for (const std::string& file : expandShardPatterns({pattern})) {
    const ShardIndex index = ShardIndex::open(file);
    for (size_t i = 0; i < index.size(); ++i) covis[index[i].key] = index[i].record.covis;
    if (samples) *samples += index.size();
  }
  return covis;
}

// The mean of the finite values of `key` over pairs whose covis (in `covisByKey`) is in [lo, hi)
// (hi = 1 closed), with their count.
std::pair<double, int> meanOver(const nlohmann::json& pairs,
                                const std::map<std::string, double>& covisByKey,
                                const std::string& key, double lo, double hi) {
  double sum = 0;
  int n = 0;
  for (const auto& p : pairs) {
    const auto it = covisByKey.find(p.value("key", ""));
    if (it == covisByKey.end()) continue;
    const double v = numberOrNan(p, key), covis = it->second;
    const bool in = covis >= lo - 1e-9 && (covis < hi - 1e-9 || (hi >= 1 && covis <= 1));
    if (in && std::isfinite(v)) sum += v, ++n;
  }
  return {n ? sum / n : NAN, n};
}

// heldout.json's per-pair figures of a fine-tune (the model's, or the baseline's), or null.
nlohmann::json perPair(const fs::path& dir, bool baseline) {
  const nlohmann::json h = readSweepState((dir / "heldout.json").string());
  if (!h.is_object()) return nullptr;
  return h.at("per_pair").at(baseline ? "baseline" : "model");
}

void addFlowFigures(nlohmann::json& out, const nlohmann::json& pairs, const DownstreamData& d) {
  const auto& covis = d.flowHeldoutCovis;
  const double lo = d.flowBandLo, hi = d.flowBandHi;
  out["ft_flow_aepe"] = meanOver(pairs, covis, "aepe", lo, hi).first;
  out["ft_flow_aepe_covisible"] = meanOver(pairs, covis, "aepe_covisible", lo, hi).first;
  out["ft_flow_px3"] = meanOver(pairs, covis, "px3", lo, hi).first;
  out["ft_flow_aepe_all"] = meanOver(pairs, covis, "aepe", 0, 1).first;
  nlohmann::json bins = nlohmann::json::array();
  for (int b = 0; b * kDownstreamBinWidth < 1 - 1e-9; ++b) {
    const double blo = b * kDownstreamBinWidth, bhi = (b + 1) * kDownstreamBinWidth;
    const auto [aepe, n] = meanOver(pairs, covis, "aepe", blo, bhi);
    if (n == 0) continue;
    bins.push_back(
        {{"covis_lo", blo},
         {"covis_hi", bhi},
         {"pairs", n},
         {"ft_flow_aepe", aepe},
         {"ft_flow_aepe_covisible", meanOver(pairs, covis, "aepe_covisible", blo, bhi).first}});
  }
  out["ft_flow_by_covis"] = bins;
}

// ds/<train> and ds/<heldout>'s shard patterns, training pairs and held-out covis; throws
// paircast::Error naming the folder when training has fewer pairs than a batch, or nothing is
// held out.
void openParts(const SweepConfig& c, const std::string& train, const std::string& heldout,
               std::string* trainShards, std::string* heldoutShards, size_t* trainPairs,
               std::map<std::string, double>* heldoutCovis) {
  const fs::path ds = fs::path(c.out) / "ds";
  *trainShards = (ds / train / "pairs-*.tar").string();
  *heldoutShards = (ds / heldout / "pairs-*.tar").string();
  covisByKey(*trainShards, trainPairs);
  *heldoutCovis = covisByKey(*heldoutShards);
  if (*trainPairs < static_cast<size_t>(c.finetuneBatch))
    throw Error((ds / train).string(),
                "holds " + std::to_string(*trainPairs) +
                    " fine-tuning pairs, fewer than one batch (--finetune-batch)");
  if (heldoutCovis->empty()) throw Error((ds / heldout).string(), "holds no held-out pairs");
}

}  // namespace

DownstreamData prepareDownstreamData(const SweepConfig& c, const std::vector<std::string>& train,
                                     const std::vector<std::string>& heldout) {
  keepOnlyIfMadeWith(c, fs::path(c.out) / "ds", dataSettings(c));
  // Seeds apart from the pool's (c.seed), the held-out xv pairs' (+1) and the probes' (+3).
  if (c.finetunesOnWidePairs()) {
    generateTruth(c, "train", train, c.finetunePairs, kWideTrainMinCovis, 1.0, c.seed + 11);
    generateTruth(c, "heldout", heldout, c.finetuneEvalPairs, kWideHeldoutMinCovis, 1.0,
                  c.seed + 12);
  }
  if (c.flowOnFlowStylePairs()) {
    const auto near = SamplerOptions::Motion::kNear;
    generateTruth(c, "flow-train", train, c.finetunePairs, kFlowStyleMinCovis, 1.0, c.seed + 13,
                  near);
    generateTruth(c, "flow-heldout", heldout, c.finetuneEvalPairs, kFlowStyleMinCovis, 1.0,
                  c.seed + 14, near);
  }
  return openDownstreamData(c);
}

DownstreamData openDownstreamData(const SweepConfig& c) {
  DownstreamData d;
  if (c.finetunesOnWidePairs())
    openParts(c, "train", "heldout", &d.trainShards, &d.heldoutShards, &d.trainPairs,
              &d.heldoutCovis);
  if (!c.flowOnFlowStylePairs()) {
    d.flowTrainShards = d.trainShards, d.flowHeldoutShards = d.heldoutShards;
    d.flowTrainPairs = d.trainPairs, d.flowHeldoutCovis = d.heldoutCovis;
    return d;
  }
  openParts(c, "flow-train", "flow-heldout", &d.flowTrainShards, &d.flowHeldoutShards,
            &d.flowTrainPairs, &d.flowHeldoutCovis);
  d.flowBandLo = kFlowStyleMinCovis, d.flowBandHi = 1.0;
  return d;
}

fs::path finetuneDir(const fs::path& runDir, const std::string& task) {
  return runDir / ("finetune-" + task);
}

std::vector<FinetuneJob> planFinetunes(const SweepConfig& c, const std::vector<SweepRun>& runs) {
  std::vector<FinetuneJob> jobs;
  const fs::path root = fs::path(c.out) / "runs";
  for (const int k : c.seedIndices()) {
    auto add = [&](const std::string& name, const std::string& init, const fs::path& runDir) {
      for (const std::string& task : c.downstream)
        jobs.push_back({name + " seed " + std::to_string(k) + " " + task, name, task, init,
                        runSeed(c, k), finetuneDir(runDir, task)});
    };
    add("random", "random", root / "random" / seedFolder(k));
    for (const SweepRun& run : runs)
      if (run.seedIndex == k) add(run.name, (run.dir / "checkpoint-last.pth").string(), run.dir);
  }
  return jobs;
}

FinetuneConfig finetuneConfig(const SweepConfig& c, const CroCoConfig& mc,
                              const DownstreamData& data, const FinetuneJob& job, int world) {
  FinetuneConfig f;
  f.model.croco = mc;
  f.model.task = job.task;
  f.model.head = "linear";
  const bool flow = job.task == "flow";
  f.data = {flow ? data.flowTrainShards : data.trainShards};
  f.evalData = {flow ? data.flowHeldoutShards : data.heldoutShards};
  f.init = job.init;
  TrainConfig& t = f.train;
  t.device = c.device;
  t.amp = c.amp;
  setSweepSchedule(t, c.finetuneSteps,
                   static_cast<int64_t>(flow ? data.flowTrainPairs : data.trainPairs),
                   c.finetuneBatch, world);
  t.blr = c.finetuneBlr;
  t.seed = job.seed;
  t.workers = c.workers;
  t.out = job.dir.string();
  t.progress = false;
  return f;
}

bool runFinetuneJob(const SweepConfig& c, const CroCoConfig& mc, const DownstreamData& data,
                    const FinetuneJob& job, Distributed* dist) {
  const int world = dist ? dist->worldSize() : 1;
  if (!dist || dist->rank() == 0) keepOnlyIfMadeWith(c, job.dir, jobSettings(c, job, world));
  if (dist) dist->barrier();
  const nlohmann::json done = readSweepState((job.dir / "summary.json").string());
  if (done.is_object() && done.value("steps", int64_t{0}) >= c.finetuneSteps &&
      !done.value("interrupted", false) && fs::exists(job.dir / "heldout.json"))
    return false;
  sweepSay(c, "fine-tuning " + job.label + " (" + std::to_string(c.finetuneSteps) + " steps)");
  const nlohmann::json r = runFinetune(finetuneConfig(c, mc, data, job, world), dist);
  if (r.value("interrupted", false))
    throw Error(job.dir.string(), "interrupted; run covis_sweep again to resume");
  return true;
}

nlohmann::json downstreamFigures(const SweepConfig& c, const DownstreamData& d,
                                 const fs::path& runDir, bool baseline) {
  nlohmann::json out = nlohmann::json::object();
  for (const std::string& task : c.downstream) {
    const nlohmann::json pairs = perPair(finetuneDir(runDir, task), baseline);
    if (pairs.is_null()) continue;
    if (task == "flow") addFlowFigures(out, pairs, d);
    if (task == "depth") {
      out["ft_depth_delta1"] =
          meanOver(pairs, d.heldoutCovis, "delta1", kDownstreamBandLo, kDownstreamBandHi).first;
      out["ft_depth_absrel"] =
          meanOver(pairs, d.heldoutCovis, "absrel", kDownstreamBandLo, kDownstreamBandHi).first;
    }
  }
  return out;
}

}  // namespace paircast
