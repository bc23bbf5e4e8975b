#include "sweep/depth_probe.h"

#include "util/error.h"

namespace paircast {

nlohmann::json DepthMetrics::toJson() const {
  return {{"delta1", delta1}, {"absrel", absRel}, {"rmse", rmse}, {"pixels", pixels}};
}

DepthMetrics depthMetrics(const torch::Tensor& predIn, const torch::Tensor& gtIn) {
  if (predIn.sizes() != gtIn.sizes())
    throw Error("depthMetrics: prediction and ground truth differ in shape");
  const auto pred = predIn.to(torch::kFloat64).flatten(), gt = gtIn.to(torch::kFloat64).flatten();
  const auto valid = torch::logical_and(gt > 0, torch::isfinite(gt));
  DepthMetrics m;
  m.pixels = valid.sum().item<int64_t>();
  if (m.pixels == 0) throw Error("depthMetrics: no valid ground-truth pixel");
  const auto p = pred.masked_select(valid).clamp_min(1e-6), g = gt.masked_select(valid);
  const auto ratio = torch::maximum(p / g, g / p);
  m.delta1 = (ratio < 1.25).to(torch::kFloat64).mean().item<double>();
  m.absRel = ((p - g).abs() / g).mean().item<double>();
  m.rmse = std::sqrt((p - g).pow(2).mean().item<double>());
  return m;
}

torch::Tensor encoderFeatures(CroCoNet& model, const torch::Tensor& images, int batch) {
  torch::NoGradGuard ng;
  const bool wasTraining = model->is_training();
  model->eval();
  std::vector<torch::Tensor> out;
  for (int64_t i = 0; i < images.size(0); i += batch)
    out.push_back(model
                      ->encode(images.slice(0, i, std::min<int64_t>(i + batch, images.size(0))),
                               torch::Tensor())
                      .to(torch::kFloat32));  // bf16 under autocast
  if (wasTraining) model->train();
  return torch::cat(out);
}

namespace {

// [B, S, S] -> [B, N, p*p], patches in row-major order, pixels (row, col) within a patch.
torch::Tensor depthPatches(const torch::Tensor& depth, int p) {
  const int64_t B = depth.size(0), S = depth.size(1), n = S / p;
  return depth.reshape({B, n, p, n, p}).permute({0, 1, 3, 2, 4}).reshape({B, n * n, p * p});
}

// [B, N, D] features -> [B * N, 2 D + 1] design rows: the patch, its image's mean, 1.
torch::Tensor design(const torch::Tensor& feats) {
  const auto f = feats.to(torch::kFloat64);
  const auto ctx = f.mean(1, true).expand_as(f);
  const auto x = torch::cat({f, ctx}, 2).reshape({-1, 2 * f.size(2)});
  return torch::cat({x, torch::ones({x.size(0), 1}, torch::kFloat64)}, 1);
}

torch::Tensor ridgeFit(const torch::Tensor& X, const torch::Tensor& Y, double relative) {
  auto A = X.t().matmul(X);
  const double lambda = relative * A.diagonal().mean().item<double>();
  A = A + lambda * torch::eye(A.size(0), torch::kFloat64);
  return torch::linalg_solve(A, X.t().matmul(Y));
}

// Rows of X and log Y for the patches whose pixels all have depth.
std::pair<torch::Tensor, torch::Tensor> fitRows(const torch::Tensor& feats,
                                                const torch::Tensor& depth, int p) {
  const auto X = design(feats);
  const auto Y = depthPatches(depth.to(torch::kFloat64), p).reshape({-1, p * p});
  const auto keep = (Y > 0).all(1);
  if (keep.sum().item<int64_t>() < 1)
    throw Error("depth probe: no patch with full depth to fit the head on");
  return {X.index({keep}), torch::log(Y.index({keep}))};
}

torch::Tensor predictWith(const torch::Tensor& feats, const torch::Tensor& w, int p, int S) {
  const int n = S / p;
  const int64_t B = feats.size(0);
  return torch::exp(design(feats).matmul(w).clamp(-10, 10))
      .reshape({B, n, n, p, p})
      .permute({0, 1, 3, 2, 4})
      .reshape({B, S, S});
}

}  // namespace

DepthProbe::DepthProbe(CroCoNet& model, const ProbeData& train, const ProbeOptions& options)
    : model_(model), options_(options) {
  const int p = model->config().patch_size, S = model->config().img_size;
  const auto feats = encoderFeatures(model, train.images, options.batch);  // [B, N, D]
  const int64_t B = feats.size(0), fitB = std::max<int64_t>(1, B - B / 4);
  ridge_ = options.ridges.empty() ? 1e-3 : options.ridges.front();
  if (options.ridges.size() > 1 && fitB < B) {
    const auto [X, Y] = fitRows(feats.slice(0, 0, fitB), train.depth.slice(0, 0, fitB), p);
    double best = INFINITY;
    for (double r : options.ridges) {
      const auto pred = predictWith(feats.slice(0, fitB), ridgeFit(X, Y, r), p, S);
      const double absRel = depthMetrics(pred, train.depth.slice(0, fitB)).absRel;
      if (absRel < best) best = absRel, ridge_ = r;
    }
  }
  const auto [X, Y] = fitRows(feats, train.depth, p);
  weights_ = ridgeFit(X, Y, ridge_);
}

torch::Tensor DepthProbe::predict(const torch::Tensor& images) const {
  return predictWith(encoderFeatures(model_, images, options_.batch), weights_,
                     model_->config().patch_size, model_->config().img_size);
}

DepthMetrics DepthProbe::evaluate(const ProbeData& test) const {
  return depthMetrics(predict(test.images), test.depth);
}

DepthMetrics crossFitProbe(CroCoNet& model, const ProbeData& a, const ProbeData& b,
                           const ProbeOptions& options) {
  const auto predB = DepthProbe(model, a, options).predict(b.images);
  const auto predA = DepthProbe(model, b, options).predict(a.images);
  return depthMetrics(torch::cat({predB, predA}), torch::cat({b.depth, a.depth}));
}

}  // namespace paircast
