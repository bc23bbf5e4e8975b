#include "trainer/training_loop.h"

#include <ATen/CPUGeneratorImpl.h>
#include <link.h>
#include <signal.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <set>

#include "model/autocast.h"
#include "model/torch_compat.h"
#include "trainer/distributed.h"
#include "trainer/flat_adamw.h"
#include "trainer/fused_adamw.h"
#include "trainer/grad_scaler.h"
#include "trainer/op_profile.h"
#include "util/atomic_file.h"
#include "util/blas_core.h"
#include "util/error.h"
#include "util/heap.h"
#include "util/plot.h"
#include "util/progress_line.h"
#include "util/timer.h"

namespace paircast {
namespace fs = std::filesystem;

namespace {

using Clock = SteadyClock;
constexpr auto since = secondsSince;
// The first steps of a run allocate and warm caches; a profile leaves them out.
constexpr int64_t kProfileWarmupSteps = 2;

std::atomic<int> gSignal{0};
// The handlers StopSignals replaced, called too: a worker process's own stop flag then hears a
// signal that lands after the loop's last look.
using Handler = void (*)(int);
std::atomic<Handler> gOuterInt{nullptr}, gOuterTerm{nullptr};
void onSignal(int sig) {
  gSignal = sig;
  const Handler outer = sig == SIGINT ? gOuterInt.load() : gOuterTerm.load();
  if (outer) outer(sig);
}

// AdamW state, by parameter position, as "optimizer/state/<i>/{exp_avg,exp_avg_sq,step}".
auto stateKey(const torch::Tensor& p) {
  return torch_compat::optimizerStateKey(p);
}

std::map<std::string, torch::Tensor> optimizerTensors(torch::optim::AdamW& opt,
                                                      const std::vector<torch::Tensor>& params) {
  std::map<std::string, torch::Tensor> out;
  auto& state = opt.state();
  for (size_t i = 0; i < params.size(); ++i) {
    auto it = state.find(stateKey(params[i]));
    if (it == state.end()) continue;
    auto& s = static_cast<torch::optim::AdamWParamState&>(*it->second);
    const std::string base = "optimizer/state/" + std::to_string(i) + "/";
    out[base + "exp_avg"] = s.exp_avg();
    out[base + "exp_avg_sq"] = s.exp_avg_sq();
    out[base + "step"] = torch::tensor(static_cast<int64_t>(s.step()));
  }
  return out;
}

void restoreOptimizer(torch::optim::AdamW& opt, const std::vector<torch::Tensor>& params,
                      const std::map<std::string, torch::Tensor>& tensors,
                      const std::string& source) {
  auto& state = opt.state();
  for (size_t i = 0; i < params.size(); ++i) {
    const std::string base = "optimizer/state/" + std::to_string(i) + "/";
    auto a = tensors.find(base + "exp_avg"), b = tensors.find(base + "exp_avg_sq"),
         s = tensors.find(base + "step");
    if (a == tensors.end() || b == tensors.end() || s == tensors.end()) continue;
    if (a->second.sizes() != params[i].sizes())
      throw Error(source, "optimizer state " + base + " has the wrong shape");
    auto st = std::make_unique<torch::optim::AdamWParamState>();
    st->step(s->second.item<int64_t>());
    st->exp_avg(a->second.to(params[i].device()).clone());
    st->exp_avg_sq(b->second.to(params[i].device()).clone());
    state[stateKey(params[i])] = std::move(st);
  }
}

void writeLossCurve(const std::string& path,
                    const std::vector<std::pair<int64_t, double>>& points) {
  if (points.size() < 2) return;
  plot::Series loss;
  loss.label = "loss";
  loss.markers = false;
  for (const auto& [step, value] : points) loss.x.push_back(step), loss.y.push_back(value);
  writeFileAtomic(path, plot::lines({loss}, {"training loss by step", "step", "loss", 640, 360}));
}

// SIGINT and SIGTERM, while training: the loop saves a checkpoint at the next step and stops.
class StopSignals {
 public:
  StopSignals() {
    gSignal = 0;
    oldInt_ = signal(SIGINT, onSignal);
    oldTerm_ = signal(SIGTERM, onSignal);
    gOuterInt = callable(oldInt_);
    gOuterTerm = callable(oldTerm_);
  }
  ~StopSignals() {
    signal(SIGINT, oldInt_);
    signal(SIGTERM, oldTerm_);
    gOuterInt = nullptr;
    gOuterTerm = nullptr;
  }
  bool raised() const { return gSignal != 0; }

