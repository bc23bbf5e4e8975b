// covis_sweep: the co-visibility ablation of CroCo's appendix, end to end. One pool of pairs is
// sampled from the training scenes and bucketed by covis (20 buckets of 0.05); every set of the
// sweep ("bin": covis in [x - 0.05, x + 0.05); "uniform": spread evenly over [x, 1]) is drawn
// from the pool with the same size. The same model is pre-trained on each set with the same
// steps, once per seed (and so is any baseline, such as mae), then evaluated on held-out
// scenes: the completion loss on pairs at covis about 0.5, and a monocular depth probe on the
// frozen encoder, against a randomly initialised encoder of each seed. With --downstream, every
// run (and each seed's random weights) is also fine-tuned for flow and depth and measured on
// held-out pairs (sweep_downstream.h). Every stage is kept on disk and reused, so a killed sweep
// resumes run by run and fine-tune by fine-tune.
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "render/scene_loader.h"

namespace paircast {

constexpr int kCovisBuckets = 20;  // of width 0.05
int covisBucket(double covis);
// A centre or a bucket's edge as the sets' names and the results write it: "0.45".
std::string centerName(double center);

struct SweepSet {
  std::string name;  // e.g. bin_0.45, uniform_0.25
  std::string mode;  // bin or uniform
  double center = 0;
  std::vector<int> buckets;  // covis buckets it draws from, equally
};

// The set of `mode` at `center`. Throws paircast::Error when the centre is not on the buckets'
// grid (bin: 0.05, 0.15, ...; uniform: a multiple of 0.05 below 1).
SweepSet makeSweepSet(const std::string& mode, double center);
// The set a name gives, "<mode>_<centre>" (bin_0.55, uniform_0.50); throws paircast::Error
// naming it when it is not one.
SweepSet parseSweepSet(const std::string& name);

// Pairs needed from each bucket so that every set of n pairs can be drawn (sets share pairs).
std::vector<int> bucketDemand(const std::vector<SweepSet>& sets, int n);

// Draws each set from a pool (pair i has covis poolCovis[i]), in pool order: n / k pairs from
// each of its k buckets (the remainder from its first buckets). Returns pool indices per set.
// Throws paircast::Error naming the bucket that is short.
std::vector<std::vector<size_t>> drawSets(const std::vector<double>& poolCovis,
                                          const std::vector<SweepSet>& sets, int n);

struct SweepConfig {
  // Checks what a user sets; throws OptionError naming the field.
  void validate() const;
  // Whether `task` (flow or depth) is in --downstream.
  bool finetunes(const std::string& task) const;
  // firstSeed .. firstSeed + seeds - 1.
  std::vector<int> seedIndices() const;
  // Whether flow is fine-tuned, on flow-style pairs of its own (finetuneFlowMotion "near").
  bool flowOnFlowStylePairs() const;
  // Whether a fine-tune reads depth's wide pairs (ds/train, ds/heldout): depth is fine-tuned, or
  // flow is, on those pairs (finetuneFlowMotion "walk").
  bool finetunesOnWidePairs() const;

