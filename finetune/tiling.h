// How finetune's predictions combine overlapping tiles (finetune/evaluate.h), on its own so
// that finetune.h can take it without the metrics.
#pragma once

#include <string>

namespace paircast {

// How overlapping tiles combine into one prediction.
//   kNearest: each pixel takes the output of the tile whose centre is nearest (the CroCo paper's
//     tiling, and the default).
//   kConfidence: each pixel is the mean of every tile's output there, weighted by the inverse of
//     the Laplacian scale the DPT flow head predicts (1 / (3.75 sigmoid(c) + 0.25), the
//     fine-tuning loss's scale); outputs without a confidence (depth, the linear flow head) are
//     weighted alike. naver/croco's tiled_pred also weights by a confidence, exp(-20 (sigmoid(c
//     / 5) - 0.5)) of its head's confidence channel by default.
enum class Tiling { kNearest, kConfidence };
// "nearest" or "confidence"; throws OptionError("tiling", ...) for anything else.
Tiling parseTiling(const std::string& name);

}  // namespace paircast