 private:
  static Handler callable(Handler h) {
    return h == SIG_DFL || h == SIG_IGN || h == SIG_ERR ? nullptr : h;
  }
  Handler oldInt_, oldTerm_;
};

// The loaded OpenBLAS when it is Debian's pthread build ("" otherwise). Its own threads spin
// against LibTorch's OpenMP threads: CPU training steps ran 1.2-10x slower (docs/releases.md).
std::string pthreadOpenBlas() {
  std::string found;
  dl_iterate_phdr(
      [](dl_phdr_info* info, size_t, void* out) {
        const std::string name = info->dlpi_name ? info->dlpi_name : "";
        if (name.find("/openblas-pthread/") == std::string::npos) return 0;
        *static_cast<std::string*>(out) = name;
        return 1;
      },
      &found);
  return found;
}

// One run of runTraining. Its stages, in order: the constructor (device and output folder),
// buildModelAndOptimizer, resumeOrStartLog, startData, trainSteps and summary.
class TrainingLoop {
 public:
  TrainingLoop(const TrainConfig& c, TrainingTask& task, Distributed* dist)
      : c_(c),
        task_(task),
        tool_(task.tool()),
        dist_(dist),
        rank_(dist ? dist->rank() : 0),
        world_(dist ? dist->worldSize() : 1),
        lead_(rank_ == 0),
        progress_(c.progress && lead_) {
    if (c.device == "cuda") {
      if (!torch::cuda::is_available())
        throw OptionError("device", "device cuda, but this LibTorch has no CUDA device");
      device_ =
          torch::Device(torch::kCUDA, dist ? static_cast<c10::DeviceIndex>(dist->localRank()) : 0);
      allowTf32();
    }
    precision_ = resolvePrecision(c.amp, device_.type(), tool_);
    if (const std::string blas = lead_ && !device_.is_cuda() ? pthreadOpenBlas() : "";
        !blas.empty())
      std::fprintf(stderr,
                   "%s: warning: LibTorch runs on the pthread OpenBLAS (%s), 1.2-10x slower "
                   "on the CPU than libopenblas0-openmp; scripts/setup.sh selects that one\n",
                   tool_.c_str(), blas.c_str());
    makeDirs(c.out);
    if (lead_) removeStaleTemporaries(c.out);  // left by a killed run
    ckptPath_ = (fs::path(c.out) / "checkpoint-last.pth").string();
    logPath_ = (fs::path(c.out) / "log.jsonl").string();
  }

  // AdamW with no weight decay on biases and 1-D parameters (norms), and CroCo's lr scaling.
  void buildModelAndOptimizer() {
    torch::manual_seed(c_.seed);
    model_ = task_.buildModel();
    const auto named = task_.trainable();
    const DecayGroups names = weightDecayGroups(named);
    const std::set<std::string> decayNames(names.decay.begin(), names.decay.end());
    std::vector<torch::Tensor> decay, noDecay;
    for (const auto& [name, t] : named) {
      ordered_.push_back(t);
      (decayNames.count(name) ? decay : noDecay).push_back(t);
    }
    const int effBatch = c_.batchSize * c_.accumIter * world_;
    lr_ = c_.blr * effBatch / 256.0;
    const auto adamw = torch::optim::AdamWOptions(lr_).betas({0.9, 0.95});
    std::vector<torch::optim::OptimizerParamGroup> groups;
    groups.emplace_back(decay, std::make_unique<torch::optim::AdamWOptions>(
                                   torch::optim::AdamWOptions(adamw).weight_decay(c_.weightDecay)));
    groups.emplace_back(noDecay, std::make_unique<torch::optim::AdamWOptions>(
                                     torch::optim::AdamWOptions(adamw).weight_decay(0.0)));
    opt_ = std::make_unique<torch::optim::AdamW>(groups, adamw);
    // fp16 needs a loss scale; bf16 has float32's range and does not.
    scaler_ = std::make_unique<GradScaler>(precision_.ran == "fp16" || c_.forceLossScaling,
                                           c_.initScale, c_.scaleGrowthInterval);
  }

