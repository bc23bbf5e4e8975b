// The CroCo pre-trainer: data in worker threads, AdamW with CroCo's schedule, atomic
// checkpoints that resume exactly, NaN guards, signals, a JSONL log and a loss curve.
#pragma once

#include <torch/torch.h>

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "model/croco_config.h"
#include "model/croco_net.h"

namespace paircast {

class Distributed;

struct TrainConfig {
  // Checks what a user sets (the model config too); throws OptionError naming the field.
  void validate() const;

  // Data: one or more of these. With one source, each epoch is a permutation of it. With
  // several, each sample comes from a source drawn with these weights (normalised; samples
  // within a source drawn with replacement), and an epoch is the sum of the sources' sizes.
  std::vector<std::string> shards;  // tar shards or glob patterns
  std::string keysFile;             // optional: train only on these shard keys (one per line)
  std::string crocoDir;             // CroCo layout with pairs.txt
  std::vector<std::string> live;    // scenes: pairs rendered on the fly
  int liveEpochPairs = 1000;        // pairs per "epoch" from --live
  double shardsWeight = 1.0, crocoWeight = 1.0, liveWeight = 1.0;

  CroCoConfig model = presetConfig("tiny");
  // What the model learns: "croco" completes view 1 from its visible patches and view 2;
  // "mae" (auto-completion) from its visible patches alone, with no reference view.
  std::string task = "croco";
  int batchSize = 16;
  int accumIter = 1;
  int epochs = 10;        // the schedule's length
  int64_t maxSteps = -1;  // stop after this many iterations (all epochs counted); -1: never
  // true (finetune): the warm-up and the cosine span the steps the run takes, maxSteps when it
  // comes before the last epoch's end, with the warm-up at most a tenth of them. false
  // (pretrain): they span `epochs`, so that a run stopped by maxSteps and resumed with a larger
  // one goes on as if it had never stopped.
  bool scheduleSpansRun = false;
  // Stop after this many iterations as a signal stops a run (a checkpoint, "interrupted"),
  // leaving the schedule as it is: a run cut into parts, resumed with --resume. -1: never.
  int64_t stopAfter = -1;
  double blr = 1.5e-4;  // lr = blr * effective batch / 256
  double minLr = 0.0;
  double warmupEpochs = 1.0;
  double weightDecay = 0.05;
  std::string out;
  bool resume = false;
  std::string device = "cpu";
  // Mixed precision (model/precision.h): "auto" (bf16 autocast on CUDA and on a CPU with bf16
  // units, float32 elsewhere), "bf16", "fp16" (CUDA only: autocast and a dynamic loss scale, as
  // torch.cuda.amp.GradScaler) or "none" (float32; TF32 matmuls on CUDA).
  std::string amp = "auto";
  bool fusedAdamW = true;  // on CUDA with LibTorch >= 2.1: AdamW as one fused kernel per group
  bool forceLossScaling = false;  // the fp16 loss scale on any device (tests)
  double initScale = 65536.0;     // GradScaler's defaults
  int scaleGrowthInterval = 2000;
  uint64_t seed = 0;
  int workers = 2;
  // What the loader's threads hand over: "float32" (cropped, jittered, normalised), "uint8"
  // (the crops as decoded, with their jitter draws, finished on the device: a quarter of the
  // bytes), or "auto": uint8 on CUDA, float32 on the CPU. The batches are the same either way
  // (float32's bit for bit, uint8's within float rounding).
  std::string batchFormat = "auto";
  int64_t saveEvery = 100;  // iterations between checkpoints (rounded up to accumIter)
  int keepEvery = 0;        // keep checkpoint-<epoch>.pth every K epochs (0: never)
  int64_t logEvery = 1;
  int64_t reconEvery = 0;  // write recon-latest.png every N iterations (0: never)
  int maxNanSkips = 5;     // consecutive non-finite losses before stopping
  bool progress = true;
  // Write an operator profile (trainer/op_profile.h) of every step after the first two to this
  // file at the end of the run (--profile); empty: none.
  std::string profile;
  int64_t debugNanAtStep = -1;  // fault injection for tests: this iteration's loss becomes NaN
};

// The pre-training forward pass of `task` ("croco" or "mae"): the model gets
// taskReference(task, img2), so for "mae" no reference, whatever img2 holds.
CroCoOutput pretrainForward(CroCoNet& model, const std::string& task, const torch::Tensor& img1,
                            const torch::Tensor& img2, const torch::Tensor& mask);

// lr at fractional epoch `e`: linear warmup, then half-cosine to minLr (CroCo's pretrain.py).
double learningRate(double baseLr, double minLr, double warmupEpochs, double epochs, double e);

// Parameter names with and without weight decay: none on biases and 1-D parameters (norms),
// as timm's param_groups_weight_decay, which CroCo's pretrain.py uses.
struct DecayGroups {
  std::vector<std::string> decay, noDecay;
};
DecayGroups weightDecayGroups(
    const std::vector<std::pair<std::string, torch::Tensor>>& namedParameters);

// Trains and returns the summary (also written to <out>/summary.json). Throws paircast::Error on
// bad input or when the loss stays non-finite (no checkpoint is written from poisoned weights).
// Data-parallel when WORLD_SIZE > 1: the process group is made from the environment.
nlohmann::json runPretrain(const TrainConfig& config);
// The same over a process group the caller owns (nullptr: one process), for callers that train
// several runs in a row: one rendezvous serves them all.
nlohmann::json runPretrain(const TrainConfig& config, Distributed* dist);

}  // namespace paircast
