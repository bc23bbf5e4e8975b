// Pairs rendered live, for training with the renderer in the loop: worker threads make pairs
// round-robin over the scenes and push them into a bounded queue; nothing touches the disk.
#pragma once

#include <atomic>
#include <condition_variable>
#include <deque>
#include <exception>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "dataset/pair_generator.h"

namespace paircast {

struct PairStreamOptions {
  std::vector<std::string> scenes;  // as generate_pairs' --scenes
  LoadOptions load;
  PairOptions pair;
  uint64_t seed = 0;
  uint64_t firstIndex = 0;  // pair counter to start from (to resume a stream)
  int threads = 2;
  size_t queueCapacity = 64;
  // Pairs whose counter n satisfies n % partCount == partIndex: disjoint streams per rank.
  int partIndex = 0;
  int partCount = 1;
};

class PairStream {
 public:
  // Loads every scene (skipping, with a warning on stderr, those that cannot be used) and starts
  // the workers. Throws paircast::Error when no scene is usable.
  explicit PairStream(const PairStreamOptions& options);
  ~PairStream();  // stops and joins the workers
  PairStream(const PairStream&) = delete;
  PairStream& operator=(const PairStream&) = delete;

  // The next pair; blocks while the queue is empty. nullopt after stop(). Rethrows the error
  // that stopped a worker (a scene that fails to render), on the consumer's thread.
  std::optional<PairSample> next();
  void stop();
  size_t usableScenes() const { return scenes_.size(); }
  // Counter of pairs handed out so far (to resume with firstIndex).
  uint64_t position() const { return position_; }

 private:
  struct SceneState;
  void work();
  PairStreamOptions options_;
  std::vector<std::unique_ptr<SceneState>> scenes_;
  std::vector<std::thread> threads_;
  std::mutex mu_;
  std::condition_variable notEmpty_, notFull_;
  std::deque<PairSample> queue_;
  std::atomic<uint64_t> counter_;
  std::atomic<uint64_t> position_{0};
  std::atomic<bool> stopped_{false};
  std::exception_ptr failure_;  // a worker's error, rethrown by next(); guarded by mu_
};

}  // namespace paircast