  // From OUT/checkpoint-last.pth with --resume (the log cut back to its step), else a new log.
  // The model goes to its device first, so that restored optimizer state lands there too; then
  // rank 0's weights go to every rank.
  void resumeOrStartLog() {
    model_->to(device_);
    if (c_.resume && fs::exists(ckptPath_)) {
      restoreCheckpoint();
      cutLogToCheckpoint();
      std::fprintf(stderr, "%s: resumed from %s at step %lld\n", tool_.c_str(), ckptPath_.c_str(),
                   static_cast<long long>(iter_));
    } else if (!c_.resume && lead_) {
      writeFileAtomic(logPath_, "");
    }
    if (dist_) dist_->broadcast(ordered_);
  }

  void startData() {
    perEpoch_ = task_.startData(iter_, rank_, world_);
    PAIRCAST_CHECK(perEpoch_ > 0);
    const int64_t total = static_cast<int64_t>(c_.epochs) * perEpoch_;
    stopAt_ = c_.maxSteps >= 0 ? std::min(total, c_.maxSteps) : total;
    scheduleEpochs_ = c_.epochs;
    warmupEpochs_ = c_.warmupEpochs;
    if (c_.scheduleSpansRun) {
      scheduleEpochs_ = static_cast<double>(stopAt_) / perEpoch_;
      warmupEpochs_ = std::min(warmupEpochs_, 0.1 * scheduleEpochs_);
    }
    saveEvery_ = std::max<int64_t>(c_.accumIter,
                                   (c_.saveEvery + c_.accumIter - 1) / c_.accumIter * c_.accumIter);
  }

  // Steps until stopAt, --max-steps or a signal; checkpoints, log lines, progress and the task's
  // own work after each step on the way.
  void trainSteps() {
    const StopSignals signals;
    if (lead_) log_.open(logPath_, std::ios::app);
    start_ = Clock::now();
    firstIter_ = iter_;
    model_->train();
    std::unique_ptr<OpProfile> profile;
    if (lead_ && !c_.profile.empty()) profile = std::make_unique<OpProfile>();
    int64_t profiled = 0;
    double profiledSeconds = 0;
    while (iter_ < stopAt_) {
      const bool counting = profile && iter_ - firstIter_ >= kProfileWarmupSteps;
      if (counting) profile->resume();
      const auto t0 = Clock::now();
      {
        RECORD_USER_SCOPE(kStageData);
        task_.fetch(iter_);
      }
      const double wait = since(t0);
      epoch_ = static_cast<double>(iter_) / perEpoch_;
      if (iter_ % c_.accumIter == 0) setLearningRate();
      stepLoss_ = step();
      ++iter_;
      const double stepTime = since(t0);
      if (counting) {
        profile->pause();
        ++profiled;
        profiledSeconds += stepTime;
      }
      waitTotal_ += wait;
      stepTotal_ += stepTime;
      if (lead_ && std::isfinite(stepLoss_) && ((iter_ - 1) % c_.logEvery == 0 || iter_ == stopAt_))
        logStep(wait, stepTime);
      if (progress_.due()) progress_.show(progressText());
      const bool boundary = iter_ % c_.accumIter == 0;
      const bool stopNow = stopRequested(signals, boundary);
      if (boundary &&
          (iter_ % saveEvery_ == 0 || iter_ % perEpoch_ == 0 || iter_ == stopAt_ || stopNow)) {
        if (lead_) saveCheckpoints();
        if (stopNow) {
          interrupted_ = true;
          progress_.breakLine();
          if (lead_)
            std::fprintf(stderr, "%s: %s: checkpoint saved at step %lld, exiting\n", tool_.c_str(),
                         stopAfterReached() ? "stop after" : "signal",
                         static_cast<long long>(iter_));
          break;
        }
      }
      if (lead_) {
        task_.afterStep(iter_, device_);
        logTaskLine(task_.logAfterStep(iter_, device_));
        model_->train();
      }
    }
    if (iter_ > firstIter_) progress_.show(progressText(), /*last=*/true);
    if (profile) writeProfile(*profile, profiled, profiledSeconds);
  }

