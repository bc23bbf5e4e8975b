// The training loop that pretrain and finetune share: AdamW with CroCo's schedule (no weight decay
// on biases and norms, lr = blr * effective batch / 256, warmup then half-cosine), gradient
// accumulation, atomic checkpoints that resume exactly (weights, optimizer, step, random state),
// NaN guards, SIGINT/SIGTERM, a JSONL log, a loss curve, the progress line, CUDA with mixed
// precision, and data parallelism over a process group. What is trained, on which data and with
// which loss is a TrainingTask's.
#pragma once

#include <torch/torch.h>

#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "model/checkpoint.h"
#include "trainer/trainer.h"

namespace paircast {

class Distributed;

class TrainingTask {
 public:
  virtual ~TrainingTask() = default;
  // The command's name, for messages, the progress line and the log ("pretrain", "finetune").
  virtual std::string tool() const = 0;
  // Builds the model (after the loop seeds torch with the run's seed) and returns its root.
  virtual std::shared_ptr<torch::nn::Module> buildModel() = 0;
  // The parameters to train, by name, each once (shared modules give the same tensor twice).
  virtual std::vector<std::pair<std::string, torch::Tensor>> trainable() = 0;
  // Starts the data at iteration `iter` for rank `rank` of `world`; returns iterations per epoch.
  virtual int64_t startData(int64_t iter, int rank, int world) = 0;
  // Takes the batch of iteration `iter` (the loop times this as the wait for data).
  virtual void fetch(int64_t iter) = 0;
  // The loss of the fetched batch, float32, computed on `device` under the loop's autocast.
  virtual torch::Tensor loss(const torch::Device& device) = 0;
  // Writes a checkpoint of the model with the loop's `extra` entries and `tensors` (optimizer
  // state, random state).
  virtual void save(const std::string& path, int64_t epoch, const nlohmann::json& extra,
                    const std::map<std::string, torch::Tensor>& tensors) = 0;
  // Loads this run's OUT/checkpoint-last.pth into the model, and the task's own entries (a data
  // position); throws paircast::Error naming `path` when it belongs to another task or model.
  virtual void restore(const Checkpoint& checkpoint, const std::string& path) = 0;
  // The task's own entries of a checkpoint (what it was trained on, a data position).
  virtual nlohmann::json checkpointEntries() const { return nlohmann::json::object(); }
  // After each step (iterations done so far), on the lead rank: images, evaluations.
  virtual void afterStep(int64_t /*iter*/, const torch::Device& /*device*/) {}
  // After each step, on the lead rank: entries of a line of its own in the log (held-out figures
  // measured during the run), or null for none. The line takes the step's "step"; on resume it
  // is kept or cut with the loss lines.
  virtual nlohmann::json logAfterStep(int64_t /*iter*/, const torch::Device& /*device*/) {
    return nullptr;
  }
  // Task entries of the run's summary.
  virtual void summarise(nlohmann::json& /*summary*/) {}
};

// Trains `task` with the loop settings of `config` (batch, schedule, out, resume, device, amp,
// seed, checkpoints, log, NaN guard), over `dist` (nullptr: one process). Returns the summary,
// also written to <out>/summary.json.
nlohmann::json runTraining(const TrainConfig& config, TrainingTask& task, Distributed* dist);

}  // namespace paircast
