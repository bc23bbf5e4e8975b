// The pool of covis_sweep: pairs sampled once from the training scenes into 20 covis buckets,
// kept in pool/pool-RRRRRR.tar (one shard per sampling round) and pool/pool.json (the pairs of
// the completed rounds), so that a killed sweep resumes its sampling.
#pragma once

#include <string>
#include <vector>

#include "sweep/covis_sweep.h"

namespace paircast {

// The pool's pairs, in sampling order.
struct Pool {
  std::vector<std::string> keys;
  std::vector<double> covis;
};

// Samples rounds until every bucket holds its demand (pairs per bucket), resuming from
// pool.json. Throws paircast::Error when the scenes cannot fill a bucket, or when pool.json was
// sampled with other settings.
Pool buildPool(const SweepConfig& config, const std::vector<std::string>& sceneFiles,
               const std::vector<int>& demand);

}  // namespace paircast
