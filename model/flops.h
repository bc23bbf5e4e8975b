// Parameter and FLOP counts of a CroCo configuration, computed from the architecture, one
// forward pass on one pair at the configured mask ratio. A multiply and an add count as two.
#pragma once

#include <cstdint>

#include "model/croco_config.h"

namespace paircast {

struct FlopCount {
  int64_t params = 0;
  // The paper's convention (Table 1 of CroCo): the weight layers only (patch embedding, every
  // linear layer, the prediction head), image 1 encoded on its visible patches only.
  double flops = 0;
  // Everything: weight layers with their biases, attention scores and weighted sums, softmax,
  // scaling, layer norms, GELU, residual and positional additions.
  double flops_full = 0;
};

FlopCount countFlops(const CroCoConfig& config);

}  // namespace paircast