  std::vector<std::string> scenes;   // training scenes (files, folders or .txt lists)
  std::vector<std::string> heldout;  // evaluation scenes; never in training (checked)
  LoadOptions load;                  // how every scene loads (its up axis: y, z or auto)
  std::string out;
  std::vector<std::string> modes = {"bin", "uniform"};
  // The defaults fit the shipped scenes on 2 cores in about 25 minutes (docs/covis_ablation.md).
  std::vector<double> centers = {0.15, 0.35, 0.55, 0.75, 0.95};
  // When given, the sets trained instead of every mode at every centre: "<mode>_<centre>", e.g.
  // bin_0.55 or uniform_0.50 (CroCo's own set: covis >= 0.5).
  std::vector<std::string> sets;
  int pairsPerSet = 512;
  int64_t steps = 700;
  std::string preset = "tiny";
  int imgSize = 112;  // training crop and probe size
  int patchSize = 16;
  int resolution = 128;        // rendered pair size
  int batchSize = 16;          // per process
  std::string device = "cpu";  // training: cpu or cuda (evaluation runs on the CPU)
  // Training and evaluation precision (TrainConfig::amp): auto, bf16 where the CPU has bf16
  // units. A killed and resumed sweep gives the same bytes at either precision.
  std::string amp = "auto";
  double blr = 6e-3;  // high for so few steps: at 1.5e-3, 700 steps barely move the encoder
  uint64_t seed = 0;  // the pool and held-out data; run k of a set trains with seed + k
  int seeds = 1;      // runs per set and baseline, for the intervals of results.csv
  // The seed index of the first run: this sweep trains seed indices firstSeed .. firstSeed +
  // seeds - 1, so that a study's seeds can run as parts, on several machines, and be merged
  // (mergeSweepParts, sweep_merge.h).
  int firstSeed = 0;
  // Baselines trained like every set, each at most once: "mae" (auto-completion: view 1 alone,
  // no reference view, on the pairs of referenceSet).
  std::vector<std::string> baselines;
  int jobs = 0;           // render threads (0: all cores)
  int workers = 2;        // trainer data threads
  int evalPairs = 64;     // held-out pairs at covis in [0.45, 0.55]
  int probeViews = 1024;  // held-out views in two halves, each fitting a probe for the other
  // The mechanism probes (mechanism_probe.h): pairs per held-out scene, covis in the band.
  int mechanismPairs = 48;
  double mechanismMinCovis = 0.3, mechanismMaxCovis = 0.7;
  double minWalkScale = 0.05;  // the pool's second views walk log-uniformly from this scale up
  // Fine-tuning of every run and of each seed's random weights (sweep_downstream.h): tasks
  // "flow" and "depth"; empty: none. Added to a finished sweep, only the fine-tunes run.
  std::vector<std::string> downstream;
  int64_t finetuneSteps = 200;  // per fine-tune, of finetuneBatch pairs
  int finetunePairs = 512;      // fine-tuning pairs from the training scenes (covis >= 0.5)
  int finetuneEvalPairs = 256;  // held-out pairs from the held-out scenes (covis 0.1-1)
  // Flow's pairs: "near", flow-style pairs of their own (generate_pairs --motion near, covis >=
  // 0.6), as many, for training and held out; "walk", depth's pairs above.
  std::string finetuneFlowMotion = "near";
  int finetuneBatch = 8;
  double finetuneBlr = 1e-2;
  bool reports = true;  // a dataset report per set
  bool progress = true;
  // Independent worker processes that share the training and fine-tuning, each run by one of
  // them, each worker on 1/processes of the threads (OMP_NUM_THREADS, else the cores; on 2
  // cores, 2 train 1.7x faster than 1).
  // They rerun `command` (the tool's own argv, argv[0] its executable) with --worker k.
  int processes = 1;
  std::vector<std::string> command;
  int worker = 0;  // 1..processes in a worker, 0 in the command a user runs
};

// The sets of a config: its `sets`, else every mode at every centre, mode by mode.
std::vector<SweepSet> planSets(const SweepConfig& config);

// One training run of a sweep: a set, or a baseline, with one of the seeds.
struct SweepRun {
  std::string name;           // the set's name, or the baseline's ("mae")
  std::string task;           // "croco", or "mae" for the auto-completion baseline
  std::string keysSet;        // the set whose pairs it trains on (sets/<keysSet>.keys)
  int seedIndex = 0;          // 0 .. seeds - 1
  uint64_t seed = 0;          // the model's initialisation, its masks and the data order
  std::filesystem::path dir;  // <out>/runs/<name>/seed-<k>
  std::string label() const;  // "bin_0.55 seed 1"
};

// "seed-<k>", the folder of a run's seed under runs/<name>/.
std::string seedFolder(int seedIndex);
// The reference set: the bin set nearest covis 0.5 (else the set nearest it). mae trains on its
// pairs, so that its views are those a cross-view model of that set completes, and the paper's
// claims are judged on it (results.json's "reference_set").
std::string referenceSet(const std::vector<SweepSet>& sets);
// The seed of run k of every set and baseline: --seed + k (so run 0 is --seed), which also
// initialises the random encoder of seed k.
uint64_t runSeed(const SweepConfig& c, int seedIndex);
// Every run, seed by seed: each set and then each baseline with the first seed, then the next.
// A sweep stopped part way can so be finished with a smaller --seeds, from the runs it has.
std::vector<SweepRun> planRuns(const SweepConfig& c, const std::vector<SweepSet>& sets);

// Runs (or resumes) the sweep; writes results.csv (a row per set and baseline, means and 95 %
// intervals over the seeds), results_runs.csv (a row per run), results.json, plots and
// summary.html in out.
// With WORLD_SIZE > 1 (torchrun-style variables, `out` on a folder every rank shares), rank 0
// samples the pool and evaluates, and every rank trains each set data-parallel; other ranks
// return {"rank": r, "runs_trained": n}.
nlohmann::json runCovisSweep(const SweepConfig& config);

}  // namespace paircast
