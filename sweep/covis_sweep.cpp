#include "sweep/covis_sweep.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <numeric>
#include <set>
#include <thread>

#include <omp.h>

#include "dataset/dataset_report.h"
#include "dataset/generate_job.h"
#include "model/checkpoint.h"
#include "model/croco_net.h"
#include "model/precision.h"
#include "sweep/heldout_eval.h"
#include "sweep/sweep_downstream.h"
#include "sweep/sweep_pool.h"
#include "sweep/sweep_report.h"
#include "sweep/sweep_scene.h"
#include "sweep/sweep_stats.h"
#include "trainer/distributed.h"
#include "trainer/trainer.h"
#include "util/atomic_file.h"
#include "util/error.h"
#include "util/timer.h"
#include "util/work_claims.h"

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

CroCoConfig modelConfig(const SweepConfig& c) {
  CroCoConfig m = presetConfig(c.preset);
  m.img_size = c.imgSize;
  m.patch_size = c.patchSize;
  m.validate();
  return m;
}

// Whether a run's pre-training is complete.
bool pretrained(const SweepConfig& c, const fs::path& runDir) {
  const nlohmann::json done = readSweepState((runDir / "summary.json").string());
  return done.is_object() && done.value("steps", int64_t{0}) >= c.steps &&
         !done.value("interrupted", false);
}

// Pre-trains (or resumes) one run, unless it is complete. Every rank of a multi-process sweep
// calls it for every run, in the same order: runPretrain is data-parallel.
void trainRun(const SweepConfig& c, const CroCoConfig& mc, const SweepRun& run, Distributed* dist) {
  const fs::path out(c.out);
  if (pretrained(c, run.dir)) return;
  TrainConfig t;
  t.shards = {(out / "pool" / "pool-*.tar").string()};
  t.keysFile = (out / "sets" / (run.keysSet + ".keys")).string();
  t.model = mc;
  t.task = run.task;
  t.device = c.device;
  t.amp = c.amp;
  // --batch-size is per process, as in pretrain: epochs count the global batch.
  setSweepSchedule(t, c.steps, c.pairsPerSet, c.batchSize, dist ? dist->worldSize() : 1);
  t.blr = c.blr;
  t.seed = run.seed;
  t.workers = c.workers;
  t.out = run.dir.string();
  t.progress = false;
  sweepSay(c, "training " + run.label() + " (" + std::to_string(c.steps) + " steps)");
  const nlohmann::json r = runPretrain(t, dist);
  if (r.value("interrupted", false))
    throw Error(run.dir.string(), "interrupted; run covis_sweep again to resume");
}

// What the fine-tunes are made with (results.json's config, and what the ranks agree on).
nlohmann::json downstreamSettings(const SweepConfig& c) {
  if (c.downstream.empty()) return nullptr;
  return {{"tasks", c.downstream},
          {"steps", c.finetuneSteps},
          {"pairs", c.finetunePairs},
          {"eval_pairs", c.finetuneEvalPairs},
          {"batch", c.finetuneBatch},
          {"blr", c.finetuneBlr},
          {"head", "linear"},
          {"eval_covis", {kWideHeldoutMinCovis, 1.0}},
          {"band", {kDownstreamBandLo, kDownstreamBandHi}},
          {"flow_motion", c.finetuneFlowMotion}};
}

// What every rank must agree on before training: the sets, and how they are trained.
nlohmann::json rankSettings(const SweepConfig& c) {
  return {{"scenes", c.scenes},
          {"heldout", c.heldout},
          {"modes", c.modes},
          {"centers", c.centers},
          {"pairs", c.pairsPerSet},
          {"steps", c.steps},
          {"preset", c.preset},
          {"img_size", c.imgSize},
          {"patch_size", c.patchSize},
          {"batch", c.batchSize},
          {"blr", c.blr},
          {"seed", c.seed},
          {"resolution", c.resolution},
          {"device", c.device},
          {"amp", c.amp},
          {"seeds", c.seeds},
          {"first_seed", c.firstSeed},
          {"baselines", c.baselines},
          {"sets", c.sets},
          {"downstream", downstreamSettings(c)}};
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
      sweepSay(c, "rank " + std::to_string(rank) + ": waiting for rank 0's pool and sets");
      said = waited + 60;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
  }
  const auto dist = Distributed::fromEnvironment(c.device);
  for (const auto& run : runs) trainRun(c, mc, run, dist.get());
  if (!c.downstream.empty()) {
    const DownstreamData data = openDownstreamData(c);  // rank 0 made it before ready.json
    for (const FinetuneJob& job : planFinetunes(c, runs))
      runFinetuneJob(c, mc, data, job, dist.get());
  }
  return {{"rank", rank}, {"runs_trained", runs.size()}};
}

