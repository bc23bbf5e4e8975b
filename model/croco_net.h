// CroCo (cross-view completion) in LibTorch, module for module and name for name the official
// PyTorch CroCoNet (naver/croco models/croco.py), so that state_dicts move both ways.
//
// Shapes, one legend for the whole model:
//   B batch, N patches per image (grid G x G), Nv visible patches of image 1,
//   D encoder width, Dd decoder width, H heads, P = patch * patch * 3, S = img_size.
#pragma once

#include <torch/torch.h>

#include <tuple>

#include "model/croco_config.h"

namespace paircast {

// MAE's 2D sine-cosine embedding, [N, dim]: the first half encodes the column, the second the
// row (CroCo's get_2d_sincos_pos_embed, whose meshgrid puts w first); each half is
// [sin(p w_i), cos(p w_i)] with w_i = 1 / 10000^(i / (dim / 4)).
torch::Tensor sincosPosEmbed(int dim, int grid);

// Patch positions (row, col), [N, 2] int64, row-major.
torch::Tensor patchPositions(int grid);

// The residual stream in float32 under autocast: the patch and decoder embeddings come out of
// autocast in bf16 or fp16, and with cosine embeddings adding the float32 table promotes them.
// With RoPE there is no table, and LibTorch 1.13's CPU LayerNorm refuses a bf16 input with
// float32 weights; so both embeddings go through this, whatever the positions.
inline torch::Tensor residualStream(const torch::Tensor& x) {
  const auto t = x.scalar_type();
  return t == torch::kBFloat16 || t == torch::kHalf ? x.to(torch::kFloat32) : x;
}

// 2D rotary embedding (CroCo v2's RoPE2D): the first half of each head's channels rotates with
// the row, the second with the column. tokens [B, H, N, Dh], positions [B, N, 2].
torch::Tensor applyRope2d(const torch::Tensor& tokens, const torch::Tensor& positions, double freq);

struct MlpImpl : torch::nn::Module {
  MlpImpl(int dim, int hidden);
  torch::Tensor forward(const torch::Tensor& x);
  torch::nn::Linear fc1{nullptr}, fc2{nullptr};
};
TORCH_MODULE(Mlp);

struct AttentionImpl : torch::nn::Module {
  AttentionImpl(int dim, int heads, double ropeFreq);
  torch::Tensor forward(const torch::Tensor& x, const torch::Tensor& pos);  // x [B, N, D]
  torch::nn::Linear qkv{nullptr}, proj{nullptr};
  int heads;
  double ropeFreq;  // 0: no RoPE
};
TORCH_MODULE(Attention);

struct CrossAttentionImpl : torch::nn::Module {
  CrossAttentionImpl(int dim, int heads, double ropeFreq);
  torch::Tensor forward(const torch::Tensor& q, const torch::Tensor& kv, const torch::Tensor& qpos,
                        const torch::Tensor& kpos, torch::Tensor* scores = nullptr);
  torch::nn::Linear projq{nullptr}, projk{nullptr}, projv{nullptr}, proj{nullptr};
  int heads;
  double ropeFreq;
};
TORCH_MODULE(CrossAttention);

// Pre-norm transformer block (encoder, and the "cat" decoder).
struct BlockImpl : torch::nn::Module {
  BlockImpl(int dim, int heads, int mlpRatio, double ropeFreq);
  torch::Tensor forward(const torch::Tensor& x, const torch::Tensor& pos);
  torch::nn::LayerNorm norm1{nullptr}, norm2{nullptr};
  Attention attn{nullptr};
  Mlp mlp{nullptr};
};
TORCH_MODULE(Block);

// The official DecoderBlock: self-attention, cross-attention to the second image, MLP. With y
// undefined there is no second image: the cross-attention attends to nothing, and as a softmax
// over an empty memory contributes nothing, its residual branch is skipped. `crossScores`, when
// given, receives the cross-attention's pre-softmax scores q k^T / sqrt(Dh), [B, H, N, Ny].
struct DecoderBlockImpl : torch::nn::Module {
  DecoderBlockImpl(int dim, int heads, int mlpRatio, bool normMem, double ropeFreq);
  torch::Tensor forward(const torch::Tensor& x, const torch::Tensor& y, const torch::Tensor& xpos,
                        const torch::Tensor& ypos, torch::Tensor* crossScores = nullptr);
  torch::nn::LayerNorm norm1{nullptr}, norm2{nullptr}, norm3{nullptr}, norm_y{nullptr};
  Attention attn{nullptr};
  CrossAttention cross_attn{nullptr};
  Mlp mlp{nullptr};
};
TORCH_MODULE(DecoderBlock);

struct PatchEmbedImpl : torch::nn::Module {
  PatchEmbedImpl(int patch, int dim);
  torch::Tensor forward(const torch::Tensor& img);  // [B, 3, S, S] -> [B, N, D]
  torch::nn::Conv2d proj{nullptr};
};
TORCH_MODULE(PatchEmbed);

struct CroCoOutput {
  torch::Tensor prediction;  // [B, N, P] raw head output
  torch::Tensor mask;        // [B, N] bool, true = masked
  torch::Tensor target;      // [B, N, P] patchified image 1
};

class CroCoNetImpl : public torch::nn::Module {
 public:
  explicit CroCoNetImpl(const CroCoConfig& config);

