#include "trainer/batch_loader.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <mutex>
#include <numeric>

#if PAIRCAST_WITH_RENDER
#include "dataset/pair_stream.h"
#endif
#include "trainer/augment.h"
#include "trainer/pair_dataset.h"
#include "util/batch_ring.h"
#include "util/error.h"
#include "util/random.h"

namespace paircast {

// CroCo's RandomMask (argsort(noise) < num_mask) with the noise drawn from a stream keyed by
// the sample, so that masks do not depend on how samples are split over batches and ranks.
torch::Tensor sampleMask(const CroCoConfig& m, uint64_t seed, const std::string& stream,
                         uint64_t key) {
  auto mask = torch::empty({m.numPatches()}, torch::kBool);
  sampleMaskInto(m, seed, stream, key, mask.data_ptr<bool>());
  return mask;
}

void sampleMaskInto(const CroCoConfig& m, uint64_t seed, const std::string& stream, uint64_t key,
                    bool* out) {
  Rng rng(mixSeed(seed, stream, key));
  const int n = m.numPatches();
  std::vector<double> noise(n);
  for (auto& x : noise) x = rng.uniform();
  std::vector<int64_t> order(n);
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](int64_t a, int64_t b) { return noise[a] < noise[b]; });
  for (int i = 0; i < n; ++i) out[i] = order[i] < m.numMasked();
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
      : sources_(std::move(sources)), c_(c), rank_(rank), world_(world), next_(startIter) {
    checkSources();
    if (std::any_of(sources_.begin(), sources_.end(), [](const Source& s) { return !s.dataset; }))
      live_ = std::make_unique<LiveLoader>(c, livePosition, rank, world);
    single_ = sources_.size() == 1 && sources_[0].dataset;
    uint8_ = uint8Batches(c);
    if (uint8_ && live_)
      throw Error(
          "uint8 batches (--batch-format) read shards and CroCo folders; live pairs "
          "(--live) need --batch-format float32");
    BatchRing::Options o;
    o.threads = std::max(1, c.workers);
    o.batchSize = c.batchSize;
    o.prefetch = kPrefetch;
    o.keep = 1;
    o.first = startIter;
    o.items = std::numeric_limits<int64_t>::max() / 2;  // as many batches as the run takes
    for (int k = 0; k < BatchRing::depthOf(o); ++k) buffers_.push_back(makeBuffer(c));
    ring_ = std::make_unique<BatchRing>(o, [this](int64_t, int64_t iter, int slot, int buffer) {
      fill(iter, slot, buffers_[buffer]);
      return true;
    });
  }
  ~Impl() { ring_.reset(); }  // the threads stop before the buffers go

  int64_t perEpoch() const { return perEpoch_; }
  uint64_t livePosition() const { return live_ ? live_->position() : 0; }
  // Pairs drawn from each source by get() so far, by source name.
  nlohmann::json counts() const {
    nlohmann::json j = nlohmann::json::object();
    for (size_t i = 0; i < sources_.size(); ++i) j[sources_[i].name] = counts_[i];
    return j;
  }

  Batch get(int64_t iter) {
    if (iter != next_)
      throw Error("the batch loader gives iterations in order: " + std::to_string(next_) +
                  " is next, not " + std::to_string(iter));
    const auto ready = ring_->next();  // rethrows a worker's error
    PAIRCAST_CHECK(ready && ready->batch == iter);
    ++next_;
    Buffer& out = buffers_[ready->buffer];
    for (int i = 0; i < c_.batchSize; ++i) {
      ++counts_[out.source[i]];
      if (!out.live[i]) continue;
      torch::Tensor a, b, mask;
      live_->next(static_cast<uint64_t>(iter) * c_.batchSize + i, a, b, mask);
      out.a[i].copy_(a);
      out.b[i].copy_(b);
      out.mask[i].copy_(mask);
    }
    if (uint8_) return {out.a, out.b, out.mask, out.jitter1, out.jitter2};
    return {out.a, out.b, out.mask};
  }

 private:
  // Batches filled ahead of the one taken. The threads share the pairs of a batch, so two keep
  // any number of them busy.
  static constexpr int kPrefetch = 2;

  // One batch of the ring, made once: the two views, the masks, and each slot's source.
  struct Buffer {
    torch::Tensor a, b, mask;
    torch::Tensor jitter1, jitter2;  // uint8 batches: each image's jitter draws
    std::vector<size_t> source;
    std::vector<char> live;  // slots that get() fills from the live stream, in order
  };

  Buffer makeBuffer(const TrainConfig& c) const {
    const int64_t s = c.model.img_size;
    // Pinned for a CUDA run, so that the copies to the device need no staging.
    const bool pin = c.device.rfind("cuda", 0) == 0 && torch::cuda::is_available();
    const auto f = torch::TensorOptions().dtype(torch::kFloat32).pinned_memory(pin);
    const auto images = uint8_ ? f.dtype(torch::kUInt8) : f;
    Buffer b;
    b.a = torch::empty({c.batchSize, 3, s, s}, images);
    b.b = torch::empty({c.batchSize, 3, s, s}, images);
    b.mask = torch::empty({c.batchSize, c.model.numPatches()}, f.dtype(torch::kBool));
    if (uint8_) {
      b.jitter1 = torch::empty({c.batchSize, 4}, f);
      b.jitter2 = torch::empty({c.batchSize, 4}, f);
    }
    b.source.assign(c.batchSize, 0);
    b.live.assign(c.batchSize, 0);
    return b;
  }

  void checkSources() {
    double total = 0;
    int64_t pairs = 0;
    for (const auto& s : sources_) {
      if (!(s.weight >= 0) || !std::isfinite(s.weight))
        throw Error("the weight of " + s.name + " must be a finite number >= 0");
      total += s.weight;
      pairs += s.dataset ? static_cast<int64_t>(s.dataset->size()) : c_.liveEpochPairs;
      if (s.dataset && s.dataset->size() == 0 && s.weight > 0)
        throw Error(s.name + " holds no pairs");
    }
    if (!(total > 0)) throw Error("the data sources' weights sum to 0");
    for (const auto& s : sources_)
      cumulative_.push_back((cumulative_.empty() ? 0.0 : cumulative_.back()) + s.weight / total);
    perEpoch_ = pairs / (static_cast<int64_t>(c_.batchSize) * world_);
    if (perEpoch_ < 1)
      throw Error("the data has " + std::to_string(pairs) + " pairs, fewer than one batch of " +
                  std::to_string(c_.batchSize) + (world_ > 1 ? " per rank" : ""));
  }

  // Element `at` of epoch `epoch`'s permutation of the single source.
  int64_t permuted(int64_t epoch, int64_t at) {
    std::lock_guard<std::mutex> lock(permMu_);
    auto it = perms_.find(epoch);
    if (it == perms_.end()) {
      std::vector<int64_t> p(sources_[0].dataset->size());
      std::iota(p.begin(), p.end(), 0);
      Rng rng(mixSeed(c_.seed, "epoch", static_cast<uint64_t>(epoch)));
      for (size_t i = p.size() - 1; i > 0; --i) std::swap(p[i], p[rng.below(i + 1)]);
      if (perms_.size() > 4) perms_.erase(perms_.begin());
      it = perms_.emplace(epoch, std::move(p)).first;
    }
    return it->second[static_cast<size_t>(at)];
  }

  // Loads, augments and masks pair k of `ds` (view 1 and another view drawn from a stream
  // keyed like the augmentation) into slot `slot`, decoding only the crops; a corrupt pair is
  // reported and replaced by the next one, deterministically.
  void loadPair(const PairDataset& ds, int64_t i, const std::string& augStream,
                const std::string& maskStream, Buffer& out, int slot) {
    for (int attempt = 0;; ++attempt) {
      const size_t k = static_cast<size_t>(i + attempt) % ds.size();
      try {
        const auto [x, y] = ds.encoded(k, mixSeed(c_.seed, "view" + augStream, k));
        Rng rng(mixSeed(c_.seed, augStream, k));
        AugmentOptions ao;
        ao.size = c_.model.img_size;
        if (uint8_)
          cropEncodedPairInto(x, y, ao, rng, scratch(), out.a[slot], out.b[slot],
                              out.jitter1[slot].data_ptr<float>(),
                              out.jitter2[slot].data_ptr<float>());
        else
          augmentEncodedPairInto(x, y, ao, rng, scratch(), out.a[slot], out.b[slot]);
        sampleMaskInto(c_.model, c_.seed, maskStream, k,
                       out.mask.data_ptr<bool>() + static_cast<int64_t>(slot) * out.mask.size(1));
        return;
      } catch (const Error& e) {
        std::fprintf(stderr, "pretrain: warning: skipping a corrupt pair: %s\n", e.what());
        if (attempt >= 16) throw;
      }
    }
  }

  // This worker thread's scratch, made on its first pair.
  AugmentScratch& scratch() const {
    thread_local std::unique_ptr<AugmentScratch> s;
    if (!s || s->size != c_.model.img_size) s = std::make_unique<AugmentScratch>(c_.model.img_size);
    return *s;
  }

  // Slot `slot` of iteration `iter`, on a worker thread.
  void fill(int64_t iter, int slot, Buffer& out) {
    const int64_t epoch = iter / perEpoch_;
    out.live[slot] = 0;
    out.source[slot] = 0;
    if (single_) {
      const int64_t at = ((iter % perEpoch_) * world_ + rank_) * c_.batchSize + slot;
      loadPair(*sources_[0].dataset, permuted(epoch, at), "aug" + std::to_string(epoch),
               "mask" + std::to_string(epoch), out, slot);
      return;
    }
    // Slot g of the whole run, the same whatever the number of ranks.
    const uint64_t g = (static_cast<uint64_t>(iter) * world_ + rank_) * c_.batchSize + slot;
    Rng rng(mixSeed(c_.seed, "mix", g));
    const double u = rng.uniform();
    size_t src = 0;
    while (src + 1 < sources_.size() && u >= cumulative_[src]) ++src;
    out.source[slot] = src;
    if (!sources_[src].dataset) {
      out.live[slot] = 1;
      return;
    }
    const int64_t k = static_cast<int64_t>(rng.below(sources_[src].dataset->size()));
    const std::string tag = "/" + std::to_string(src) + "/" + std::to_string(g);
    loadPair(*sources_[src].dataset, k, "maug" + tag, "mmask" + tag, out, slot);
  }

  std::vector<Source> sources_;
  std::vector<double> cumulative_;
  std::vector<int64_t> counts_ = std::vector<int64_t>(sources_.size());
  const TrainConfig& c_;
  int rank_, world_;
  std::unique_ptr<LiveLoader> live_;
  bool single_ = false, uint8_ = false;
  int64_t perEpoch_ = 0, next_;
  std::mutex permMu_;
  std::map<int64_t, std::vector<int64_t>> perms_;
  std::vector<Buffer> buffers_;
  std::unique_ptr<BatchRing> ring_;
};

bool uint8Batches(const TrainConfig& c) {
  if (c.batchFormat == "float32") return false;
  if (c.batchFormat == "uint8") return true;
  if (c.batchFormat == "auto") return c.device.rfind("cuda", 0) == 0;
  throw Error("the batch format must be auto, float32 or uint8, not '" + c.batchFormat + "'");
}

Batch finishBatch(const Batch& batch, const torch::Device& device) {
  Batch out;
  out.mask = batch.mask.to(device, true);
  if (!batch.isUint8()) {
    out.img1 = batch.img1.to(device, true);
    out.img2 = batch.img2.to(device, true);
    return out;
  }
  out.img1 = jitterAndNormalizeBatch(batch.img1.to(device, true), batch.jitter1.to(device, true));
  out.img2 = jitterAndNormalizeBatch(batch.img2.to(device, true), batch.jitter2.to(device, true));
  return out;
}

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
