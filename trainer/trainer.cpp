#include "trainer/trainer.h"

#include <ATen/CPUGeneratorImpl.h>

#include <cmath>
#include <filesystem>
#include <map>

#include "model/checkpoint.h"
#include "model/croco_net.h"
#include "model/precision.h"
#include "model/reconstruct.h"
#include "trainer/batch_loader.h"
#include "trainer/distributed.h"
#include "trainer/pair_dataset.h"
#include "trainer/training_loop.h"
#include "util/error.h"
#include "util/image_io.h"

namespace paircast {
namespace fs = std::filesystem;

DecayGroups weightDecayGroups(const std::vector<std::pair<std::string, torch::Tensor>>& named) {
  DecayGroups g;
  for (const auto& [name, t] : named) {
    const bool bias = name.size() >= 5 && name.compare(name.size() - 5, 5, ".bias") == 0;
    (t.dim() <= 1 || bias ? g.noDecay : g.decay).push_back(name);
  }
  return g;
}

CroCoOutput pretrainForward(CroCoNet& model, const std::string& task, const torch::Tensor& img1,
                            const torch::Tensor& img2, const torch::Tensor& mask) {
  return model->forward(img1, taskReference(task, img2), mask);
}

double learningRate(double baseLr, double minLr, double warmupEpochs, double epochs, double e) {
  if (e < warmupEpochs) return baseLr * e / warmupEpochs;
  const double span = std::max(1e-12, epochs - warmupEpochs);
  return minLr +
         (baseLr - minLr) * 0.5 * (1.0 + std::cos(M_PI * std::min(1.0, (e - warmupEpochs) / span)));
}

void TrainConfig::validate() const {
  if (shards.empty() && crocoDir.empty() && live.empty())
    throw OptionError("data",
                      "give a data source: shards, a CroCo folder or live scenes (or "
                      "several, with weights)");
  checkAmp(amp);
  if (task != "croco" && task != "mae")
    throw OptionError("task", "the task must be croco or mae, not '" + task + "'");
  if (out.empty()) throw OptionError("out", "an output folder is required");
  if (batchSize < 1) throw OptionError("batch_size", "the batch size must be >= 1");
  if (accumIter < 1) throw OptionError("accum_iter", "accumulation steps must be >= 1");
  if (epochs < 1) throw OptionError("epochs", "epochs must be >= 1");
  if (workers < 1) throw OptionError("workers", "data workers must be >= 1");
  if (device != "cpu" && device != "cuda")
    throw OptionError("device", "the device must be cpu or cuda, not '" + device + "'");
  model.validate();
}

nlohmann::json runPretrain(const TrainConfig& c) {
  if (c.device != "cpu" && c.device != "cuda")
    throw OptionError("device", "the device must be cpu or cuda, not '" + c.device + "'");
  const std::unique_ptr<Distributed> dist = Distributed::fromEnvironment(c.device);
  return runPretrain(c, dist.get());
}

namespace {

// CroCo pre-training as a task of the shared loop: the data sources through BatchLoader, the
// masked reconstruction loss, and reconstruction grids.
class PretrainTask : public TrainingTask {
 public:
  explicit PretrainTask(const TrainConfig& c) : c_(c) { openDataSources(); }

  std::string tool() const override { return "pretrain"; }

  std::shared_ptr<torch::nn::Module> buildModel() override {
    model_ = CroCoNet(c_.model);
    return model_.ptr();
  }

  std::vector<std::pair<std::string, torch::Tensor>> trainable() override {
    std::vector<std::pair<std::string, torch::Tensor>> named;
    for (const auto& p : model_->named_parameters()) named.emplace_back(p.key(), p.value());
    return named;
  }

  int64_t startData(int64_t iter, int rank, int world) override {
    loader_ = std::make_unique<BatchLoader>(sources_, c_, iter, rank, world, livePosition_);
    return loader_->perEpoch();
  }

  void fetch(int64_t iter) override { batch_ = loader_->get(iter); }

