// Comparing the weights of checkpoints in tests (pretrain, covis_sweep).
#pragma once

#include <algorithm>
#include <string>

#include "model/checkpoint.h"

namespace paircast::testing {

// The largest absolute difference between the weights of two checkpoints, tensor by tensor of
// the same name.
inline double weightDifference(const std::string& a, const std::string& b) {
  const Checkpoint x = loadCheckpoint(a), y = loadCheckpoint(b);
  double worst = 0;
  for (const auto& [name, t] : x.model)
    worst = std::max(worst, (t - y.model.at(name)).abs().max().item<double>());
  return worst;
}

}  // namespace paircast::testing
