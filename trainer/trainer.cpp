#include "trainer/trainer.h"

#include <ATen/CPUGeneratorImpl.h>
#include <signal.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <numeric>
#include <thread>

#if PAIRCAST_WITH_RENDER
#include "dataset/pair_stream.h"
#endif
#include "model/autocast.h"
#include "model/checkpoint.h"
#include "model/croco_net.h"
#include "model/reconstruct.h"
#include "trainer/augment.h"
#include "trainer/distributed.h"
#include "trainer/fused_adamw.h"
#include "trainer/grad_scaler.h"
#include "trainer/pair_dataset.h"
#include "util/atomic_file.h"
#include "util/error.h"
#include "util/image_io.h"
#include "util/timer.h"

namespace paircast {
namespace fs = std::filesystem;

namespace {

using Clock = SteadyClock;
constexpr auto since = secondsSince;

std::atomic<int> gSignal{0};
void onSignal(int sig) {
  gSignal = sig;
}

struct Batch {
  torch::Tensor img1, img2;  // [B, 3, S, S] normalised
  torch::Tensor mask;        // [B, N] bool, true = masked
};

// CroCo's RandomMask (argsort(noise) < num_mask) with the noise drawn from a stream keyed by
// the sample, so that masks do not depend on how samples are split over batches and ranks.
torch::Tensor sampleMask(const CroCoConfig& m, uint64_t seed, const std::string& stream,
                         uint64_t key) {
  Rng rng(mixSeed(seed, stream, key));
  const int n = m.numPatches();
  std::vector<double> noise(n);
  for (auto& x : noise) x = rng.uniform();
  std::vector<int64_t> order(n);
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](int64_t a, int64_t b) { return noise[a] < noise[b]; });
  auto mask = torch::empty({n}, torch::kBool);
  for (int i = 0; i < n; ++i) mask[i] = order[i] < m.numMasked();
  return mask;
}

#if PAIRCAST_WITH_RENDER
// Live pairs: rendered by a PairStream, augmented like the others. The stream is read in
// order by the training thread, so its position in a checkpoint resumes it exactly.
class LiveLoader {
 public:
  LiveLoader(const TrainConfig& c, uint64_t position, int rank, int world) : c_(c) {
    PairStreamOptions o;
    o.partIndex = rank;
    o.partCount = world;
    o.scenes = c.live;
    o.seed = c.seed;
    o.threads = std::max(1, c.workers);
    o.firstIndex = position;
    o.pair.resolution = std::max(c.model.img_size, 64);
    stream_ = std::make_unique<PairStream>(o);
  }
  // The next live pair, augmented and masked with streams keyed by `key`.
  void next(uint64_t key, torch::Tensor& a, torch::Tensor& b, torch::Tensor& mask) {
    auto p = stream_->next();
    if (!p) throw Error("the live pair stream stopped");
    Rng rng(mixSeed(c_.seed, "live", key));
    AugmentOptions ao;
    ao.size = c_.model.img_size;
    std::tie(a, b) = augmentPair(p->rgb[0], p->rgb[1], ao, rng);
    mask = sampleMask(c_.model, c_.seed, "livemask", key);
  }
  uint64_t position() const { return stream_->position(); }

 private:
  const TrainConfig& c_;
  std::unique_ptr<PairStream> stream_;
};
#else
// The trainer-only build (PAIRCAST_WITH_RENDER=OFF) has no renderer.
class LiveLoader {
 public:
  LiveLoader(const TrainConfig&, uint64_t, int, int) {
    throw Error(
        "--live needs the renderer: this is a trainer-only build (PAIRCAST_WITH_RENDER=OFF)");
  }
  void next(uint64_t, torch::Tensor&, torch::Tensor&, torch::Tensor&) {}
  uint64_t position() const { return 0; }
};
#endif