// The claim file of a unit of work (a run's training, a fine-tune): <out>/claims/<label>.lock.
std::string claimFile(const SweepConfig& c, std::string label) {
  std::replace(label.begin(), label.end(), ' ', '-');
  return (fs::path(c.out) / "claims" / (label + ".lock")).string();
}

// What worker k ran: <out>/claims/worker-<k>.json.
fs::path workerRecord(const SweepConfig& c, int k) {
  return fs::path(c.out) / "claims" / ("worker-" + std::to_string(k) + ".json");
}

// One of the --processes worker processes, started by the sweep once its pool, sets and held-out
// data are ready. It trains every run that no other worker holds, in order, then fine-tunes
// likewise; a fine-tune of a run another worker is training waits for it (and trains it, if that
// worker was killed part way). Before each unit it stops when asked to (SIGINT, SIGTERM, or the
// command that started it gone). It writes what it ran to claims/worker-<k>.json.
nlohmann::json workOnClaims(const SweepConfig& c, const CroCoConfig& mc,
                            const std::vector<SweepRun>& runs) {
  stopWithParent();
  auto stopIfAsked = [&] {
    if (workerShouldStop())
      throw Error(c.out, "worker " + std::to_string(c.worker) +
                             " stopped; run covis_sweep again to resume");
  };
  int trained = 0, finetuned = 0;
  for (const SweepRun& run : runs) {
    stopIfAsked();
    const auto claim = WorkClaim::tryTake(claimFile(c, run.label()));
    if (claim && !pretrained(c, run.dir)) trainRun(c, mc, run, nullptr), ++trained;
  }
  if (!c.downstream.empty()) {
    const DownstreamData data = openDownstreamData(c);
    for (const FinetuneJob& job : planFinetunes(c, runs)) {
      stopIfAsked();
      const auto run = std::find_if(runs.begin(), runs.end(), [&](const SweepRun& r) {
        return (r.dir / "checkpoint-last.pth").string() == job.init;
      });
      if (run != runs.end()) {
        // Its training, wherever it ran, is over. When it is not complete, the worker that held
        // it was killed (a failing worker stops them all): its run is trained here.
        const WorkClaim training = WorkClaim::take(claimFile(c, run->label()));
        if (!pretrained(c, run->dir)) trainRun(c, mc, *run, nullptr), ++trained;
      }
      const auto claim = WorkClaim::tryTake(claimFile(c, job.label));
      if (claim) finetuned += runFinetuneJob(c, mc, data, job, nullptr);
    }
  }
  sweepSay(c, "done: " + std::to_string(trained) + " runs trained, " + std::to_string(finetuned) +
                  " fine-tunes");
  const nlohmann::json done = {
      {"worker", c.worker}, {"runs_trained", trained}, {"finetunes", finetuned}};
  writeFileAtomic(workerRecord(c, c.worker).string(), done.dump() + "\n");
  return done;
}

// With --processes N: N workers (workOnClaims) train and fine-tune every run, each on its share
// of our threads (OMP_NUM_THREADS, else the cores). On a few cores, N independent runs go faster
// than one on all of them.
void trainInWorkers(const SweepConfig& c) {
  const int threads = std::max(1, omp_get_max_threads() / c.processes);
  sweepSay(c, "training and fine-tuning in " + std::to_string(c.processes) + " processes of " +
                  std::to_string(threads) + (threads == 1 ? " thread" : " threads"));
  for (int k = 1; k <= c.processes; ++k)  // a previous sweep's records
    fs::remove(workerRecord(c, k));
  try {
    runWorkerProcesses(kSelfExecutable, c.command, "--worker", c.processes, threads);
  } catch (const Error& e) {
    throw Error(c.out, std::string(e.what()) + "; run covis_sweep again to resume");
  }
}