  // The operator profile with the steps' wall time beside the operators' summed self times.
  void writeProfile(const OpProfile& profile, int64_t steps, double seconds) {
    nlohmann::json j = profile.report(steps);
    j["wall_ms_per_step"] = 1e3 * seconds / std::max<int64_t>(steps, 1);
    j["precision"] = precision_.toJson();
    j["batch_size"] = c_.batchSize;
    writeFileAtomic(c_.profile, j.dump(1) + "\n");
  }

  nlohmann::json summary() {
    const double seconds = since(start_);
    nlohmann::json s = {
        {"steps", iter_},
        {"steps_this_run", iter_ - firstIter_},
        {"loss", lastLoss_},
        {"seconds", seconds},
        {"pairs_per_s", (iter_ - firstIter_) * c_.batchSize / std::max(seconds, 1e-9)},
        {"data_wait", waitTotal_ / std::max(stepTotal_, 1e-9)},
        {"skipped_steps", skipped_},
        {"interrupted", interrupted_},
        {"checkpoint", ckptPath_}};
    s["world_size"] = world_;
    // The schedule: blr, the peak lr it gives, and the epochs (and steps) its warm-up and
    // cosine span.
    s["schedule"] = {{"blr", c_.blr},
                     {"peak_lr", lr_},
                     {"epochs", scheduleEpochs_},
                     {"warmup_epochs", warmupEpochs_},
                     {"steps", stopAt_}};
    s["fused_adamw"] = c_.fusedAdamW && device_.is_cuda() && fusedAdamWCompiled();
    s["flat_adamw"] = flatAdamW_.active();
    if (scaler_->enabled()) s["loss_scale"] = scaler_->scale();
    s["precision"] = precision_.toJson();
    s["openblas_core"] = blasCore().toJson();
    task_.summarise(s);
    if (lead_) writeFileAtomic((fs::path(c_.out) / "summary.json").string(), s.dump(1) + "\n");
    if (dist_) dist_->barrier();
    return s;
  }

 private:
  // A checkpoint's entries of the wrong type or shape are an error naming it, not a JSON or
  // LibTorch exception.
  void restoreCheckpoint() {
    try {
      restoreCheckpointEntries();
    } catch (const nlohmann::json::exception& e) {
      throw Error(ckptPath_, std::string("cannot resume: bad checkpoint entry: ") + e.what());
    } catch (const c10::Error& e) {
      throw Error(ckptPath_, std::string("cannot resume: ") + e.what_without_backtrace());
    }
  }

  void restoreCheckpointEntries() {
    const Checkpoint ck = loadCheckpoint(ckptPath_);
    task_.restore(ck, ckptPath_);
    restoreOptimizer(*opt_, ordered_, ck.extraTensors, ckptPath_);
    iter_ = ck.extra.value("step", int64_t{0});
    if (ck.extra.contains("scaler")) scaler_->restore(ck.extra["scaler"]);
    auto rng = ck.extraTensors.find("rng/torch");
    if (rng != ck.extraTensors.end()) {
      auto gen = at::detail::getDefaultCPUGenerator();
      std::lock_guard<std::mutex> lock(gen.mutex());
      gen.set_state(rng->second);
    }
  }

  // Keeps the log up to the checkpoint: lines a killed run wrote after it are dropped. A
  // resumed run that has no step left still reports the last logged loss.
  void cutLogToCheckpoint() {
    std::ifstream in(logPath_);
    std::string line, kept;
    while (std::getline(in, line)) {
      auto j = nlohmann::json::parse(line, nullptr, false);
      if (!j.is_object() || !j.contains("step") || !j["step"].is_number_integer() ||
          j["step"].get<int64_t>() >= iter_)
        continue;
      const bool lossLine = j.contains("loss") && j["loss"].is_number();
      if (!lossLine && !j.contains("heldout")) continue;
      kept += line + "\n";
      if (lossLine) curve_.emplace_back(j["step"].get<int64_t>(), j["loss"].get<double>());
    }
    if (lead_) writeFileAtomic(logPath_, kept);
    if (!curve_.empty()) lastLoss_ = curve_.back().second;
  }

  void setLearningRate() {
    const double l = learningRate(lr_, c_.minLr, warmupEpochs_, scheduleEpochs_, epoch_);
    for (auto& g : opt_->param_groups())
      static_cast<torch::optim::AdamWOptions&>(g.options()).lr(l);
  }
  double currentLr() const {
    return static_cast<torch::optim::AdamWOptions&>(opt_->param_groups()[0].options()).lr();
  }