// One weighted data source: a dataset on disk, or the live stream (dataset == nullptr).
struct Source {
  const PairDataset* dataset = nullptr;
  double weight = 1.0;
  std::string name;
};

// Batches in a fixed order. With one disk source, batch b of epoch e holds the pairs
// perm_e[b B .. (b+1) B). With several sources, slot g of the run draws its source with the
// weights and its pair uniformly, from a stream keyed by g. Either way each pair is augmented
// with a stream seeded by its position, so a batch depends only on its position, whatever the
// number of workers. Workers prefetch a window ahead; live slots are filled in order by get().
class BatchLoader {
 public:
  // Rank `rank` of `world` reads slice `rank` of each global batch of world x batchSize pairs.
  BatchLoader(std::vector<Source> sources, const TrainConfig& c, int64_t startIter, int rank,
              int world, LiveLoader* live)
      : sources_(std::move(sources)),
        c_(c),
        rank_(rank),
        world_(world),
        live_(live),
        next_(startIter),
        consumed_(startIter) {
    double total = 0;
    int64_t pairs = 0;
    for (const auto& s : sources_) {
      if (!(s.weight >= 0) || !std::isfinite(s.weight))
        throw Error("the weight of " + s.name + " must be a finite number >= 0");
      total += s.weight;
      pairs += s.dataset ? static_cast<int64_t>(s.dataset->size()) : c.liveEpochPairs;
      if (s.dataset && s.dataset->size() == 0 && s.weight > 0)
        throw Error(s.name + " holds no pairs");
    }
    if (!(total > 0)) throw Error("the data sources' weights sum to 0");
    for (const auto& s : sources_)
      cumulative_.push_back((cumulative_.empty() ? 0.0 : cumulative_.back()) + s.weight / total);
    single_ = sources_.size() == 1 && sources_[0].dataset;
    perEpoch_ = pairs / (static_cast<int64_t>(c.batchSize) * world);
    if (perEpoch_ < 1)
      throw Error("the data has " + std::to_string(pairs) + " pairs, fewer than one batch of " +
                  std::to_string(c.batchSize) + (world > 1 ? " per rank" : ""));
    const bool liveOnly = sources_.size() == 1 && !sources_[0].dataset;  // get() fills all
    if (!liveOnly)
      for (int w = 0; w < std::max(1, c.workers); ++w) threads_.emplace_back([this] { work(); });
  }
  ~BatchLoader() {
    {
      std::lock_guard<std::mutex> lock(mu_);
      stop_ = true;
    }
    cv_.notify_all();
    for (auto& t : threads_) t.join();
  }
  int64_t perEpoch() const { return perEpoch_; }
  // Pairs drawn from each source by get() so far, by source name.
  nlohmann::json counts() const {
    nlohmann::json j = nlohmann::json::object();
    for (size_t i = 0; i < sources_.size(); ++i) j[sources_[i].name] = counts_[i];
    return j;
  }

  Batch get(int64_t iter) {
    Slots s(c_.batchSize);
    if (threads_.empty()) {  // live only
      for (int i = 0; i < c_.batchSize; ++i) s.live.push_back(i);
    } else {
      std::unique_lock<std::mutex> lock(mu_);
      cv_.wait(lock, [&] { return ready_.count(iter) || failure_; });
      if (failure_) std::rethrow_exception(failure_);
      s = std::move(ready_[iter]);
      ready_.erase(iter);
      consumed_ = iter + 1;
      cv_.notify_all();
    }
    for (int i : s.live) {
      const uint64_t key = static_cast<uint64_t>(iter) * c_.batchSize + i;
      live_->next(key, s.a[i], s.b[i], s.mask[i]);
    }
    for (size_t src : s.source) ++counts_[src];
    return {torch::stack(s.a), torch::stack(s.b), torch::stack(s.mask)};
  }