// ---- the stages of runCovisSweep, in order ----

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
  sweepSay(c, std::to_string(sets.size()) + " sets of " + std::to_string(c.pairsPerSet) +
                  " pairs from a pool of " + std::to_string(pool.keys.size()));
  return setInfo;
}

// The random-encoder baseline of each seed: the weights that seed's runs start from
// (runs/random/seed-<k>/eval.json).
nlohmann::json randomEncoderRuns(const SweepConfig& c, const CroCoConfig& mc, const HeldOut& h) {
  nlohmann::json runs = nlohmann::json::array();
  for (const int k : c.seedIndices()) {
    const fs::path dir = fs::path(c.out) / "runs" / "random" / seedFolder(k);
    nlohmann::json ev = readSweepState((dir / "eval.json").string());
    if (!evaluatedWith(ev, h)) {
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
  nlohmann::json ev = readSweepState((run.dir / "eval.json").string());
  if (evaluatedWith(ev, h)) return ev;
  trainRun(c, mc, run, dist);
  CroCoNet model(mc);
  const std::string checkpoint = (run.dir / "checkpoint-last.pth").string();
  loadStateDictStrict(model, loadCheckpoint(checkpoint).model, checkpoint);
  ev = evaluate(model, h, run.task);
  const nlohmann::json sum = readSweepState((run.dir / "summary.json").string());
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
                              const nlohmann::json& constant, const nlohmann::json& trivial) {
  nlohmann::json results = {{"rows", aggregateRuns(runs)},
                            {"runs", runs},
                            {"random_encoder", aggregateRuns(randomRuns).at(0)},
                            {"random_runs", randomRuns},
                            {"constant_depth", constant},
                            {"finetune_baselines", trivial},
                            {"config",
                             {{"scenes", scenes.train},
                              {"heldout", scenes.heldout},
                              {"modes", c.modes},
                              {"centers", c.centers},
                              {"sets", c.sets},
                              {"seeds", c.seeds},
                              {"first_seed", c.firstSeed},
                              {"baselines", c.baselines},
                              {"pairs_per_set", c.pairsPerSet},
                              {"steps", c.steps},
                              {"preset", c.preset},
                              {"img_size", c.imgSize},
                              {"patch_size", c.patchSize},
                              {"resolution", c.resolution},
                              {"batch_size", c.batchSize},
                              {"blr", c.blr},
                              {"seed", c.seed},
                              {"amp", c.amp},
                              {"precision", h.precision.toJson()},
                              {"eval_pairs", h.img1.size(0)},
                              {"probe_views", c.probeViews},
                              {"mechanism_pairs", h.mechanism.size()},
                              {"mechanism_covis", {c.mechanismMinCovis, c.mechanismMaxCovis}},
                              {"downstream", downstreamSettings(c)}}},
                            {"pool_pairs", pool.keys.size()},
                            {"reference_set", referenceSet(sets)}};
  results["verdicts"] = sweepVerdicts(results);
  return results;
}

// Fine-tunes every run and each seed's random weights (all ranks, in the same order), then adds
// each one's downstream figures to its row. Returns the trivial baselines' figures (zero flow,
// constant depth), the same for every fine-tune.
nlohmann::json fineTuneAll(const SweepConfig& c, const CroCoConfig& mc,
                           const std::vector<SweepRun>& runs, const DownstreamData& data,
                           Distributed* dist, nlohmann::json& rows, nlohmann::json& randomRuns) {
  const std::vector<FinetuneJob> jobs = planFinetunes(c, runs);
  for (const FinetuneJob& job : jobs) runFinetuneJob(c, mc, data, job, dist);
  for (size_t i = 0; i < runs.size(); ++i) rows[i].update(downstreamFigures(c, data, runs[i].dir));
  for (auto& random : randomRuns)
    random.update(downstreamFigures(
        c, data, fs::path(c.out) / "runs" / "random" / seedFolder(random.at("seed_index"))));
  return downstreamFigures(c, data, jobs.front().dir.parent_path(), true);
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

SweepSet parseSweepSet(const std::string& name) {
  const size_t cut = name.rfind('_');
  char* end = nullptr;
  const double center = cut == std::string::npos ? NAN : std::strtod(name.c_str() + cut + 1, &end);
  if (cut == std::string::npos || cut == 0 || cut + 1 == name.size() || !end || *end != '\0')
    throw Error("set '" + name + "' is not <mode>_<centre>, e.g. bin_0.55 or uniform_0.50");
  return makeSweepSet(name.substr(0, cut), center);
}

std::vector<SweepSet> planSets(const SweepConfig& c) {
  std::vector<SweepSet> sets;
  for (const auto& name : c.sets) sets.push_back(parseSweepSet(name));
  if (c.sets.empty())
    for (const auto& mode : c.modes)
      for (double x : c.centers) sets.push_back(makeSweepSet(mode, x));
  return sets;
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
  if (c.worker > 0) return workOnClaims(c, mc, runs);
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

  std::unique_ptr<DownstreamData> downstream;
  if (!c.downstream.empty())
    downstream =
        std::make_unique<DownstreamData>(prepareDownstreamData(c, scenes.train, scenes.heldout));

  // 3. The random-encoder baseline, once per seed.
  nlohmann::json randomRuns = randomEncoderRuns(c, mc, h);

  // 4. Train and evaluate every run (each set and baseline with each seed), with the other ranks.
  //    With --processes, the workers train (and fine-tune) every run first; what follows here
  //    finds them done.
  releaseOtherRanks(c);
  if (c.processes > 1) trainInWorkers(c);
  const auto dist = Distributed::fromEnvironment(c.device);
  nlohmann::json rows = nlohmann::json::array();
  for (const SweepRun& run : runs) {
    const nlohmann::json ev = trainAndEvaluate(c, mc, run, h, dist.get());
    rows.push_back(runRow(sets, run, setInfo, ev));
    sweepSay(c, run.label() + ": xv_loss " + std::to_string(numberOrNan(ev, "xv_loss")) +
                    ", probe delta1 " + std::to_string(numberOrNan(ev, "probe_delta1")));
  }

  // 5. With --downstream, every run and each seed's random weights fine-tuned, and measured.
  nlohmann::json trivial = nullptr;
  if (downstream) trivial = fineTuneAll(c, mc, runs, *downstream, dist.get(), rows, randomRuns);

  // 6. Results: results.csv (a row per set, with intervals), results_runs.csv, results.json,
  //    the plots and summary.html.
  nlohmann::json results =
      collectResults(c, sets, scenes, pool, h, rows, randomRuns, constant, trivial);
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
  for (const int k : c.seedIndices()) {
    auto add = [&](const std::string& name, const std::string& task, const std::string& keys) {
      runs.push_back({name, task, keys, k, runSeed(c, k), root / name / seedFolder(k)});
    };
    for (const SweepSet& set : sets) add(set.name, "croco", set.name);
    for (const std::string& b : c.baselines) add(b, "mae", referenceSet(sets));
  }
  return runs;
}

std::vector<int> SweepConfig::seedIndices() const {
  std::vector<int> k(std::max(seeds, 0));
  std::iota(k.begin(), k.end(), firstSeed);
  return k;
}

bool SweepConfig::finetunes(const std::string& task) const {
  return std::find(downstream.begin(), downstream.end(), task) != downstream.end();
}

bool SweepConfig::flowOnFlowStylePairs() const {
  return finetuneFlowMotion == "near" && finetunes("flow");
}

bool SweepConfig::finetunesOnWidePairs() const {
  return finetunes("depth") || (finetunes("flow") && !flowOnFlowStylePairs());
}

void SweepConfig::validate() const {
  if (out.empty()) throw OptionError("out", "an output folder is required");
  if (scenes.empty()) throw OptionError("scenes", "give the training scenes");
  if (heldout.empty()) throw OptionError("heldout", "give at least one held-out scene");
  if (sets.empty() && (modes.empty() || centers.empty()))
    throw OptionError("modes", "give at least one mode and one centre, or --sets");
  if (mechanismPairs < 1) throw OptionError("mechanism_pairs", "must be >= 1");
  for (size_t i = 0; i < sets.size(); ++i) {
    try {
      parseSweepSet(sets[i]);
    } catch (const Error& e) {
      throw OptionError("sets", e.what());
    }
    if (std::find(sets.begin(), sets.begin() + i, sets[i]) != sets.begin() + i)
      throw OptionError("sets", "set '" + sets[i] + "' is given twice");
  }
  if (!(mechanismMinCovis >= 0 && mechanismMinCovis < mechanismMaxCovis && mechanismMaxCovis <= 1))
    throw OptionError("mechanism_covis", "must be lo,hi with 0 <= lo < hi <= 1");
  if (pairsPerSet < batchSize)
    throw OptionError("pairs_per_set", "pairs per set must be at least one batch (" +
                                           std::to_string(batchSize) + ")");
  if (steps < 1) throw OptionError("steps", "training steps must be >= 1");
  checkAmp(amp);
  if (evalPairs < 1) throw OptionError("eval_pairs", "held-out pairs must be >= 1");
  if (probeViews < 4) throw OptionError("probe_views", "the depth probe needs at least 4 views");
  if (seeds < 1 || seeds > 1000) throw OptionError("seeds", "seeds must be in 1..1000");
  if (firstSeed < 0 || firstSeed + seeds > 1000)
    throw OptionError("first_seed", "seed indices must lie in 0..999 (--first-seed " +
                                        std::to_string(firstSeed) + ", --seeds " +
                                        std::to_string(seeds) + ")");
  if (processes < 1 || processes > 64) throw OptionError("processes", "processes must be in 1..64");
  if (processes > 1 && environmentRole().world > 1)
    throw OptionError("processes",
                      "--processes runs independent workers; it does not combine with a "
                      "multi-process launch (WORLD_SIZE > 1)");
  if (processes > 1 && command.empty())
    throw OptionError("processes", "--processes needs the command line to start its workers");
  if (worker < 0 || worker > processes)
    throw OptionError("worker", "--worker is for the workers that --processes starts");
  for (size_t i = 0; i < downstream.size(); ++i) {
    if (downstream[i] == "pose")
      throw OptionError("downstream",
                        "pose is not fine-tuned by the sweep: at this scale it does not beat the "
                        "identity pose (docs/finetune.md); use flow, depth or flow,depth");
    if (downstream[i] != "flow" && downstream[i] != "depth")
      throw OptionError("downstream", "unknown downstream task '" + downstream[i] +
                                          "' (use flow, depth or flow,depth)");
    if (std::find(downstream.begin(), downstream.begin() + i, downstream[i]) !=
        downstream.begin() + i)
      throw OptionError("downstream", "task '" + downstream[i] + "' is given twice");
  }
  if (!downstream.empty()) {
    if (finetuneSteps < 1) throw OptionError("finetune_steps", "fine-tuning steps must be >= 1");
    if (finetuneBatch < 1) throw OptionError("finetune_batch", "the batch must be >= 1");
    if (finetunePairs < finetuneBatch)
      throw OptionError("finetune_pairs", "fine-tuning pairs must be at least one batch (" +
                                              std::to_string(finetuneBatch) + ")");
    if (finetuneEvalPairs < 1)
      throw OptionError("finetune_eval_pairs", "held-out pairs must be >= 1");
    if (finetuneFlowMotion != "near" && finetuneFlowMotion != "walk")
      throw OptionError("finetune_flow_motion",
                        "flow's pairs are near or walk, not '" + finetuneFlowMotion + "'");
  }
  for (size_t i = 0; i < baselines.size(); ++i) {
    if (baselines[i] != "mae")
      throw OptionError("baseline", "unknown baseline '" + baselines[i] + "' (use mae)");
    if (std::find(baselines.begin(), baselines.begin() + i, baselines[i]) != baselines.begin() + i)
      throw OptionError("baseline", "baseline '" + baselines[i] + "' is given twice");
  }
}

}  // namespace paircast
