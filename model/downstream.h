// CroCo's downstream models in LibTorch (naver/croco models/croco_downstream.py), with its names:
//   - "flow" (CroCoDownstreamBinocular): both images through the encoder, image 1's tokens through
//     the decoder with image 2's as memory; the head reads image 1's encoder blocks then the
//     decoder's (only the last of each normalised), as naver/croco's forward returns them.
//   - "depth" (CroCoDownstreamMonocularEncoder): the encoder alone.
//   - "pose": the binocular trunk with a relative-pose head (paircast's own: the paper's has no
//     public code) on the decoder's last block, ending in an SVD Procrustes layer.
// Heads: "dpt" (PixelwiseTaskWithDPT, model/dpt_head.h, under "head."), "linear" (the paper's flow
// head: CroCo's prediction head regressing 2 channels per patch pixel, "prediction_head"; for
// depth, 1 channel from the encoder's tokens, for sizes the DPT head does not take), and "pose"
// (under "head.").
//
// The CroCo parts keep CroCoNet's names (patch_embed, enc_blocks, enc_norm, decoder_embed,
// dec_blocks, dec_norm and the cosine pos_embed buffers) and have no mask token: a flow or depth
// checkpoint with the DPT head loads strictly into naver/croco's class built with the
// checkpoint's croco_kwargs and PixelwiseTaskWithDPT(**head_kwargs).
#pragma once

#include <torch/torch.h>

#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "model/checkpoint.h"
#include "model/croco_config.h"
#include "model/croco_net.h"
#include "model/dpt_head.h"

namespace paircast {

struct DownstreamConfig {
  // The widest DPT layer accepted (naver/croco's largest is 768): a checkpoint's head_kwargs are
  // untrusted.
  static constexpr int kMaxLayerDim = 4096;
  // Throws OptionError naming the field (the DPT head's image size among them).
  void validate() const;
  bool binocular() const { return task != "depth"; }
  // Output channels of the pixel-wise head: flow 2 (+1 confidence with the DPT head), depth 1.
  int channels() const;
  // The head's parameters, counted from the configuration alone: a checkpoint's must be checked
  // before the head is built (the DPT head's reassembly grows with layer_dims squared: 4 x 4,096
  // asks for 2 GB).
  int64_t headParameters() const;

  CroCoConfig croco;
  std::string task = "flow";  // flow, depth or pose
  std::string head = "dpt";   // dpt or linear (flow, depth); pose (pose)
  std::vector<int> hooks;     // DPT hooks; empty: defaultDptHooks
  std::vector<int> layerDims{96, 192, 384, 768};
  // Flow: the head regresses flow / flowScale, and forward() returns it times flowScale, in
  // pixels; the loss compares both in those units (docs/finetune.md, "Flow scale"). 0: the
  // default, img_size / 16 (4 pixels at 64, 8 at 128). A checkpoint keeps the value it was
  // trained with ("flow_scale"); one without it regressed pixels (1).
  double flowScale = 0;
  double flowScaleInUse() const;
};

// The flow scale a model of `imgSize` pixels takes by default: imgSize / 16.
double defaultFlowScale(int imgSize);

// The relative-pose head: each patch of the decoder's last block (normalised) through a linear
// layer and a GELU, then all patches' features in their order through a second linear layer, to
// a 3x3 matrix M (plus 2 I, so that it starts near the identity) and a translation; R is the
// rotation nearest M (SVD, with the sign that makes det R = +1).
struct PoseHeadImpl : torch::nn::Module {
  PoseHeadImpl(int dim, int patches, int hidden = 64);
  // tokens [B, N, Dd] -> [B, 12]: R row-major (9), then t (3).
  torch::Tensor forward(const torch::Tensor& tokens);
  torch::nn::Linear fc1{nullptr}, fc2{nullptr};
};
TORCH_MODULE(PoseHead);

// The rotation nearest each [B, 3, 3] matrix in the Frobenius norm (the Procrustes solution),
// computed in float64 and returned in m's type. Its gradient is the closed form, finite where
// singular values repeat (LibTorch's SVD gradient is NaN at M = c I).
torch::Tensor procrustesRotation(const torch::Tensor& m);

class DownstreamNetImpl : public torch::nn::Module {
 public:
  explicit DownstreamNetImpl(const DownstreamConfig& config);

  // flow: [B, channels, S, S] (u, v in pixels: the head's output times flowScaleInUse(), then
  // the DPT head's confidence); depth:
  // [B, 1, S, S] (log-depth); pose: [B, 12]. img2 is ignored by depth.
  torch::Tensor forward(const torch::Tensor& img1, const torch::Tensor& img2 = {});

  const DownstreamConfig& config() const { return config_; }
  const std::vector<int>& hooks() const { return hooks_; }

  // The state_dict (both names of the DPT head's shared modules) and the checkpoint entries that
  // rebuild the model: croco_kwargs (CroCoNet's arguments), head_kwargs, task, head.
  std::map<std::string, torch::Tensor> state() const { return stateDict(*this); }
  nlohmann::json checkpointEntries() const;
  // Parameters, each once (the DPT head registers some modules under two names).
  std::vector<std::pair<std::string, torch::Tensor>> uniqueParameters() const;

  // Copies the encoder (and, for a model trained on cross-view completion, the decoder) of a
  // pre-training checkpoint; what it does not have stays as initialised. Returns the parts
  // copied ("encoder", "encoder+decoder"). Throws paircast::Error naming `source` when the
  // widths or depths differ, or when it is a fine-tuning checkpoint.
  std::string initFromPretrained(const Checkpoint& ck, const std::string& source);

  PatchEmbed patch_embed{nullptr};
  torch::nn::ModuleList enc_blocks{nullptr}, dec_blocks{nullptr};
  torch::nn::LayerNorm enc_norm{nullptr}, dec_norm{nullptr};
  torch::nn::Linear decoder_embed{nullptr}, prediction_head{nullptr};
  torch::Tensor enc_pos_embed, dec_pos_embed;
  PixelwiseDpt dpt_head{nullptr};  // registered as "head"
  PoseHead pose_head{nullptr};     // registered as "head"

 private:
  std::vector<torch::Tensor> encodeBlocks(const torch::Tensor& img, bool all);
  std::vector<torch::Tensor> decodeBlocks(const torch::Tensor& f1, const torch::Tensor& f2);
  // A flow head's output [B, C, S, S] with u, v times flowScaleInUse().
  torch::Tensor inPixels(const torch::Tensor& flow) const;

  DownstreamConfig config_;
  std::vector<int> hooks_;
  torch::Tensor positions_;  // [N, 2]
};
TORCH_MODULE(DownstreamNet);

// The fine-tuning checkpoint's config (croco_kwargs, task, head, head_kwargs); throws
// paircast::Error naming `source` when it is not a fine-tuning checkpoint.
DownstreamConfig downstreamConfigOf(const Checkpoint& ck, const std::string& source);

}  // namespace paircast