 private:
  struct Slots {
    explicit Slots(int n = 0) : a(n), b(n), mask(n), source(n, 0) {}
    std::vector<torch::Tensor> a, b, mask;
    std::vector<int> live;       // slots the live stream fills
    std::vector<size_t> source;  // each slot's source
  };

  const std::vector<int64_t>& permutation(int64_t epoch) {  // under mu_
    auto it = perms_.find(epoch);
    if (it != perms_.end()) return it->second;
    std::vector<int64_t> p(sources_[0].dataset->size());
    std::iota(p.begin(), p.end(), 0);
    Rng rng(mixSeed(c_.seed, "epoch", static_cast<uint64_t>(epoch)));
    for (size_t i = p.size() - 1; i > 0; --i) std::swap(p[i], p[rng.below(i + 1)]);
    if (perms_.size() > 4) perms_.erase(perms_.begin());
    return perms_[epoch] = std::move(p);
  }

  // Loads, augments and masks pair k of `ds`; a corrupt pair is reported and replaced by the
  // next one, deterministically.
  void loadPair(const PairDataset& ds, int64_t i, const std::string& augStream,
                const std::string& maskStream, Slots& s, int slot) {
    for (int attempt = 0;; ++attempt) {
      const size_t k = static_cast<size_t>(i + attempt) % ds.size();
      try {
        auto [x, y] = ds.load(k);
        Rng rng(mixSeed(c_.seed, augStream, k));
        AugmentOptions ao;
        ao.size = c_.model.img_size;
        std::tie(s.a[slot], s.b[slot]) = augmentPair(x, y, ao, rng);
        s.mask[slot] = sampleMask(c_.model, c_.seed, maskStream, k);
        return;
      } catch (const Error& e) {
        std::fprintf(stderr, "pretrain: warning: skipping a corrupt pair: %s\n", e.what());
        if (attempt >= 16) throw;
      }
    }
  }

  void work() {
    while (true) {
      int64_t iter;
      std::vector<int64_t> idx;
      {
        std::unique_lock<std::mutex> lock(mu_);
        cv_.wait(lock,
                 [&] { return stop_ || next_ < consumed_ + 2 * std::max(1, c_.workers) + 2; });
        if (stop_) return;
        iter = next_++;
        if (single_) {
          const int64_t epoch = iter / perEpoch_, b = iter % perEpoch_;
          const auto& perm = permutation(epoch);
          const int64_t first = (b * world_ + rank_) * c_.batchSize;
          idx.assign(perm.begin() + first, perm.begin() + first + c_.batchSize);
        }
      }
      try {
        Slots s(c_.batchSize);
        const int64_t epoch = iter / perEpoch_;
        for (int j = 0; j < c_.batchSize; ++j) {
          if (single_) {
            loadPair(*sources_[0].dataset, idx[j], "aug" + std::to_string(epoch),
                     "mask" + std::to_string(epoch), s, j);
            continue;
          }
          // Slot g of the whole run, the same whatever the number of ranks.
          const uint64_t g = (static_cast<uint64_t>(iter) * world_ + rank_) * c_.batchSize + j;
          Rng rng(mixSeed(c_.seed, "mix", g));
          const double u = rng.uniform();
          size_t src = 0;
          while (src + 1 < sources_.size() && u >= cumulative_[src]) ++src;
          s.source[j] = src;
          if (!sources_[src].dataset) {
            s.live.push_back(j);
            continue;
          }
          const int64_t k = static_cast<int64_t>(rng.below(sources_[src].dataset->size()));
          const std::string tag = "/" + std::to_string(src) + "/" + std::to_string(g);
          loadPair(*sources_[src].dataset, k, "maug" + tag, "mmask" + tag, s, j);
        }
        std::lock_guard<std::mutex> lock(mu_);
        ready_[iter] = std::move(s);
        cv_.notify_all();
      } catch (...) {
        std::lock_guard<std::mutex> lock(mu_);
        failure_ = std::current_exception();
        cv_.notify_all();
        return;
      }
    }
  }