  // Forward and backward of iteration iter_, and the optimizer step when it ends an
  // accumulation. Returns the loss averaged over the ranks; a non-finite one skips the step.
  double step() {
    torch::Tensor loss;
    {
      // bf16 or fp16 autocast, or none; the task computes the loss itself in float32.
      const AutocastGuard autocast(precision_);
      RECORD_USER_SCOPE(kStageForward);
      loss = task_.loss(device_);
    }
    if (iter_ == c_.debugNanAtStep) loss = loss * std::numeric_limits<float>::quiet_NaN();
    // The ranks agree on the loss (and so on skipping a non-finite one).
    auto lossAll = loss.detach().to(torch::kCPU, torch::kFloat64).reshape({1});
    if (dist_) dist_->allReduceMean({lossAll});
    const double lossValue = lossAll.item<double>();
    if (!std::isfinite(lossValue)) {
      ++skipped_;
      if (++nanRun_ > c_.maxNanSkips)
        throw Error(c_.out, "loss is not finite for " + std::to_string(nanRun_) +
                                " steps in a row (step " + std::to_string(iter_) +
                                "); stopped, the last checkpoint is kept");
      progress_.breakLine();
      std::fprintf(stderr, "%s: warning: non-finite loss at step %lld, step skipped\n",
                   tool_.c_str(), static_cast<long long>(iter_));
      flatAdamW_.zeroGrad(*opt_);
      return lossValue;
    }
    nanRun_ = 0;
    {
      RECORD_USER_SCOPE(kStageBackward);
      scaler_->scaleLoss(loss / c_.accumIter).backward();
    }
    if ((iter_ + 1) % c_.accumIter == 0) {
      RECORD_USER_SCOPE(kStageOptimizer);
      optimizerStep();
    }
    lastLoss_ = lossValue;
    return lossValue;
  }

  void optimizerStep() {
    if (dist_) {
      std::vector<torch::Tensor> grads;
      for (auto& p : ordered_)
        if (p.grad().defined()) grads.push_back(p.grad());
      dist_->allReduceMean(grads);
    }
    // With a loss scale, gradients that overflowed skip the step (on every rank alike: they
    // were all-reduced) and the scale backs off.
    const bool finite = scaler_->unscale(ordered_);
    // CUDA: the fused kernel; the CPU: flat buffers (both --no-fused-adamw turns off).
    if (finite && !(c_.fusedAdamW && (fusedAdamWStep(*opt_) || flatAdamW_.step(*opt_))))
      opt_->step();
    scaler_->update(finite);
    if (!finite && lead_) {
      progress_.breakLine();
      std::fprintf(stderr,
                   "%s: warning: fp16 gradients overflowed at step %lld; step skipped, "
                   "loss scale now %g\n",
                   tool_.c_str(), static_cast<long long>(iter_), scaler_->scale());
    }
    flatAdamW_.zeroGrad(*opt_);
  }

  // One line of log.jsonl for the step just taken (iter_ - 1).
  void logStep(double wait, double stepTime) {
    nlohmann::json j = {{"step", iter_ - 1},
                        {"epoch", epoch_},
                        {"loss", stepLoss_},
                        {"lr", currentLr()},
                        {"pairs_per_s", c_.batchSize / stepTime},
                        {"data_wait", wait / stepTime}};
    log_ << j.dump() << "\n";
    log_.flush();
    curve_.emplace_back(iter_ - 1, stepLoss_);
  }

  void logTaskLine(nlohmann::json entries) {
    if (!entries.is_object() || entries.empty()) return;
    entries["step"] = iter_ - 1;
    log_ << entries.dump() << "\n";
    log_.flush();
  }

  std::string progressText() const {
    const double rate = (iter_ - firstIter_) / std::max(1e-9, since(start_));
    char line[256];
    std::snprintf(line, sizeof line,
                  "[%s] step %lld/%lld  epoch %.2f  loss %.4f  lr %.2e  %.1f pairs/s  %s  "
                  "data-wait %.1f%%  ETA %.0fs",
                  tool_.c_str(), static_cast<long long>(iter_), static_cast<long long>(stopAt_),
                  epoch_, stepLoss_, currentLr(), rate * c_.batchSize, precision_.ran.c_str(),
                  100 * waitTotal_ / std::max(1e-9, stepTotal_),
                  (stopAt_ - iter_) / std::max(rate, 1e-9));
    return line;
  }

