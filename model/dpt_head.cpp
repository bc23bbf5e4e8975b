#include "model/dpt_head.h"

#include <string>

#include "util/error.h"

namespace paircast {
namespace {

namespace F = torch::nn::functional;

torch::nn::Conv2d conv(int in, int out, int kernel, int stride = 1, int padding = 0,
                       bool bias = true) {
  return torch::nn::Conv2d(
      torch::nn::Conv2dOptions(in, out, kernel).stride(stride).padding(padding).bias(bias));
}

torch::Tensor upsample2(const torch::Tensor& x) {
  return F::interpolate(x, F::InterpolateFuncOptions()
                               .scale_factor(std::vector<double>{2.0, 2.0})
                               .mode(torch::kBilinear)
                               .align_corners(true));
}

// act_k_postprocess: a 1x1 projection to layerDims[k], then to the scale of map k: x4 and x2
// (transposed convs), x1, /2 (a strided 3x3 conv).
torch::nn::Sequential reassemble(int k, int tokens, int dim) {
  torch::nn::Sequential s;
  s->push_back(conv(tokens, dim, 1));
  if (k == 0 || k == 1) {
    const int f = k == 0 ? 4 : 2;
    s->push_back(
        torch::nn::ConvTranspose2d(torch::nn::ConvTranspose2dOptions(dim, dim, f).stride(f)));
  } else if (k == 3) {
    s->push_back(conv(dim, dim, 3, 2, 1));
  }
  return s;
}

}  // namespace

ResidualConvUnitImpl::ResidualConvUnitImpl(int features) {
  conv1 = register_module("conv1", conv(features, features, 3, 1, 1));
  conv2 = register_module("conv2", conv(features, features, 3, 1, 1));
}

torch::Tensor ResidualConvUnitImpl::forward(const torch::Tensor& x) {
  // In place where autograd allows it (a convolution's backward needs its input, not its output):
  // two fewer maps of the fine levels written a step.
  return conv2(conv1(torch::relu(x)).relu_()).add_(x);
}

FusionBlockImpl::FusionBlockImpl(int features) {
  out_conv = register_module("out_conv", conv(features, features, 1));
  resConfUnit1 = register_module("resConfUnit1", ResidualConvUnit(features));
  resConfUnit2 = register_module("resConfUnit2", ResidualConvUnit(features));
}

torch::Tensor FusionBlockImpl::forward(const torch::Tensor& x, const torch::Tensor& skip) {
  auto out = skip.defined() ? x + resConfUnit1(skip) : x;
  // naver/croco upsamples, then applies the 1x1 out_conv. Both are linear and act on different
  // axes (the bilinear weights sum to 1, so the bias passes through), so they commute: the 1x1
  // convolution runs at a quarter of the pixels. Outputs agree within float rounding.
  return upsample2(out_conv(resConfUnit2(out)));
}

DptAdapterImpl::DptAdapterImpl(const DptOptions& o) : options(o) {
  PAIRCAST_CHECK(o.hooks.size() == 4 && o.layerDims.size() == 4 && o.tokenDims.size() == 4);
  // Registration follows naver/croco's: scratch (its convs, the list of them, the fusions), the
  // regression head, then the reassembly (as init() adds it).
  auto scratch = register_module("scratch", std::make_shared<torch::nn::Module>());
  auto list = torch::nn::ModuleList();
  for (int k = 0; k < 4; ++k) {
    layerRn.push_back(conv(o.layerDims[k], o.featureDim, 3, 1, 1, /*bias=*/false));
    scratch->register_module("layer" + std::to_string(k + 1) + "_rn", layerRn.back());
    list->push_back(layerRn.back());
  }
  scratch->register_module("layer_rn", list);
  for (int k = 0; k < 4; ++k) {
    refine.push_back(FusionBlock(o.featureDim));
    scratch->register_module("refinenet" + std::to_string(k + 1), refine.back());
  }
  head = register_module(
      "head", torch::nn::Sequential(conv(o.featureDim, o.featureDim / 2, 3, 1, 1),
                                    torch::nn::Functional(upsample2),
                                    conv(o.featureDim / 2, o.lastDim, 3, 1, 1), torch::nn::ReLU(),
                                    conv(o.lastDim, o.numChannels, 1)));
  auto acts = torch::nn::ModuleList();
  for (int k = 0; k < 4; ++k) {
    act.push_back(reassemble(k, o.tokenDims[k], o.layerDims[k]));
    register_module("act_" + std::to_string(k + 1) + "_postprocess", act.back());
    acts->push_back(act.back());
  }
  register_module("act_postprocess", acts);
}

torch::Tensor DptAdapterImpl::forward(const std::vector<torch::Tensor>& blocks, int64_t height,
                                      int64_t width) {
  const int64_t gh = height / 16, gw = width / 16;
  std::vector<torch::Tensor> maps;
  for (int k = 0; k < 4; ++k) {
    const int hook = options.hooks[k];
    PAIRCAST_CHECK_MSG(hook >= 0 && hook < static_cast<int>(blocks.size()),
                       "DPT hook " + std::to_string(hook) + " out of range");
    const auto& t = blocks[hook];  // [B, N, D]
    auto grid = t.transpose(1, 2).reshape({t.size(0), t.size(2), gh, gw});
    maps.push_back(layerRn[k](act[k]->forward(grid)));
  }
  auto path = refine[3](maps[3]);
  path = refine[2](path, maps[2]);
  path = refine[1](path, maps[1]);
  path = refine[0](path, maps[0]);
  return head->forward(path);
}

PixelwiseDptImpl::PixelwiseDptImpl(const DptOptions& o) {
  dpt = register_module("dpt", DptAdapter(o));
}

std::vector<int> defaultDptHooks(int encDepth, int decDepth) {
  std::vector<int> hooks;
  if (decDepth == 0) {
    const int step = encDepth / 4;
    for (int i = 3; i >= 0; --i) hooks.push_back(std::max(0, encDepth - 1 - i * step));
    return hooks;
  }
  const int last = encDepth + decDepth - 1;
  if (decDepth == 8 || decDepth == 12 || decDepth == 24) {
    const int step = decDepth == 8 ? 3 : decDepth == 12 ? 4 : 8;
    for (int i = 3; i >= 0; --i) hooks.push_back(last - i * step);
    return hooks;
  }
  const int step = std::max(1, decDepth / 3);
  hooks.push_back(encDepth - 1);
  for (int i = 2; i >= 0; --i) hooks.push_back(std::max(encDepth - 1, last - i * step));
  return hooks;
}

std::string dptSizeProblem(int imgSize, int patchSize) {
  if (patchSize != 16)
    return "the DPT head needs 16-pixel patches, not " + std::to_string(patchSize);
  if (imgSize % 32 != 0)
    return "the DPT head needs an image side divisible by 32 (128, 160, 192, 224, 256, ...), "
           "not " +
           std::to_string(imgSize);
  return "";
}

nlohmann::json dptHeadKwargs(const DptOptions& o) {
  return {{"hooks_idx", o.hooks}, {"layer_dims", o.layerDims}, {"num_channels", o.numChannels}};
}

}  // namespace paircast
