// The monocular depth probe of covis_sweep: a frozen CroCo encoder, and a linear head per patch
// (ridge regression, solved in closed form, so its "training budget" is fixed and the same for
// every encoder) that maps a patch's feature, with the mean feature of its image for context,
// to the log z-depth of its pixels. Metrics as NYUv2
// evaluation: delta1 (max(pred/gt, gt/pred) < 1.25), AbsRel and RMSE over valid pixels.
#pragma once

#include <torch/torch.h>

#include <nlohmann/json.hpp>
#include <vector>

#include "model/croco_net.h"

namespace paircast {

struct DepthMetrics {
  double delta1 = 0, absRel = 0, rmse = 0;
  int64_t pixels = 0;  // valid pixels counted
  nlohmann::json toJson() const;
};

// Over the pixels where gt > 0 (and finite). pred and gt have the same shape.
DepthMetrics depthMetrics(const torch::Tensor& pred, const torch::Tensor& gt);

// Held-out views: images [B, 3, S, S] (ImageNet-normalised) and z-depth [B, S, S] (0 = miss).
struct ProbeData {
  torch::Tensor images, depth;
};

struct ProbeOptions {
  // Ridge lambdas tried, relative to the mean diagonal of X^T X: the one with the lowest AbsRel
  // on the last quarter of the training views is kept, then the head is refit on all of them.
  std::vector<double> ridges = {1e-4, 1e-3, 1e-2, 1e-1};
  int batch = 16;  // encoder batch
};

// Encoder features [B, N, D] of every image, unmasked, without gradients.
torch::Tensor encoderFeatures(CroCoNet& model, const torch::Tensor& images, int batch = 16);

class DepthProbe {
 public:
  // Fits the head on `train` with the frozen encoder's features. Patches with a pixel without
  // depth are left out of the fit.
  DepthProbe(CroCoNet& model, const ProbeData& train, const ProbeOptions& options = {});
  // Predicted z-depth [B, S, S].
  torch::Tensor predict(const torch::Tensor& images) const;
  DepthMetrics evaluate(const ProbeData& test) const;

 private:
  CroCoNet& model_;
  ProbeOptions options_;
  double ridge_ = 0;       // the lambda kept
  torch::Tensor weights_;  // [2 D + 1, p * p], float64

 public:
  double ridge() const { return ridge_; }
};

// Two-fold cross-fitting: a head fit on `a` is tested on `b` and one fit on `b` on `a`; the
// metrics are over the predictions of both. Every view is tested once, so the figures are less
// noisy than one split's for the same views.
DepthMetrics crossFitProbe(CroCoNet& model, const ProbeData& a, const ProbeData& b,
                           const ProbeOptions& options = {});

}  // namespace paircast
