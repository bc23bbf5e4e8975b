// The DPT head of CroCo's downstream models, module for module and name for name naver/croco's
// PixelwiseTaskWithDPT (models/head_downstream.py) around its DPTOutputAdapter
// (models/dpt_block.py), so that its state_dict loads strictly there: "dpt.act_postprocess.*",
// "dpt.scratch.layer{1..4}_rn" (also as "dpt.scratch.layer_rn.{0..3}", the same modules),
// "dpt.scratch.refinenet{1..4}.*" and "dpt.head.{0,2,4}".
//
// Four token maps [B, N, D_k] (the hooked blocks, grid G x G) are reassembled at 4G, 2G, G and
// G/2, projected to 256 channels, fused from coarse to fine (each fusion doubles the size) and
// regressed to num_channels at 16 G: the image size for 16-pixel patches. So the head takes
// patch 16 and image sides divisible by 32 (the G/2 map must double back to G).
#pragma once

#include <torch/torch.h>

#include <nlohmann/json.hpp>
#include <vector>

namespace paircast {

struct DptOptions {
  std::vector<int> hooks;  // the 4 block indices (encoder blocks, then decoder's)
  std::vector<int> layerDims{96, 192, 384, 768};
  std::vector<int> tokenDims;  // width of each hooked block's tokens
  int numChannels = 1;
  int featureDim = 256;  // DPTOutputAdapter's defaults
  int lastDim = 32;
};

// naver/croco's ResidualConvUnit_custom without batch norm: x + conv2(relu(conv1(relu(x)))).
struct ResidualConvUnitImpl : torch::nn::Module {
  explicit ResidualConvUnitImpl(int features);
  torch::Tensor forward(const torch::Tensor& x);
  torch::nn::Conv2d conv1{nullptr}, conv2{nullptr};
};
TORCH_MODULE(ResidualConvUnit);

// FeatureFusionBlock_custom: (x [+ resConfUnit1(skip)]) -> resConfUnit2 -> x2 bilinear
// (align_corners) -> out_conv.
struct FusionBlockImpl : torch::nn::Module {
  explicit FusionBlockImpl(int features);
  torch::Tensor forward(const torch::Tensor& x, const torch::Tensor& skip = {});
  torch::nn::Conv2d out_conv{nullptr};
  ResidualConvUnit resConfUnit1{nullptr}, resConfUnit2{nullptr};
};
TORCH_MODULE(FusionBlock);

struct DptAdapterImpl : torch::nn::Module {
  explicit DptAdapterImpl(const DptOptions& o);
  // `blocks`: every block's tokens in order; returns [B, numChannels, H, W].
  torch::Tensor forward(const std::vector<torch::Tensor>& blocks, int64_t height, int64_t width);
  DptOptions options;
  std::vector<torch::nn::Sequential> act;  // act_{1..4}_postprocess (also act_postprocess.k)
  std::vector<torch::nn::Conv2d> layerRn;  // scratch.layer{1..4}_rn (also scratch.layer_rn.k)
  std::vector<FusionBlock> refine;         // scratch.refinenet{1..4}
  torch::nn::Sequential head{nullptr};
};
TORCH_MODULE(DptAdapter);

// PixelwiseTaskWithDPT: its one child is "dpt".
struct PixelwiseDptImpl : torch::nn::Module {
  explicit PixelwiseDptImpl(const DptOptions& o);
  torch::Tensor forward(const std::vector<torch::Tensor>& blocks, int64_t height, int64_t width) {
    return dpt->forward(blocks, height, width);
  }
  DptAdapter dpt{nullptr};
};
TORCH_MODULE(PixelwiseDpt);

// naver/croco's default hooks where it has them: with a decoder of depth 8, 12 or 24, the blocks
// E + D - 1 - i * {3, 4, 8}[D] for i = 3..0 of the E + D encoder and decoder blocks; encoder
// alone, E - 1 - i * (E / 4). Other decoder depths (paircast's presets) take the last encoder
// block and the decoder's last three blocks at a step of max(1, D / 3): tiny (6 + 2 blocks)
// [5, 5, 6, 7], small (12 + 4) [11, 13, 14, 15].
std::vector<int> defaultDptHooks(int encDepth, int decDepth /* 0: encoder alone */);

// Whether the DPT head takes this geometry; the reason when it does not ("" when it does).
std::string dptSizeProblem(int imgSize, int patchSize);

// PixelwiseTaskWithDPT(**head_kwargs)'s arguments for these options.
nlohmann::json dptHeadKwargs(const DptOptions& o);

}  // namespace paircast