  std::vector<Source> sources_;
  std::vector<double> cumulative_;
  std::vector<int64_t> counts_ = std::vector<int64_t>(sources_.size());
  const TrainConfig& c_;
  int rank_, world_;
  LiveLoader* live_;
  bool single_ = false;
  int64_t perEpoch_ = 0, next_, consumed_;
  std::vector<std::thread> threads_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::map<int64_t, Slots> ready_;
  std::map<int64_t, std::vector<int64_t>> perms_;
  std::exception_ptr failure_;
  bool stop_ = false;
};

// AdamW state, by parameter position, as "optimizer/state/<i>/{exp_avg,exp_avg_sq,step}".
#if TORCH_VERSION_MAJOR >= 2
void* stateKey(const torch::Tensor& p) {
  return p.unsafeGetTensorImpl();
}
#else
std::string stateKey(const torch::Tensor& p) {
  return c10::guts::to_string(p.unsafeGetTensorImpl());
}
#endif

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

void writeLossSvg(const std::string& path, const std::vector<std::pair<int64_t, double>>& points) {
  if (points.size() < 2) return;
  double lo = 1e30, hi = -1e30;
  for (const auto& [s, l] : points) lo = std::min(lo, l), hi = std::max(hi, l);
  if (hi <= lo) hi = lo + 1e-9;
  const double W = 640, H = 360, m = 40;
  const double s0 = points.front().first, s1 = std::max<double>(points.back().first, s0 + 1);
  std::string svg =
      "<svg xmlns='http://www.w3.org/2000/svg' width='640' height='360'>"
      "<rect width='640' height='360' fill='white'/><polyline fill='none' stroke='#1f77b4' "
      "stroke-width='1.5' points='";
  char buf[64];
  for (const auto& [s, l] : points) {
    std::snprintf(buf, sizeof buf, "%.1f,%.1f ", m + (W - 2 * m) * (s - s0) / (s1 - s0),
                  H - m - (H - 2 * m) * (l - lo) / (hi - lo));
    svg += buf;
  }
  std::snprintf(buf, sizeof buf, "%.4f", hi);
  svg += "'/><text x='4' y='30' font-size='12'>" + std::string(buf) + "</text>";
  std::snprintf(buf, sizeof buf, "%.4f", lo);
  svg += "<text x='4' y='" + std::to_string(static_cast<int>(H - m)) + "' font-size='12'>" + buf +
         "</text>";
  svg += "<text x='" + std::to_string(static_cast<int>(W / 2 - 40)) + "' y='" +
         std::to_string(static_cast<int>(H - 8)) +
         "' font-size='12'>training loss by step</text></svg>\n";
  writeFileAtomic(path, svg);
}

}  // namespace

DecayGroups weightDecayGroups(const std::vector<std::pair<std::string, torch::Tensor>>& named) {
  DecayGroups g;
  for (const auto& [name, t] : named) {
    const bool bias = name.size() >= 5 && name.compare(name.size() - 5, 5, ".bias") == 0;
    (t.dim() <= 1 || bias ? g.noDecay : g.decay).push_back(name);
  }
  return g;
}

double learningRate(double baseLr, double minLr, double warmupEpochs, int epochs, double e) {
  if (e < warmupEpochs) return baseLr * e / warmupEpochs;
  const double span = std::max(1e-12, epochs - warmupEpochs);
  return minLr +
         (baseLr - minLr) * 0.5 * (1.0 + std::cos(M_PI * std::min(1.0, (e - warmupEpochs) / span)));
}

nlohmann::json runPretrain(const TrainConfig& c) {
  if (c.device != "cpu" && c.device != "cuda") throw Error("--device must be cpu or cuda");
  const std::unique_ptr<Distributed> dist = Distributed::fromEnvironment(c.device);
  return runPretrain(c, dist.get());
}

