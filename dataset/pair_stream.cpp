#include "dataset/pair_stream.h"

#include <omp.h>

#include <cstdio>

#include "dataset/generate_job.h"
#include "util/error.h"

namespace paircast {

struct PairStream::SceneState {
  Scene scene;
  std::unique_ptr<RayCaster> caster;
  std::unique_ptr<ViewpointSampler> sampler;
  std::unique_ptr<PairGenerator> generator;
};

PairStream::PairStream(const PairStreamOptions& options)
    : options_(options), counter_(options.firstIndex) {
  if (options.partCount < 1 || options.partIndex < 0 || options.partIndex >= options.partCount)
    throw Error("stream part must be in [0, partCount)");
  for (const auto& path : expandSceneList(options.scenes)) {
    try {
      auto s = std::make_unique<SceneState>();
      s->scene = loadScene(path, options.load);
      s->caster = std::make_unique<RayCaster>(s->scene.mesh);
      s->sampler = std::make_unique<ViewpointSampler>(s->scene, *s->caster, options.pair.sampler);
      s->generator =
          std::make_unique<PairGenerator>(s->scene, *s->caster, *s->sampler, options.pair);
      scenes_.push_back(std::move(s));
    } catch (const Error& e) {
      std::fprintf(stderr, "pair stream: warning: skipping scene %s\n", e.what());
    }
  }
  if (scenes_.empty()) throw Error("no usable scene for the live pair stream");
  for (int t = 0; t < std::max(1, options.threads); ++t) threads_.emplace_back([this] { work(); });
}

PairStream::~PairStream() {
  stop();
  for (auto& t : threads_) t.join();
}

void PairStream::stop() {
  stopped_ = true;
  notEmpty_.notify_all();
  notFull_.notify_all();
}

void PairStream::work() {
  omp_set_num_threads(1);  // per thread: each worker renders on one core
  while (!stopped_) {
    // The counter interleaves this part's pairs over all scenes.
    const uint64_t n = counter_++;
    const uint64_t global = n * options_.partCount + options_.partIndex;
    SceneState& s = *scenes_[global % scenes_.size()];
    std::optional<PairSample> sample;
    try {
      sample = s.generator->generate(options_.seed, global / scenes_.size());
    } catch (...) {  // handed to the consumer: an exception leaving a thread ends the process
      std::lock_guard<std::mutex> lock(mu_);
      if (!failure_) failure_ = std::current_exception();
      stop();
      return;
    }
    if (!sample) continue;
    std::unique_lock<std::mutex> lock(mu_);
    notFull_.wait(lock, [&] { return stopped_ || queue_.size() < options_.queueCapacity; });
    if (stopped_) return;
    queue_.push_back(std::move(*sample));
    notEmpty_.notify_one();
  }
}

std::optional<PairSample> PairStream::next() {
  std::unique_lock<std::mutex> lock(mu_);
  notEmpty_.wait(lock, [&] { return stopped_ || !queue_.empty(); });
  if (failure_) std::rethrow_exception(failure_);
  if (queue_.empty()) return std::nullopt;
  PairSample s = std::move(queue_.front());
  queue_.pop_front();
  ++position_;
  notFull_.notify_one();
  return s;
}

}  // namespace paircast
