#include "finetune/evaluate.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>

#include "covis/covisibility.h"
#include "util/error.h"

namespace paircast {
namespace {

torch::Tensor box(const torch::Tensor& t, int64_t top, int64_t left, int64_t size) {
  return t.narrow(2, top, size).narrow(3, left, size);
}

// The contiguous range of coordinates that tile `i` owns.
std::pair<int64_t, int64_t> ownedRange(const TileAxis& a, size_t i) {
  const auto first = std::find(a.owner.begin(), a.owner.end(), static_cast<int64_t>(i));
  const auto last =
      std::find_if(first, a.owner.end(), [&](int64_t o) { return o != static_cast<int64_t>(i); });
  return {first - a.owner.begin(), last - a.owner.begin()};
}

double meanOf(const torch::Tensor& values) {
  return values.numel() ? values.to(torch::kFloat64).mean().item<double>() : NAN;
}

nlohmann::json number(double v) {
  return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr);
}

double median(std::vector<double> v) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

torch::Tensor identityPose() {
  return torch::tensor({1.f, 0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 0.f});
}

// The model's and the baseline's figures for one pair.
std::pair<nlohmann::json, nlohmann::json> pairFigures(DownstreamNet& net, const TruthPair& p,
                                                      double constantDepth,
                                                      const torch::Device& device) {
  const std::string& task = net->config().task;
  const torch::Tensor x1 = normalizedImage(p.rgb1).to(device),
                      x2 = normalizedImage(p.rgb2).to(device);
  const torch::Tensor out = predict(net, x1, x2).to(torch::kCPU).to(torch::kFloat32);
  if (task == "flow") {
    const torch::Tensor truth = planes(p.flow)[0];
    const Image8 seen = visibilityMask(p.camera1, p.depth1, p.camera2, p.depth2);
    const torch::Tensor covisible = torch::from_blob(const_cast<uint8_t*>(seen.data.data()),
                                                     {seen.height, seen.width}, torch::kUInt8)
                                        .to(torch::kBool);
    return {flowMetrics(out[0].narrow(0, 0, 2), truth, covisible),
            flowMetrics(torch::zeros_like(truth), truth, covisible)};
  }
  if (task == "depth") {
    const torch::Tensor truth = planes(p.depth1)[0];
    return {depthMetrics(torch::exp(out[0]), truth),
            depthMetrics(torch::full_like(truth, constantDepth), truth)};
  }
  const torch::Tensor truth = poseVector(p.camera1, p.camera2);
  return {poseMetrics(out[0], truth), poseMetrics(identityPose(), truth)};
}

}  // namespace

TileAxis tileAxis(int64_t length, int64_t tile) {
  TileAxis a;
  const int64_t span = length - tile;
  const int64_t n = span <= 0 ? 1 : (span + tile / 2 - 1) / (tile / 2) + 1;
  for (int64_t i = 0; i < n; ++i)
    a.origins.push_back(n == 1 ? 0
                               : static_cast<int64_t>(std::llround(double(i) * span / (n - 1))));
  a.owner.resize(length);
  for (int64_t x = 0; x < length; ++x) {
    double best = INFINITY;
    for (int64_t i = 0; i < n; ++i) {
      const double d = std::abs(x + 0.5 - (a.origins[i] + 0.5 * tile));
      if (d < best) best = d, a.owner[x] = i;
    }
  }
  return a;
}

Tiling parseTiling(const std::string& name) {
  if (name == "nearest") return Tiling::kNearest;
  if (name == "confidence") return Tiling::kConfidence;
  throw OptionError("tiling", "tiling is 'nearest' or 'confidence', not '" + name + "'");
}

namespace {

// Each tile's weight per pixel under kConfidence: [1, 1, S, S].
torch::Tensor tileWeight(const DownstreamNet& net, const torch::Tensor& tile) {
  const auto& c = net->config();
  if (c.task == "flow" && tile.size(1) == 3)
    return 1.0 / (3.75 * torch::sigmoid(tile.narrow(1, 2, 1)) + 0.25);
  return torch::ones_like(tile.narrow(1, 0, 1));
}

}  // namespace

