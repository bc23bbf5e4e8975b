// What a generate_pairs run spent, summed over its workers: the samples made and the indices
// without one, what screening turned down, the full renders kept and wasted, and where the
// workers' time went (summary.json's pairs_this_run, screening, renders, time_split and
// time_seconds). Thread-safe: workers add, the writer reads.
#pragma once

#include <mutex>
#include <nlohmann/json.hpp>

#include "dataset/pair_generator.h"

namespace paircast {

class RunStats {
 public:
  // One index: what generating it cost, whether it gave a sample, and the seconds its encoding
  // and its CroCo files took.
  void addIndex(const GenerationCost& spent, bool kept, double encodeSeconds, double writeSeconds);
  // Seconds the writer spent on journal and shards.
  void addWrite(double seconds);

  size_t accepted() const;
  size_t candidates() const;  // candidates tried, with a covis or an estimate

  // summary.json's figures of this run, over `seconds` of wall time: pairs_this_run,
  // pairs_per_second, failed_pairs, screening (turned down, false rejections, the funnels),
  // renders and the time split.
  nlohmann::json toJson(double seconds) const;

 private:
  mutable std::mutex mu_;
  GenerationCost sum_;  // the attempts' costs, added (not their candidateCovis)
  size_t accepted_ = 0, failed_ = 0, candidates_ = 0;
  double sampling_ = 0, encode_ = 0, write_ = 0;
};

}  // namespace paircast