  // TrainConfig::stopAfter: the run has taken its part's steps, short of its last one.
  bool stopAfterReached() const {
    return c_.stopAfter >= 0 && iter_ >= c_.stopAfter && iter_ < stopAt_;
  }

  // A signal to any rank stops them all, at the same accumulation boundary.
  bool stopRequested(const StopSignals& signals, bool boundary) {
    if (boundary && stopAfterReached()) return true;
    bool stop = signals.raised();
    if (dist_ && boundary) {
      auto flag = torch::tensor({stop ? 1.0 : 0.0}, torch::kFloat64);
      dist_->allReduceMean({flag});
      stop = flag.item<double>() > 0;
    }
    return stop;
  }

  // checkpoint-last.pth and the loss curve; checkpoint-<epoch>.pth every --keep-every epochs.
  void saveCheckpoints() {
    save(ckptPath_, iter_);
    writeLossCurve((fs::path(c_.out) / "loss.svg").string(), curve_);
    if (c_.keepEvery > 0 && iter_ % perEpoch_ == 0 && (iter_ / perEpoch_) % c_.keepEvery == 0)
      save((fs::path(c_.out) / ("checkpoint-" + std::to_string(iter_ / perEpoch_) + ".pth"))
               .string(),
           iter_);
  }

  void save(const std::string& path, int64_t step) {
    for (const auto& p : ordered_)
      if (!torch::isfinite(p).all().item<bool>())
        throw Error(path, "weights are not finite at step " + std::to_string(step) +
                              ": checkpoint not written");
    auto tensors = optimizerTensors(*opt_, ordered_);
    {
      auto gen = at::detail::getDefaultCPUGenerator();
      std::lock_guard<std::mutex> lock(gen.mutex());
      tensors["rng/torch"] = gen.get_state();
    }
    nlohmann::json extra = task_.checkpointEntries();
    extra.update({{"step", step},
                  {"seed", c_.seed},
                  {"batch_size", c_.batchSize},
                  {"accum_iter", c_.accumIter}});
    if (scaler_->enabled()) extra["scaler"] = scaler_->state();
    task_.save(path, step / perEpoch_, extra, tensors);
  }

  // Set-up.
  const TrainConfig& c_;
  TrainingTask& task_;
  const std::string tool_;
  Distributed* dist_;
  const int rank_, world_;
  const bool lead_;  // rank 0: writes checkpoints, logs and images
  torch::Device device_{torch::kCPU};
  std::string ckptPath_, logPath_;
  ProgressLine progress_;
  // Model and optimizer.
  std::shared_ptr<torch::nn::Module> model_;
  std::vector<torch::Tensor> ordered_;  // the trained parameters, in trainable() order
  double lr_ = 0;                       // the peak lr
  std::unique_ptr<torch::optim::AdamW> opt_;
  FlatAdamW flatAdamW_;  // the CPU step over flat buffers (trainer/flat_adamw.h)
  std::unique_ptr<GradScaler> scaler_;
  Precision precision_;
  // Position.
  int64_t iter_ = 0, firstIter_ = 0;
  std::vector<std::pair<int64_t, double>> curve_;  // (step, loss) of the logged steps
  int64_t perEpoch_ = 0, stopAt_ = 0, saveEvery_ = 0;
  // The step loop's state and tallies.
  std::ofstream log_;
  Clock::time_point start_ = Clock::now();
  double epoch_ = 0, stepLoss_ = NAN, lastLoss_ = NAN;
  double scheduleEpochs_ = 0, warmupEpochs_ = 0;  // the schedule's span (scheduleSpansRun)
  double waitTotal_ = 0, stepTotal_ = 0;
  int nanRun_ = 0, skipped_ = 0;
  bool interrupted_ = false;
};

}  // namespace

nlohmann::json runTraining(const TrainConfig& c, TrainingTask& task, Distributed* dist) {
  // Each step's large activations reuse the last step's memory instead of fresh pages.
  if (c.device == "cpu") keepFreedMemoryForReuse();
  TrainingLoop run(c, task, dist);
  run.buildModelAndOptimizer();
  run.resumeOrStartLog();
  run.startData();
  run.trainSteps();
  return run.summary();
}

}  // namespace paircast