nlohmann::json runPretrain(const TrainConfig& c, Distributed* dist) {
  if (c.shards.empty() && c.crocoDir.empty() && c.live.empty())
    throw Error("give a data source: --data, --croco-dir or --live (or several, with weights)");
  if (c.amp != "bf16" && c.amp != "fp16" && c.amp != "none")
    throw Error("--amp must be bf16, fp16 or none, not '" + c.amp + "'");
  if (c.out.empty()) throw Error("--out is required");
  if (c.batchSize < 1 || c.accumIter < 1 || c.epochs < 1)
    throw Error("batch size, accum-iter and epochs must be >= 1");
  c.model.validate();
  if (c.device != "cpu" && c.device != "cuda") throw Error("--device must be cpu or cuda");
  const int rank = dist ? dist->rank() : 0, world = dist ? dist->worldSize() : 1;
  const bool lead = rank == 0;  // writes checkpoints, logs and images
  torch::Device device(torch::kCPU);
  if (c.device == "cuda") {
    if (!torch::cuda::is_available())
      throw Error("--device cuda, but this LibTorch has no CUDA device");
    device =
        torch::Device(torch::kCUDA, dist ? static_cast<c10::DeviceIndex>(dist->localRank()) : 0);
    allowTf32();
  }
  makeDirs(c.out);
  if (lead) removeStaleTemporaries(c.out);  // left by a killed run
  const std::string ckptPath = (fs::path(c.out) / "checkpoint-last.pth").string();
  const std::string logPath = (fs::path(c.out) / "log.jsonl").string();

  // Data.
  std::unique_ptr<PairDataset> shardSet, crocoSet;
  std::vector<Source> sources;
  if (!c.shards.empty()) {
    shardSet = std::make_unique<PairDataset>(PairDataset::fromShards(c.shards));
    if (!c.keysFile.empty()) shardSet->restrictTo(c.keysFile);
    sources.push_back({shardSet.get(), c.shardsWeight, "--data"});
  }
  if (!c.crocoDir.empty()) {
    crocoSet = std::make_unique<PairDataset>(PairDataset::fromCrocoDir(c.crocoDir));
    sources.push_back({crocoSet.get(), c.crocoWeight, "--croco-dir " + c.crocoDir});
  }
  if (!c.live.empty()) sources.push_back({nullptr, c.liveWeight, "--live"});
  const PairDataset* dataset = shardSet ? shardSet.get() : crocoSet.get();  // for the recon grid

  // Model and optimizer: no weight decay on biases and 1-D parameters (norms).
  torch::manual_seed(c.seed);
  CroCoNet model(c.model);
  std::vector<std::pair<std::string, torch::Tensor>> named;
  for (const auto& p : model->named_parameters()) named.emplace_back(p.key(), p.value());
  const DecayGroups names = weightDecayGroups(named);
  std::vector<torch::Tensor> decay, noDecay, ordered;
  for (const auto& [name, t] : named) {
    ordered.push_back(t);
    const bool isDecay =
        std::find(names.decay.begin(), names.decay.end(), name) != names.decay.end();
    (isDecay ? decay : noDecay).push_back(t);
  }
  const int effBatch = c.batchSize * c.accumIter * world;
  const double lr = c.blr * effBatch / 256.0;
  std::vector<torch::optim::OptimizerParamGroup> groups;
  groups.emplace_back(
      decay, std::make_unique<torch::optim::AdamWOptions>(
                 torch::optim::AdamWOptions(lr).betas({0.9, 0.95}).weight_decay(c.weightDecay)));
  groups.emplace_back(noDecay,
                      std::make_unique<torch::optim::AdamWOptions>(
                          torch::optim::AdamWOptions(lr).betas({0.9, 0.95}).weight_decay(0.0)));
  torch::optim::AdamW opt(groups, torch::optim::AdamWOptions(lr).betas({0.9, 0.95}));

  // fp16 needs a loss scale; bf16 has float32's range and does not.
  GradScaler scaler((device.is_cuda() && c.amp == "fp16") || c.forceLossScaling, c.initScale,
                    c.scaleGrowthInterval);

  // On the device before the optimizer state is restored, so that the state lands there too.
  model->to(device);

  // Resume.
  int64_t iter = 0;
  uint64_t livePosition = 0;
  std::vector<std::pair<int64_t, double>> curve;
  if (c.resume && fs::exists(ckptPath)) {
    const Checkpoint ck = loadCheckpoint(ckptPath);
    if (ck.hasArgs && configFromJson(ck.args, ckptPath).enc_embed_dim != c.model.enc_embed_dim)
      throw Error(ckptPath, "checkpoint was trained with other hyper-parameters than --preset");
    loadStateDictStrict(model, ck.model, ckptPath);
    restoreOptimizer(opt, ordered, ck.extraTensors, ckptPath);
    iter = ck.extra.value("step", int64_t{0});
    livePosition = ck.extra.value("live_position", uint64_t{0});
    if (ck.extra.contains("scaler")) scaler.restore(ck.extra["scaler"]);
    auto rng = ck.extraTensors.find("rng/torch");
    if (rng != ck.extraTensors.end()) {
      auto gen = at::detail::getDefaultCPUGenerator();
      std::lock_guard<std::mutex> lock(gen.mutex());
      gen.set_state(rng->second);
    }
    // Keep the log up to the checkpoint: lines a killed run wrote after it are dropped.
    std::ifstream in(logPath);
    std::string line, kept;
    while (std::getline(in, line)) {
      auto j = nlohmann::json::parse(line, nullptr, false);
      if (j.is_object() && j.value("step", int64_t{-1}) < iter) {
        kept += line + "\n";
        curve.emplace_back(j["step"].get<int64_t>(), j["loss"].get<double>());
      }
    }
    if (lead) writeFileAtomic(logPath, kept);
    std::fprintf(stderr, "pretrain: resumed from %s at step %lld\n", ckptPath.c_str(),
                 static_cast<long long>(iter));
  } else if (!c.resume && lead) {
    writeFileAtomic(logPath, "");
  }
  if (dist) dist->broadcast(ordered);  // every rank starts from rank 0's weights

  std::unique_ptr<LiveLoader> live;
  if (!c.live.empty()) live = std::make_unique<LiveLoader>(c, livePosition, rank, world);
  auto loader = std::make_unique<BatchLoader>(sources, c, iter, rank, world, live.get());
  const int64_t perEpoch = loader->perEpoch();
  const int64_t total = static_cast<int64_t>(c.epochs) * perEpoch;
  const int64_t stopAt = c.maxSteps >= 0 ? std::min(total, c.maxSteps) : total;
  const int64_t saveEvery =
      std::max<int64_t>(c.accumIter, (c.saveEvery + c.accumIter - 1) / c.accumIter * c.accumIter);

  auto save = [&](const std::string& path, int64_t step) {
    for (const auto& p : model->parameters())
      if (!torch::isfinite(p).all().item<bool>())
        throw Error(path, "weights are not finite at step " + std::to_string(step) +
                              ": checkpoint not written");
    auto tensors = optimizerTensors(opt, ordered);
    {
      auto gen = at::detail::getDefaultCPUGenerator();
      std::lock_guard<std::mutex> lock(gen.mutex());
      tensors["rng/torch"] = gen.get_state();
    }
    nlohmann::json extra = {{"step", step},
                            {"live_position", live ? live->position() : 0},
                            {"seed", c.seed},
                            {"batch_size", c.batchSize},
                            {"accum_iter", c.accumIter}};
    if (scaler.enabled()) extra["scaler"] = scaler.state();
    saveCheckpoint(path, model, step / perEpoch, extra, tensors);
  };

  gSignal = 0;
  auto oldInt = signal(SIGINT, onSignal), oldTerm = signal(SIGTERM, onSignal);
  std::ofstream log;
  if (lead) log.open(logPath, std::ios::app);
  const auto start = Clock::now();
  // A resumed run that has no step left still reports the last logged loss.
  double waitTotal = 0, stepTotal = 0, lastLoss = curve.empty() ? NAN : curve.back().second;
  int nanRun = 0, skipped = 0;
  int64_t firstIter = iter;
  bool interrupted = false;
  model->train();
  auto lastPrint = Clock::now();
  while (iter < stopAt) {
    const auto t0 = Clock::now();
    const Batch batch = loader->get(iter);
    const double wait = since(t0);
    const double epochF = static_cast<double>(iter) / perEpoch;
    if (iter % c.accumIter == 0) {
      const double l = learningRate(lr, c.minLr, c.warmupEpochs, c.epochs, epochF);
      for (auto& g : opt.param_groups())
        static_cast<torch::optim::AdamWOptions&>(g.options()).lr(l);
    }
    torch::Tensor loss;
    {
      // On CUDA: bf16 or fp16 autocast; the loss itself in float32.
      AutocastGuard autocast(device.is_cuda() && c.amp != "none",
                             c.amp == "fp16" ? at::kHalf : at::kBFloat16);
      auto out =
          model->forward(batch.img1.to(device), batch.img2.to(device), batch.mask.to(device));
      loss = maskedMse(out.prediction.to(torch::kFloat32), out.mask, out.target);
    }
    if (iter == c.debugNanAtStep) loss = loss * std::numeric_limits<float>::quiet_NaN();
    // The ranks agree on the loss (and so on skipping a non-finite one).
    auto lossAll = loss.detach().to(torch::kCPU, torch::kFloat64).reshape({1});
    if (dist) dist->allReduceMean({lossAll});
    const double lossValue = lossAll.item<double>();
    if (!std::isfinite(lossValue)) {
      ++skipped;
      if (++nanRun > c.maxNanSkips)
        throw Error(c.out, "loss is not finite for " + std::to_string(nanRun) +
                               " steps in a row (step " + std::to_string(iter) +
                               "); stopped, the last checkpoint is kept");
      std::fprintf(stderr, "pretrain: warning: non-finite loss at step %lld, step skipped\n",
                   static_cast<long long>(iter));
      opt.zero_grad();
    } else {
      nanRun = 0;
      scaler.scaleLoss(loss / c.accumIter).backward();
      if ((iter + 1) % c.accumIter == 0) {
        if (dist) {
          std::vector<torch::Tensor> grads;
          for (auto& p : ordered)
            if (p.grad().defined()) grads.push_back(p.grad());
          dist->allReduceMean(grads);
        }
        // With a loss scale, gradients that overflowed skip the step (on every rank alike:
        // they were all-reduced) and the scale backs off.
        const bool finite = scaler.unscale(ordered);
        if (finite && !(c.fusedAdamW && fusedAdamWStep(opt))) opt.step();
        scaler.update(finite);
        if (!finite && lead)
          std::fprintf(stderr,
                       "pretrain: warning: fp16 gradients overflowed at step %lld; step skipped, "
                       "loss scale now %g\n",
                       static_cast<long long>(iter), scaler.scale());
        opt.zero_grad();
      }
      lastLoss = lossValue;
    }
    ++iter;
    const double stepTime = since(t0);
    waitTotal += wait;
    stepTotal += stepTime;
    const double curLr =
        static_cast<torch::optim::AdamWOptions&>(opt.param_groups()[0].options()).lr();
    if (lead && std::isfinite(lossValue) && ((iter - 1) % c.logEvery == 0 || iter == stopAt)) {
      nlohmann::json j = {{"step", iter - 1},
                          {"epoch", epochF},
                          {"loss", lossValue},
                          {"lr", curLr},
                          {"pairs_per_s", c.batchSize / stepTime},
                          {"data_wait", wait / stepTime}};
      log << j.dump() << "\n";
      log.flush();
      curve.emplace_back(iter - 1, lossValue);
    }
    if (lead && c.progress && (since(lastPrint) > 1.0 || iter == stopAt)) {
      lastPrint = Clock::now();
      const double rate = (iter - firstIter) / std::max(1e-9, since(start));
      std::fprintf(stderr,
                   "[pretrain] step %lld/%lld  epoch %.2f  loss %.4f  lr %.2e  %.1f pairs/s  "
                   "data-wait %.1f%%  ETA %.0fs\n",
                   static_cast<long long>(iter), static_cast<long long>(stopAt), epochF, lossValue,
                   curLr, rate * c.batchSize, 100 * waitTotal / std::max(1e-9, stepTotal),
                   (stopAt - iter) / std::max(rate, 1e-9));
    }
    const bool boundary = iter % c.accumIter == 0;
    bool stopNow = gSignal != 0;
    if (dist && boundary) {  // a signal to any rank stops them all at the same step
      auto flag = torch::tensor({stopNow ? 1.0 : 0.0}, torch::kFloat64);
      dist->allReduceMean({flag});
      stopNow = flag.item<double>() > 0;
    }
    if (boundary && (iter % saveEvery == 0 || iter % perEpoch == 0 || iter == stopAt || stopNow)) {
      if (lead) {
        save(ckptPath, iter);
        writeLossSvg((fs::path(c.out) / "loss.svg").string(), curve);
        if (c.keepEvery > 0 && iter % perEpoch == 0 && (iter / perEpoch) % c.keepEvery == 0)
          save((fs::path(c.out) / ("checkpoint-" + std::to_string(iter / perEpoch) + ".pth"))
                   .string(),
               iter);
      }
      if (stopNow) {
        interrupted = true;
        if (lead)
          std::fprintf(stderr, "pretrain: signal: checkpoint saved at step %lld, exiting\n",
                       static_cast<long long>(iter));
        break;
      }
    }
    if (lead && c.reconEvery > 0 && iter % c.reconEvery == 0 && dataset) {
      torch::NoGradGuard ng;
      model->eval();
      auto [x, y] = dataset->load(0);
      // A fixed mask from its own generator: training's random stream is left untouched.
      auto gen = at::make_generator<at::CPUGeneratorImpl>(c.seed);
      auto mask = torch::argsort(torch::rand({1, c.model.numPatches()}, gen), 1, false) <
                  c.model.numMasked();
      const Reconstruction r =
          reconstructWith(model, imageTensor(x, c.model.img_size).to(device),
                          imageTensor(y, c.model.img_size).to(device), mask.to(device));
      writeImage((fs::path(c.out) / "recon-latest.png").string(), r.grid);
      model->train();
    }
  }
  signal(SIGINT, oldInt);
  signal(SIGTERM, oldTerm);
  const double seconds = since(start);
  nlohmann::json summary = {
      {"steps", iter},
      {"steps_this_run", iter - firstIter},
      {"loss", lastLoss},
      {"seconds", seconds},
      {"pairs_per_s", (iter - firstIter) * c.batchSize / std::max(seconds, 1e-9)},
      {"data_wait", waitTotal / std::max(stepTotal, 1e-9)},
      {"skipped_steps", skipped},
      {"interrupted", interrupted},
      {"checkpoint", ckptPath}};
  summary["world_size"] = world;
  summary["fused_adamw"] = c.fusedAdamW && device.is_cuda() && fusedAdamWCompiled();
  summary["pairs_by_source"] = loader->counts();
  if (scaler.enabled()) summary["loss_scale"] = scaler.scale();
  if (lead) writeFileAtomic((fs::path(c.out) / "summary.json").string(), summary.dump(1) + "\n");
  if (dist) dist->barrier();
  return summary;
}

}  // namespace paircast