  // Masks image 1 at random (RandomMask: argsort(uniform noise) < num_mask, per image).
  CroCoOutput forward(const torch::Tensor& img1, const torch::Tensor& img2);
  // With a given mask [B, N] bool (each row with the same count of true). With img2 undefined,
  // auto-completion (MAE): image 1 is completed from its own visible patches only, and the
  // decoder gets no reference (the cross decoder's cross-attention attends to nothing, the cat
  // decoder sees image 1's tokens alone). The parameters are the same either way.
  // `crossScores`, when given (cross decoder and img2 only), receives the decoder's
  // cross-attention scores before the softmax, averaged over blocks and heads: [B, N, N], image
  // 1's patches (queries) against image 2's (keys). ZeroCo reads them as a cost volume.
  CroCoOutput forward(const torch::Tensor& img1, const torch::Tensor& img2,
                      const torch::Tensor& mask, torch::Tensor* crossScores = nullptr);
  torch::Tensor randomMask(int64_t batch, const torch::Device& device) const;

  // Encoder: features [B, Nv, D] of the visible patches (all when mask is undefined).
  torch::Tensor encode(const torch::Tensor& img, const torch::Tensor& mask);

  const CroCoConfig& config() const { return config_; }
  void initializeWeights();

  PatchEmbed patch_embed{nullptr};
  torch::nn::ModuleList enc_blocks{nullptr}, dec_blocks{nullptr};
  torch::nn::LayerNorm enc_norm{nullptr}, dec_norm{nullptr};
  torch::nn::Linear decoder_embed{nullptr}, prediction_head{nullptr};
  torch::Tensor mask_token;                    // [1, 1, Dd]
  torch::Tensor enc_pos_embed, dec_pos_embed;  // [N, D], [N, Dd] buffers (cosine only)
  torch::Tensor view_embed1, view_embed2;      // [1, 1, Dd], "cat" decoder only

 private:
  CroCoConfig config_;
  torch::Tensor positions_;  // [N, 2] (row, col)
};
TORCH_MODULE(CroCoNet);

// The reference view a model trained on `task` is given: img2 for "croco" (cross-view
// completion), none (undefined) for "mae", which completes view 1 alone.
torch::Tensor taskReference(const std::string& task, const torch::Tensor& img2);

// [B, 3, S, S] -> [B, N, P], each patch flattened as (row, col, channel), as CroCo's patchify.
torch::Tensor patchify(const torch::Tensor& imgs, int patch);
torch::Tensor unpatchify(const torch::Tensor& x, int patch, int channels = 3);
// Per-patch normalisation of the target: (t - mean) / sqrt(unbiased var + 1e-6).
torch::Tensor normalizePatches(const torch::Tensor& target);
// MaskedMSE with norm_pix_loss: mean over the masked patches of the per-patch mean squared error.
torch::Tensor maskedMse(const torch::Tensor& prediction, const torch::Tensor& mask,
                        const torch::Tensor& target, bool normPix = true);
// The loss of every patch, [B, N]: the mean squared error against the (normalised) target.
torch::Tensor patchLosses(const torch::Tensor& prediction, const torch::Tensor& target,
                          bool normPix = true);

// ImageNet mean and std, as the official transforms normalise images.
torch::Tensor imagenetNormalize(const torch::Tensor& rgb01);  // [B, 3, S, S] in [0, 1]
torch::Tensor imagenetDenormalize(const torch::Tensor& normed);

int64_t countParameters(torch::nn::Module& module);

}  // namespace paircast
