// The downstream stage of covis_sweep (--downstream flow,depth): every run's checkpoint, and
// each seed's random weights, fine-tuned with the same budget through the finetune command's
// code (finetune/finetune.h), then measured on held-out pairs, as CroCo's paper judges its
// pre-training. Fixed sets of fine-tuning pairs with flow and depth come from the training
// scenes: depth's wide pairs (ds/train), and flow's flow-style pairs (ds/flow-train) unless
// --finetune-flow-motion walk gives flow depth's; the held-out pairs, of the same kinds, from the
// held-out scenes (ds/heldout at covis 0.1-1, ds/flow-heldout). Depth's columns are over its
// held-out pairs at covis 0.3-0.7, flow's over every flow-style pair; the whole range goes into
// the by-covis breakdown. Each fine-tune is a folder of its run
// (finetune-<task>/), kept and reused like the runs, so a killed sweep resumes fine-tune by
// fine-tune.
#pragma once

#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "finetune/finetune.h"
#include "model/croco_config.h"
#include "sweep/covis_sweep.h"

namespace paircast {

class Distributed;

// The held-out band the columns are measured on, and the by-covis bins' width.
constexpr double kDownstreamBandLo = 0.3, kDownstreamBandHi = 0.7, kDownstreamBinWidth = 0.1;
// Flow-style pairs' least covis (as docs/finetune.md's pilot, generate_pairs --min-covis 0.6).
constexpr double kFlowStyleMinCovis = 0.6;
// The wide pairs' least covis: CroCo's band for the fine-tuning pairs, a wider one held out.
constexpr double kWideTrainMinCovis = 0.5, kWideHeldoutMinCovis = 0.1;

// The fine-tuning data, generated once (with --save-flow --save-depth) and then reused.
struct DownstreamData {
  std::string trainShards, heldoutShards;  // glob patterns
  size_t trainPairs = 0;
  std::map<std::string, double> heldoutCovis;  // held-out pair key -> its covis
  // Flow's pairs (--finetune-flow-motion): flow-style ones (near), or the ones above (walk); and
  // the held-out band its columns average over (near: every flow-style pair).
  std::string flowTrainShards, flowHeldoutShards;
  size_t flowTrainPairs = 0;
  std::map<std::string, double> flowHeldoutCovis;
  double flowBandLo = kDownstreamBandLo, flowBandHi = kDownstreamBandHi;
};

// Generates ds/train (--finetune-pairs from the training scenes, covis >= 0.5, CroCo's band)
// and ds/heldout (--finetune-eval-pairs from the held-out scenes, covis in [0.1, 1]) when a
// fine-tune reads them (SweepConfig::finetunesOnWidePairs); and, when
// flow is fine-tuned on flow-style pairs, ds/flow-train and ds/flow-heldout (as many, with
// generate_pairs --motion near, covis >= 0.6); unless a previous sweep made them with the same
// settings; then opens them. Throws paircast::Error naming the folder when a part gives too few
// pairs.
DownstreamData prepareDownstreamData(const SweepConfig& config,
                                     const std::vector<std::string>& trainScenes,
                                     const std::vector<std::string>& heldoutScenes);
// Opens the data rank 0 prepared (the other ranks of a multi-process sweep), without writing.
// The parts no fine-tune reads are left closed: their fields stay empty.
DownstreamData openDownstreamData(const SweepConfig& config);

// One fine-tune: a task from a run's checkpoint, or from a seed's random weights.
struct FinetuneJob {
  std::string label;          // "bin_0.55 seed 1 flow"
  std::string run;            // the run's name ("bin_0.55", "mae"), or "random"
  std::string task;           // flow or depth
  std::string init;           // the run's checkpoint, or "random"
  uint64_t seed = 0;          // the run's: its random weights, jitter, crops and data order
  std::filesystem::path dir;  // <run>/finetune-<task>
};

// The folder of a run's fine-tune for `task`.
std::filesystem::path finetuneDir(const std::filesystem::path& runDir, const std::string& task);

// Every fine-tune, seed by seed: the seed's random weights (runs/random/seed-<k>), then each of
// the seed's runs, each for every task of --downstream.
std::vector<FinetuneJob> planFinetunes(const SweepConfig& config,
                                       const std::vector<SweepRun>& runs);

// The finetune command's configuration of a job: the linear heads (the DPT head needs 16-pixel
// patches), the sweep's model, --finetune-steps of --finetune-batch, resumed when it exists.
FinetuneConfig finetuneConfig(const SweepConfig& config, const CroCoConfig& model,
                              const DownstreamData& data, const FinetuneJob& job, int worldSize);

// Fine-tunes (or resumes) a job unless it is complete. Every rank of a multi-process sweep calls
// it for every job, in the same order; rank 0 alone removes a fine-tune made with other
// settings (then all wait for it). Returns whether it fine-tuned (false: it was complete).
bool runFinetuneJob(const SweepConfig& config, const CroCoConfig& model, const DownstreamData& data,
                    const FinetuneJob& job, Distributed* dist);

// A run's downstream figures from its fine-tunes' heldout.json: ft_flow_aepe,
// ft_flow_aepe_covisible, ft_flow_px3, ft_depth_delta1, ft_depth_absrel (means over the held-out
// pairs at covis 0.3-0.7; flow's over every flow-style pair when it has its own), ft_flow_aepe_all
// (all of flow's held-out pairs) and ft_flow_by_covis (bins of 0.1). With `baseline`, the trivial
// baseline's (zero flow, constant depth) instead. Empty for a task not fine-tuned.
nlohmann::json downstreamFigures(const SweepConfig& config, const DownstreamData& data,
                                 const std::filesystem::path& runDir, bool baseline = false);

}  // namespace paircast
