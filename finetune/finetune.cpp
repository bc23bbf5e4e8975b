#include "finetune/finetune.h"

#include <algorithm>
#include <filesystem>

#include "finetune/evaluate.h"
#include "finetune/finetune_data.h"
#include "model/checkpoint.h"
#include "model/precision.h"
#include "trainer/distributed.h"
#include "trainer/training_loop.h"
#include "util/atomic_file.h"
#include "util/error.h"
#include "util/flo_io.h"
#include "util/image_io.h"
#include "util/random.h"

namespace paircast {
namespace fs = std::filesystem;

void FinetuneConfig::validate() const {
  if (data.empty())
    throw OptionError("data", "give shards written with generate_pairs --save-flow --save-depth");
  if (train.out.empty()) throw OptionError("out", "an output folder is required");
  if (train.batchSize < 1) throw OptionError("batch_size", "the batch size must be >= 1");
  if (train.epochs < 1) throw OptionError("epochs", "epochs must be >= 1");
  if (evalEvery < 0) throw OptionError("eval_every", "--eval-every must be >= 0");
  if (evalEvery > 0 && evalData.empty())
    throw OptionError("eval_every", "--eval-every needs --eval-data");
  if (train.device != "cpu" && train.device != "cuda")
    throw OptionError("device", "the device must be cpu or cuda, not '" + train.device + "'");
  checkAmp(train.amp);
  if (init.empty()) throw OptionError("init", "--init takes random or a checkpoint");
  model.validate();
}

torch::Tensor finetuneLoss(const std::string& task, const std::string& head,
                           const torch::Tensor& out, const torch::Tensor& flow,
                           const torch::Tensor& depth, const torch::Tensor& pose,
                           double flowScale) {
  if (task == "flow") {
    const auto finite = torch::isfinite(flow).all(1);  // [B, S, S]
    const auto known = torch::where(finite.unsqueeze(1), flow, torch::zeros_like(flow));
    const auto valid = finite & (known.pow(2).sum(1).sqrt() < 1e4);
    // Both in units of flowScale pixels (DownstreamConfig::flowScale).
    const auto gt = known / flowScale;
    const auto pred = out.narrow(1, 0, 2) / flowScale;
    if (head == "linear") {
      // The squared error where the flow lands inside the other view's crop: the pixels whose
      // flow the images show (out-of-frame flows reach hundreds of pixels and swamp it).
      const auto inFrame = valid & landsInFrame(known);
      return (gt - pred).pow(2).mean(1).masked_select(inFrame).mean();
    }
    // LaplacianLossBounded: the third channel is a confidence in [a, b] = [0.25, 4].
    const auto conf = 3.75 * torch::sigmoid(out.select(1, 2)) + 0.25;
    return ((gt - pred).abs().sum(1) / conf + torch::log(conf)).masked_select(valid).mean();
  }
  if (task == "depth") {
    const auto valid = (depth > 0) & torch::isfinite(depth);
    const auto logDepth = torch::log(torch::where(valid, depth, torch::ones_like(depth)));
    return (out - logDepth).abs().masked_select(valid).mean();
  }
  const auto rotation = (out.narrow(1, 0, 9) - pose.narrow(1, 0, 9)).pow(2).sum(1);
  const auto translation = (out.narrow(1, 9, 3) - pose.narrow(1, 9, 3)).pow(2).sum(1);
  return (rotation + 100.0 * translation).mean();
}

namespace {

// The median valid depth of view 1 over the first pairs: the constant-depth baseline.
double medianDepth(const TruthPairs& data, size_t pairs = 16) {
  std::vector<float> values;
  for (size_t i = 0; i < std::min(pairs, data.size()); ++i)
    for (float z : data.load(i).depth1.data)
      if (z > 0 && std::isfinite(z)) values.push_back(z);
  if (values.empty()) return 1.0;
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

nlohmann::json heldOutReport(DownstreamNet& net, const TruthPairs& eval, size_t evalPairs,
                             double constantDepth, const torch::Device& device) {
  const HeldOutFigures f = evaluateHeldOut(net, eval, evalPairs, constantDepth, device);
  return {{"model", summariseFigures(f.pairs)},
          {"baseline", summariseFigures(f.baseline)},
          {"constant_depth", constantDepth},
          {"per_pair", {{"model", f.pairs}, {"baseline", f.baseline}}}};
}

// A fine-tuning run as a task of the shared loop.
class FinetuneTask : public TrainingTask {
 public:
  explicit FinetuneTask(const FinetuneConfig& c) : c_(c), data_(TruthPairs::fromShards(c.data)) {
    if (data_.side() < c.model.croco.img_size)
      throw Error(c.data[0], "pairs of " + std::to_string(data_.side()) +
                                 " pixels are smaller than the training size " +
                                 std::to_string(c.model.croco.img_size) + " (--img-size)");
    if (!c.evalData.empty())
      eval_ = std::make_unique<TruthPairs>(TruthPairs::fromShards(c.evalData));
    augment_.size = c.model.croco.img_size;
    augment_.colorJitter = c.colorJitter;
    augment_.swap = c.model.task == "pose";
  }

  std::string tool() const override { return "finetune"; }

  std::shared_ptr<torch::nn::Module> buildModel() override {
    net_ = initialNet(c_, &initialised_);
    return net_.ptr();
  }

  std::vector<std::pair<std::string, torch::Tensor>> trainable() override {
    return net_->uniqueParameters();
  }

  int64_t startData(int64_t, int rank, int world) override {
    rank_ = rank;
    world_ = world;
    const size_t global = static_cast<size_t>(c_.train.batchSize) * world;
    if (data_.size() < global)
      throw Error(c_.data[0], "holds " + std::to_string(data_.size()) +
                                  " pairs, fewer than one batch of " + std::to_string(global));
    return static_cast<int64_t>(data_.size() / global);
  }

  void fetch(int64_t iter) override {
    const int64_t perEpoch = static_cast<int64_t>(data_.size()) / (c_.train.batchSize * world_);
    const std::vector<size_t>& order = epochOrder(iter / perEpoch);
    const size_t B = c_.train.batchSize;
    const size_t first = static_cast<size_t>(iter % perEpoch) * B * world_ + rank_ * B;
    const std::vector<size_t> pairs(order.begin() + first, order.begin() + first + B);
    batch_ = makeTruthBatch(data_, pairs, augment_, c_.train.seed, iter, rank_ * B);
  }

  torch::Tensor loss(const torch::Device& device) override {
    device_ = device;
    const TruthBatch b = batch_.to(device);
    const torch::Tensor out = net_->forward(b.img1, b.img2).to(torch::kFloat32);
    return finetuneLoss(c_.model.task, c_.model.head, out, b.flow, b.depth, b.pose,
                        c_.model.flowScaleInUse());
  }

  void save(const std::string& path, int64_t epoch, const nlohmann::json& extra,
            const std::map<std::string, torch::Tensor>& tensors) override {
    nlohmann::json entries = net_->checkpointEntries();
    entries.update(extra);
    entries["init"] = c_.init;
    saveCheckpoint(path, net_->state(), epoch, entries, tensors);
  }

  void restore(const Checkpoint& ck, const std::string& path) override {
    const DownstreamConfig theirs = downstreamConfigOf(ck, path);
    if (theirs.task != c_.model.task || theirs.head != c_.model.head)
      throw Error(path, "checkpoint of task " + theirs.task + " (head " + theirs.head + "), not " +
                            c_.model.task + " (head " + c_.model.head + "); use another --out");
    if (theirs.task == "flow" && theirs.flowScaleInUse() != c_.model.flowScaleInUse())
      throw Error(path, "checkpoint of flow scale " + std::to_string(theirs.flowScaleInUse()) +
                            ", not " + std::to_string(c_.model.flowScaleInUse()) +
                            " (--flow-scale); use another --out");
    if (configToJson(theirs.croco) != configToJson(c_.model.croco))
      throw Error(path, "checkpoint of another model (" + configToJson(theirs.croco).dump() +
                            "); use the --preset and --img-size it was trained with");
    loadStateDictStrict(*net_, ck.model, path);
  }

  nlohmann::json logAfterStep(int64_t iter, const torch::Device& device) override {
    if (c_.evalEvery <= 0 || !eval_ || iter % c_.evalEvery != 0) return nullptr;
    const HeldOutFigures f = evaluateHeldOut(net_, *eval_, c_.evalPairs, constantDepth(), device);
    return {{"heldout", summariseFigures(f.pairs)}};
  }

  void summarise(nlohmann::json& s) override {
    s["task"] = c_.model.task;
    s["head"] = c_.model.head;
    s["init"] = c_.init;
    s["initialised"] = initialised_;
    if (c_.model.head == "dpt") s["hooks"] = net_->hooks();
    if (!eval_ || rank_ != 0 || s.value("interrupted", false)) return;
    nlohmann::json report = heldOutReport(net_, *eval_, c_.evalPairs, constantDepth(), device_);
    writeFileAtomic((fs::path(c_.train.out) / "heldout.json").string(), report.dump(1) + "\n");
    report.erase("per_pair");
    s["heldout"] = report;
  }

 private:
  // The depth baseline (medianDepth of the training pairs), measured once for the curve's
  // points and the final figures.
  double constantDepth() {
    if (constantDepth_ < 0) constantDepth_ = medianDepth(data_);
    return constantDepth_;
  }

  // The permutation of the pairs in epoch `epoch`, from the run's seed.
  const std::vector<size_t>& epochOrder(int64_t epoch) {
    if (epoch != orderEpoch_) {
      order_.resize(data_.size());
      for (size_t i = 0; i < order_.size(); ++i) order_[i] = i;
      Rng rng(mixSeed(c_.train.seed, "finetune-epoch", static_cast<uint64_t>(epoch)));
      for (size_t i = order_.size(); i > 1; --i) std::swap(order_[i - 1], order_[rng.below(i)]);
      orderEpoch_ = epoch;
    }
    return order_;
  }

  const FinetuneConfig& c_;
  TruthPairs data_;
  std::unique_ptr<TruthPairs> eval_;
  TruthAugment augment_;
  DownstreamNet net_{nullptr};
  std::string initialised_ = "nothing (random weights)";
  int rank_ = 0, world_ = 1;
  std::vector<size_t> order_;
  int64_t orderEpoch_ = -1;
  TruthBatch batch_;
  torch::Device device_{torch::kCPU};
  double constantDepth_ = -1;  // the depth baseline, once measured
};

torch::Device deviceNamed(const std::string& name) {
  if (name == "cpu") return torch::kCPU;
  if (name != "cuda")
    throw OptionError("device", "the device must be cpu or cuda, not '" + name + "'");
  if (!torch::cuda::is_available())
    throw OptionError("device", "device cuda, but this LibTorch has no CUDA device");
  return torch::Device(torch::kCUDA, 0);
}

}  // namespace

DownstreamNet loadFinetuned(const std::string& checkpoint, const torch::Device& device) {
  const Checkpoint ck = loadCheckpoint(checkpoint);
  const DownstreamConfig config = downstreamConfigOf(ck, checkpoint);
  checkModelFitsState(config.croco, ck.model, checkpoint, config.headParameters());
  DownstreamNet net(config);
  loadStateDictStrict(*net, ck.model, checkpoint);
  net->to(device);
  net->eval();
  return net;
}

DownstreamNet initialNet(const FinetuneConfig& c, std::string* initialised) {
  torch::manual_seed(c.train.seed);
  DownstreamNet net(c.model);
  if (c.init != "random") {
    const std::string loaded = net->initFromPretrained(loadCheckpoint(c.init), c.init);
    if (initialised) *initialised = loaded;
  }
  return net;
}

nlohmann::json runFinetune(const FinetuneConfig& c, Distributed* dist) {
  c.validate();
  FinetuneTask task(c);
  TrainConfig train = c.train;
  train.scheduleSpansRun = true;
  return runTraining(train, task, dist);
}

double defaultFinetuneBlr(const std::string& task) {
  return task == "pose" ? 2e-3 : 1e-2;
}

nlohmann::json runFinetune(const FinetuneConfig& c) {
  if (c.train.device != "cpu" && c.train.device != "cuda")
    throw OptionError("device", "the device must be cpu or cuda, not '" + c.train.device + "'");
  const std::unique_ptr<Distributed> dist = Distributed::fromEnvironment(c.train.device);
  return runFinetune(c, dist.get());
}

nlohmann::json evaluateCheckpoint(const std::string& checkpoint,
                                  const std::vector<std::string>& evalData, size_t evalPairs,
                                  const std::string& deviceName) {
  const torch::Device device = deviceNamed(deviceName);
  DownstreamNet net = loadFinetuned(checkpoint, device);
  const TruthPairs eval = TruthPairs::fromShards(evalData);
  nlohmann::json report = heldOutReport(net, eval, evalPairs, medianDepth(eval), device);
  report.erase("per_pair");
  return report;
}

nlohmann::json predictToFile(const std::string& checkpoint, const std::string& image1,
                             const std::string& image2, const std::string& out,
                             const std::string& deviceName, Tiling tiling) {
  const torch::Device device = deviceNamed(deviceName);
  DownstreamNet net = loadFinetuned(checkpoint, device);
  const std::string& task = net->config().task;
  const Image8 a = readImage8(image1);
  torch::Tensor b;
  if (task != "depth") {
    const Image8 second = readImage8(image2);
    if (second.width != a.width || second.height != a.height)
      throw Error(image2, "differs in size from " + image1);
    b = normalizedImage(second).to(device);
  }
  const torch::Tensor pred =
      predict(net, normalizedImage(a).to(device), b, tiling).to(torch::kCPU).to(torch::kFloat32);
  nlohmann::json wrote = {{"task", task}, {"out", out}};
  if (task == "pose") {
    const auto v = pred[0];
    std::vector<std::vector<double>> R(3, std::vector<double>(3));
    for (int r = 0; r < 3; ++r)
      for (int k = 0; k < 3; ++k) R[r][k] = v[r * 3 + k].item<double>();
    const nlohmann::json pose = {
        {"R", R},
        {"t", {v[9].item<double>(), v[10].item<double>(), v[11].item<double>()}},
        {"frame", "view 2's camera in view 1's (OpenCV axes)"}};
    writeFileAtomic(out, pose.dump(1) + "\n");
    return wrote;
  }
  const torch::Tensor maps = (task == "depth" ? torch::exp(pred[0]) : pred[0].narrow(0, 0, 2))
                                 .permute({1, 2, 0})
                                 .contiguous();
  ImageF image(a.width, a.height, static_cast<int>(maps.size(2)));
  std::memcpy(image.data.data(), maps.data_ptr<float>(), image.size() * sizeof(float));
  if (task == "depth") {
    writeExr(out, image);
    return wrote;
  }
  const std::vector<unsigned char> flo = encodeFlo(image);
  writeFileAtomic(out, std::string_view(reinterpret_cast<const char*>(flo.data()), flo.size()));
  const std::string png = fs::path(out).replace_extension(".png").string();
  writeImage(png, flowColours(image));
  wrote["png"] = png;
  return wrote;
}

}  // namespace paircast
