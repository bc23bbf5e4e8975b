#include "trainer/batch_loader.h"

#include <algorithm>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <map>
#include <mutex>
#include <numeric>
#include <thread>

#if PAIRCAST_WITH_RENDER
#include "dataset/pair_stream.h"
#endif
#include "trainer/augment.h"
#include "trainer/pair_dataset.h"
#include "util/error.h"
#include "util/random.h"

namespace paircast {

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

namespace {

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

}  // namespace

class BatchLoader::Impl {
 public:
  // Rank `rank` of `world` reads slice `rank` of each global batch of world x batchSize pairs.
  Impl(std::vector<Source> sources, const TrainConfig& c, int64_t startIter, int rank, int world,
       uint64_t livePosition)
      : sources_(std::move(sources)),
        c_(c),
        rank_(rank),
        world_(world),
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
    const bool anyLive = std::any_of(sources_.begin(), sources_.end(),
                                     [](const Source& s) { return s.dataset == nullptr; });
    if (anyLive) live_ = std::make_unique<LiveLoader>(c, livePosition, rank, world);
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
  ~Impl() {
    {
      std::lock_guard<std::mutex> lock(mu_);
      stop_ = true;
    }
    cv_.notify_all();
    for (auto& t : threads_) t.join();
  }
  int64_t perEpoch() const { return perEpoch_; }
  uint64_t livePosition() const { return live_ ? live_->position() : 0; }
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

  // Loads, augments and masks pair k of `ds` (view 1 and another view drawn from a stream
  // keyed like the augmentation), decoding only the crops; a corrupt pair is reported and
  // replaced by the next one, deterministically.
  void loadPair(const PairDataset& ds, int64_t i, const std::string& augStream,
                const std::string& maskStream, Slots& s, int slot) {
    for (int attempt = 0;; ++attempt) {
      const size_t k = static_cast<size_t>(i + attempt) % ds.size();
      try {
        const auto [x, y] = ds.encoded(k, mixSeed(c_.seed, "view" + augStream, k));
        Rng rng(mixSeed(c_.seed, augStream, k));
        AugmentOptions ao;
        ao.size = c_.model.img_size;
        std::tie(s.a[slot], s.b[slot]) = augmentEncodedPair(x, y, ao, rng);
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
  std::unique_ptr<LiveLoader> live_;
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

BatchLoader::BatchLoader(std::vector<Source> sources, const TrainConfig& c, int64_t startIter,
                         int rank, int world, uint64_t livePosition)
    : impl_(std::make_unique<Impl>(std::move(sources), c, startIter, rank, world, livePosition)) {}
BatchLoader::~BatchLoader() = default;
int64_t BatchLoader::perEpoch() const {
  return impl_->perEpoch();
}
nlohmann::json BatchLoader::counts() const {
  return impl_->counts();
}
Batch BatchLoader::get(int64_t iter) {
  return impl_->get(iter);
}
uint64_t BatchLoader::livePosition() const {
  return impl_->livePosition();
}

}  // namespace paircast
