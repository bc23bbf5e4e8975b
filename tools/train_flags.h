// The training loop's flags, which pretrain and finetune share (trainer/training_loop.h).
#pragma once

#include <CLI/CLI.hpp>

#include "trainer/trainer.h"

namespace paircast {

// Batch, schedule, resume, device and precision, seed, checkpoints, log and NaN guard.
inline void addLoopFlags(CLI::App& app, TrainConfig& c) {
  app.add_option("--batch-size", c.batchSize, "Pairs per iteration")->check(CLI::Range(1, 65536));
  app.add_option("--epochs", c.epochs, "Epochs of the schedule")->check(CLI::Range(1, 100000));
  app.add_option("--max-steps", c.maxSteps, "Stop after this many iterations");
  app.add_option("--blr", c.blr, "Base learning rate (lr = blr * effective batch / 256)");
  app.add_option("--min-lr", c.minLr, "Final learning rate of the cosine");
  app.add_option("--warmup-epochs", c.warmupEpochs, "Linear warmup, epochs");
  app.add_option("--weight-decay", c.weightDecay, "AdamW weight decay (not on biases and norms)");
  app.add_flag("--resume", c.resume, "Continue from OUT/checkpoint-last.pth");
  app.add_option("--device", c.device, "cpu or cuda")->check(CLI::IsMember({"cpu", "cuda"}));
  app.add_option("--amp", c.amp,
                 "auto (bf16 on CUDA and on CPUs with bf16 units, else float32), bf16, fp16 "
                 "(CUDA, with a dynamic loss scale) or none (float32)")
      ->check(CLI::IsMember({"auto", "bf16", "fp16", "none"}));
  app.add_option("--seed", c.seed, "Random seed");
  app.add_option("--save-every", c.saveEvery, "Iterations between checkpoints");
  app.add_option("--log-every", c.logEvery, "Iterations between log lines")
      ->check(CLI::Range(1, 1000000));
  app.add_flag("!--no-fused-adamw", c.fusedAdamW,
               "Step AdamW with LibTorch's own per-parameter operators instead of the fused "
               "kernel (CUDA, LibTorch >= 2.1) or the flat buffers (CPU)");
  app.add_option("--profile", c.profile,
                 "Write the time per operator, kind and stage of the steps after the first two "
                 "to this JSON file (docs/trainer.md)");
  app.add_option("--max-nan-skips", c.maxNanSkips, "Non-finite losses in a row before stopping");
}

}  // namespace paircast