torch::Tensor predict(DownstreamNet& net, const torch::Tensor& img1, const torch::Tensor& img2,
                      Tiling tiling) {
  torch::NoGradGuard noGrad;
  net->eval();
  const int64_t S = net->config().croco.img_size, H = img1.size(2), W = img1.size(3);
  if (H < S || W < S)
    throw Error("images of " + std::to_string(W) + "x" + std::to_string(H) +
                " are smaller than the model's tiles of " + std::to_string(S));
  if (net->config().task == "pose") {
    const int64_t top = (H - S) / 2, left = (W - S) / 2;
    return net->forward(box(img1, top, left, S), box(img2, top, left, S));
  }
  const TileAxis rows = tileAxis(H, S), cols = tileAxis(W, S);
  torch::Tensor out, weights;
  for (size_t i = 0; i < rows.origins.size(); ++i) {
    for (size_t j = 0; j < cols.origins.size(); ++j) {
      const int64_t top = rows.origins[i], left = cols.origins[j];
      // The same box in both images: the flow's values need no shift.
      const torch::Tensor tile = net->forward(
          box(img1, top, left, S), img2.defined() ? box(img2, top, left, S) : torch::Tensor());
      if (!out.defined()) out = torch::zeros({1, tile.size(1), H, W}, tile.options());
      if (tiling == Tiling::kConfidence) {
        if (!weights.defined()) weights = torch::zeros({1, 1, H, W}, tile.options());
        const torch::Tensor w = tileWeight(net, tile);
        box(out, top, left, S).add_(tile * w);
        box(weights, top, left, S).add_(w);
        continue;
      }
      const auto [y0, y1] = ownedRange(rows, i);
      const auto [x0, x1] = ownedRange(cols, j);
      out.narrow(2, y0, y1 - y0)
          .narrow(3, x0, x1 - x0)
          .copy_(tile.narrow(2, y0 - top, y1 - y0).narrow(3, x0 - left, x1 - x0));
    }
  }
  return weights.defined() ? out / weights : out;
}

torch::Tensor landsInFrame(const torch::Tensor& flow) {
  const int64_t H = flow.size(-2), W = flow.size(-1);
  const auto x = torch::arange(W, flow.options()).view({1, W}) + 0.5 + flow.select(-3, 0);
  const auto y = torch::arange(H, flow.options()).view({H, 1}) + 0.5 + flow.select(-3, 1);
  return (x >= 0) & (x < W) & (y >= 0) & (y < H);
}

nlohmann::json flowMetrics(const torch::Tensor& pred, const torch::Tensor& truth,
                           const torch::Tensor& covisible) {
  const torch::Tensor valid = torch::isfinite(truth).all(0);
  const torch::Tensor safe = torch::where(valid.unsqueeze(0), truth, torch::zeros_like(truth));
  const torch::Tensor err = (pred - safe).pow(2).sum(0).sqrt();
  const torch::Tensor e = err.masked_select(valid & landsInFrame(safe));
  return {{"aepe", number(meanOf(e))},
          {"aepe_covisible", number(meanOf(err.masked_select(valid & covisible)))},
          {"aepe_all_known", number(meanOf(err.masked_select(valid)))},
          {"px1", number(meanOf((e > 1).to(torch::kFloat64)))},
          {"px3", number(meanOf((e > 3).to(torch::kFloat64)))},
          {"px5", number(meanOf((e > 5).to(torch::kFloat64)))}};
}

nlohmann::json depthMetrics(const torch::Tensor& pred, const torch::Tensor& truth) {
  const torch::Tensor valid = (truth > 0) & torch::isfinite(truth);
  const torch::Tensor p = pred.masked_select(valid).to(torch::kFloat64).clamp_min(1e-6);
  const torch::Tensor t = truth.masked_select(valid).to(torch::kFloat64);
  return {{"delta1", number(meanOf((torch::max(p / t, t / p) < 1.25).to(torch::kFloat64)))},
          {"absrel", number(meanOf((p - t).abs() / t))},
          {"rmse", number(std::sqrt(meanOf((p - t).pow(2))))}};
}

