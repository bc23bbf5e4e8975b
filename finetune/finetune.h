// finetune: a pre-trained CroCo (or random weights) made into a flow, depth or relative-pose
// model on pairs with exact ground truth, through the training loop pretrain uses
// (trainer/training_loop.h), then measured on held-out pairs against a trivial baseline.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "finetune/tiling.h"
#include "model/downstream.h"
#include "trainer/trainer.h"

namespace paircast {

class Distributed;

struct FinetuneConfig {
  // Checks what a user sets; throws OptionError naming the field.
  void validate() const;

  // The loop's settings (batch, schedule, out, resume, device, amp, seed, checkpoints, log, NaN
  // guard); its data and task fields are unused.
  TrainConfig train;
  DownstreamConfig model;
  std::vector<std::string> data;      // shards written with --save-flow --save-depth
  std::vector<std::string> evalData;  // held-out shards (other scenes); empty: no evaluation
  size_t evalPairs = 0;               // held-out pairs measured (0: all)
  // Every this many steps, the held-out figures (the model's means) go into log.jsonl as a line
  // {"step", "heldout"}: learning curves. 0: at the end only.
  int64_t evalEvery = 0;
  // "random", or a pre-training checkpoint: the encoder, and the decoder of a cross-view one
  // (an mae checkpoint gives its encoder, the decoder stays random).
  std::string init = "random";
  bool colorJitter = true;
};

// finetune's base learning rate for `task` when --blr is not given, as docs/finetune.md
// recommends at batch 16 (lr = blr * batch / 256): 1e-2 for flow and depth, 2e-3 for pose.
double defaultFinetuneBlr(const std::string& task);

// The model a fine-tune starts from: the seed's random weights (torch::manual_seed(train.seed),
// as for a pre-training run of that seed), with `init`'s encoder, and decoder when it has one
// (initFromPretrained), loaded over them. `initialised` receives what was loaded.
DownstreamNet initialNet(const FinetuneConfig& config, std::string* initialised = nullptr);

// Trains and evaluates; returns the summary (also <out>/summary.json), with "heldout" (model and
// baseline figures, also <out>/heldout.json with each pair's). Data-parallel when WORLD_SIZE > 1.
nlohmann::json runFinetune(const FinetuneConfig& config);
nlohmann::json runFinetune(const FinetuneConfig& config, Distributed* dist);

// The held-out figures of a fine-tuned checkpoint alone (the summary's "heldout").
nlohmann::json evaluateCheckpoint(const std::string& checkpoint,
                                  const std::vector<std::string>& evalData, size_t evalPairs,
                                  const std::string& device);

// The loss of a task's output against a batch's truth (float32 scalar): flow, in units of
// `flowScale` pixels (the model's DownstreamConfig::flowScaleInUse()), with the DPT head
// naver/croco's LaplacianLossBounded (a = 0.25, b = 4, pixels with known flow under 1e4 px), with
// the linear head the squared error over pixels whose flow lands inside the other view's crop;
// depth, the L1 error of log-depth over pixels with depth; pose, ||R - R^||_F^2 +
// 100 ||t - t^||^2.
torch::Tensor finetuneLoss(const std::string& task, const std::string& head,
                           const torch::Tensor& out, const torch::Tensor& flow,
                           const torch::Tensor& depth, const torch::Tensor& pose,
                           double flowScale = 1.0);

// A fine-tuning checkpoint's model, on `device`, in eval mode: its configuration (croco_kwargs,
// task, head, head_kwargs) checked against its tensors before the model is built, then its
// weights loaded strictly. Throws paircast::Error naming the file.
DownstreamNet loadFinetuned(const std::string& checkpoint,
                            const torch::Device& device = torch::kCPU);

// finetune --predict: the model of `checkpoint` on one pair (depth: image 1 alone), written to
// `out`: flow .flo (and a colour-wheel PNG beside it, same name with .png), depth .exr (metres),
// pose .json; images larger than the training size are tiled by `tiling`. Returns what was
// written.
nlohmann::json predictToFile(const std::string& checkpoint, const std::string& image1,
                             const std::string& image2, const std::string& out,
                             const std::string& device, Tiling tiling = Tiling::kNearest);

}  // namespace paircast
