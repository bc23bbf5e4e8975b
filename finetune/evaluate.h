// Prediction at any image size and the held-out figures of a fine-tuned model, against the
// trivial baselines: zero flow, a constant depth, the identity pose.
#pragma once

#include <torch/torch.h>

#include <nlohmann/json.hpp>
#include <vector>

#include "finetune/finetune_data.h"
#include "finetune/tiling.h"
#include "model/downstream.h"

namespace paircast {

// The model's output for images of any size at least the training size S ([1, 3, H, W]
// normalised): flow [1, channels, H, W] and depth [1, 1, H, W] from tiles of S x S that overlap
// by half or more, combined by `tiling`; pose [1, 12] from the centre crop. Throws
// paircast::Error for smaller images.
torch::Tensor predict(DownstreamNet& net, const torch::Tensor& img1, const torch::Tensor& img2,
                      Tiling tiling = Tiling::kNearest);

// The tile origins along a side of `length` for tiles of `tile`, and the tile each coordinate
// takes (its centre nearest).
struct TileAxis {
  std::vector<int64_t> origins;
  std::vector<int64_t> owner;  // [length]
};
TileAxis tileAxis(int64_t length, int64_t tile);

// Per-pair figures, one entry per metric, to be averaged (or paired across runs).
struct HeldOutFigures {
  std::vector<nlohmann::json> pairs;  // {"key", metrics...} of the model
  std::vector<nlohmann::json> baseline;
};

// flow: aepe, the primary figure, over the pixels the loss trains on (known flow landing inside
// view 2's frame), aepe_covisible (pixels view 2 sees), aepe_all_known (every pixel with known
// flow, out of frame and occluded ones too), px1, px3, px5 (shares of aepe's pixels with an
// error above 1, 3, 5 px); depth: delta1, absrel, rmse (log-depth
// predictions exponentiated); pose: trans_err (m), rot_err (degrees). The baseline's depth is
// `constantDepth`.
HeldOutFigures evaluateHeldOut(DownstreamNet& net, const TruthPairs& data, size_t limit,
                               double constantDepth, const torch::Device& device);
// Means of each metric over the pairs (medians for the pose errors), with the count.
nlohmann::json summariseFigures(const std::vector<nlohmann::json>& pairs);

// The pixels whose flow lands inside the image: flow [..., 2, H, W] in pixels (unknown flow
// given as anything finite; mask it apart) -> bool [..., H, W], the pixel centre (x + 0.5 + u,
// y + 0.5 + v) in [0, W) x [0, H).
torch::Tensor landsInFrame(const torch::Tensor& flow);

// The flow metrics of a prediction against the truth ([2, H, W] each, truth +inf unknown) and a
// covisibility mask ([H, W] bool).
nlohmann::json flowMetrics(const torch::Tensor& pred, const torch::Tensor& truth,
                           const torch::Tensor& covisible);
nlohmann::json depthMetrics(const torch::Tensor& pred, const torch::Tensor& truth);
nlohmann::json poseMetrics(const torch::Tensor& pred, const torch::Tensor& truth);

// The Middlebury colour wheel picture of a flow [H, W, 2] (unknown pixels black), normalised by
// its largest known magnitude.
Image8 flowColours(const ImageF& flow);

}  // namespace paircast