nlohmann::json poseMetrics(const torch::Tensor& pred, const torch::Tensor& truth) {
  const torch::Tensor p = pred.to(torch::kFloat64), t = truth.to(torch::kFloat64);
  const torch::Tensor Rp = p.narrow(0, 0, 9).view({3, 3}), Rt = t.narrow(0, 0, 9).view({3, 3});
  const double cosine =
      std::clamp((torch::trace(torch::matmul(Rp.t(), Rt)).item<double>() - 1) / 2, -1.0, 1.0);
  return {{"trans_err", (p.narrow(0, 9, 3) - t.narrow(0, 9, 3)).norm().item<double>()},
          {"rot_err", std::acos(cosine) * 180.0 / M_PI}};
}

HeldOutFigures evaluateHeldOut(DownstreamNet& net, const TruthPairs& data, size_t limit,
                               double constantDepth, const torch::Device& device) {
  HeldOutFigures f;
  const size_t n = limit ? std::min(limit, data.size()) : data.size();
  for (size_t i = 0; i < n; ++i) {
    auto [model, baseline] = pairFigures(net, data.load(i), constantDepth, device);
    model["key"] = baseline["key"] = data.key(i);
    f.pairs.push_back(std::move(model));
    f.baseline.push_back(std::move(baseline));
  }
  return f;
}

nlohmann::json summariseFigures(const std::vector<nlohmann::json>& pairs) {
  std::map<std::string, std::vector<double>> values;
  for (const auto& p : pairs)
    for (auto it = p.begin(); it != p.end(); ++it)
      if (it.value().is_number()) values[it.key()].push_back(it.value().get<double>());
  nlohmann::json out = {{"pairs", pairs.size()}};
  for (auto& [k, v] : values) {
    const bool poseError = k == "trans_err" || k == "rot_err";
    double mean = 0;
    for (double x : v) mean += x / v.size();
    out[poseError ? "median_" + k : k] = poseError ? median(v) : mean;
  }
  return out;
}

Image8 flowColours(const ImageF& flow) {
  // The Middlebury wheel: red, yellow, green, cyan, blue, magenta in 15, 6, 4, 11, 13, 6 steps.
  const int steps[6] = {15, 6, 4, 11, 13, 6};
  std::vector<std::array<double, 3>> wheel;
  for (int s = 0; s < 6; ++s)
    for (int i = 0; i < steps[s]; ++i) {
      const double f = double(i) / steps[s];
      const std::array<double, 3> c[6] = {{1, f, 0},     {1 - f, 1, 0}, {0, 1, f},
                                          {0, 1 - f, 1}, {f, 0, 1},     {1, 0, 1 - f}};
      wheel.push_back(c[s]);
    }
  const int n = static_cast<int>(wheel.size());
  double maxRad = 1e-9;
  for (size_t i = 0; i < flow.size(); i += 2)
    if (std::isfinite(flow.data[i]) && std::isfinite(flow.data[i + 1]))
      maxRad = std::max(maxRad, std::hypot(double(flow.data[i]), double(flow.data[i + 1])));
  Image8 out(flow.width, flow.height, 3, 0);
  for (size_t p = 0; p < size_t(flow.width) * flow.height; ++p) {
    const double u = flow.data[2 * p] / maxRad, v = flow.data[2 * p + 1] / maxRad;
    if (!std::isfinite(u) || !std::isfinite(v)) continue;
    const double rad = std::hypot(u, v), a = std::atan2(-v, -u) / M_PI;
    const double fk = (a + 1) / 2 * (n - 1);
    const int k0 = static_cast<int>(std::floor(fk)) % n, k1 = (k0 + 1) % n;
    const double f = fk - std::floor(fk);
    for (int c = 0; c < 3; ++c) {
      double col = (1 - f) * wheel[k0][c] + f * wheel[k1][c];
      col = rad <= 1 ? 1 - rad * (1 - col) : col * 0.75;
      out.data[3 * p + c] = static_cast<uint8_t>(std::lround(255 * col));
    }
  }
  return out;
}

}  // namespace paircast