  torch::Tensor loss(const torch::Device& device) override {
    // On CUDA the batch is pinned uint8, finished there; the loss's .item() waits for the
    // copies before the loader may fill the buffer again.
    const Batch b = finishBatch(batch_, device);
    auto out = pretrainForward(model_, c_.task, b.img1, b.img2, b.mask);
    return maskedMse(out.prediction.to(torch::kFloat32), out.mask, out.target);
  }

  void save(const std::string& path, int64_t epoch, const nlohmann::json& extra,
            const std::map<std::string, torch::Tensor>& tensors) override {
    saveCheckpoint(path, model_, epoch, extra, tensors);
  }

  void restore(const Checkpoint& ck, const std::string& path) override {
    if (ck.hasArgs && configFromJson(ck.args, path).enc_embed_dim != c_.model.enc_embed_dim)
      throw Error(path, "checkpoint was trained with other hyper-parameters than the model config");
    if (trainedTask(ck) != c_.task)
      throw Error(path, "checkpoint was trained on task " + trainedTask(ck) + ", not " + c_.task +
                            "; use another --out");
    loadStateDictStrict(model_, ck.model, path);
    livePosition_ = ck.extra.value("live_position", uint64_t{0});
  }

  nlohmann::json checkpointEntries() const override {
    return {{"live_position", loader_ ? loader_->livePosition() : 0}, {"task", c_.task}};
  }

  void afterStep(int64_t iter, const torch::Device& device) override {
    if (c_.reconEvery > 0 && iter % c_.reconEvery == 0 && reconData_) writeReconstruction(device);
  }

  void summarise(nlohmann::json& s) override {
    s["task"] = c_.task;
    s["pairs_by_source"] = loader_->counts();
  }

 private:
  void openDataSources() {
    if (!c_.shards.empty()) {
      shardSet_ = std::make_unique<PairDataset>(PairDataset::fromShards(c_.shards));
      if (!c_.keysFile.empty()) shardSet_->restrictTo(c_.keysFile);
      sources_.push_back({shardSet_.get(), c_.shardsWeight, "--data"});
    }
    if (!c_.crocoDir.empty()) {
      crocoSet_ = std::make_unique<PairDataset>(PairDataset::fromCrocoDir(c_.crocoDir));
      sources_.push_back({crocoSet_.get(), c_.crocoWeight, "--croco-dir " + c_.crocoDir});
    }
    if (!c_.live.empty()) sources_.push_back({nullptr, c_.liveWeight, "--live"});
    reconData_ = shardSet_ ? shardSet_.get() : crocoSet_.get();
  }

  // recon-latest.png: the first pair of the disk data with a fixed mask.
  void writeReconstruction(const torch::Device& device) {
    torch::NoGradGuard ng;
    model_->eval();
    auto [x, y] = reconData_->load(0);
    // A fixed mask from its own generator: training's random stream is left untouched.
    auto gen = at::make_generator<at::CPUGeneratorImpl>(c_.seed);
    auto mask = torch::argsort(torch::rand({1, c_.model.numPatches()}, gen), 1, false) <
                c_.model.numMasked();
    const Reconstruction r = reconstructWith(
        model_, imageTensor(x, c_.model.img_size).to(device),
        taskReference(c_.task, imageTensor(y, c_.model.img_size).to(device)), mask.to(device));
    writeImage((fs::path(c_.out) / "recon-latest.png").string(), r.grid);
  }

  const TrainConfig& c_;
  // Data. Members are declared in the order they are made, so that they are destroyed in
  // reverse: the loader's threads stop before the datasets they read go away.
  std::unique_ptr<PairDataset> shardSet_, crocoSet_;
  std::vector<Source> sources_;
  const PairDataset* reconData_ = nullptr;  // the recon grid's pair
  CroCoNet model_{nullptr};
  uint64_t livePosition_ = 0;
  std::unique_ptr<BatchLoader> loader_;
  Batch batch_;
};

}  // namespace

nlohmann::json runPretrain(const TrainConfig& c, Distributed* dist) {
  c.validate();
  PretrainTask task(c);
  return runTraining(c, task, dist);
}

}  // namespace paircast
