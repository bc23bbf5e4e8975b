#include "model/croco_net.h"

#include <cmath>

#include "model/torch_compat.h"
#include "util/error.h"

namespace paircast {
namespace F = torch::nn::functional;

namespace {

constexpr double kLayerNormEps = 1e-6;

torch::nn::LayerNorm layerNorm(int dim) {
  return torch::nn::LayerNorm(torch::nn::LayerNormOptions({dim}).eps(kLayerNormEps));
}

// x W^T + b through at::linear, which folds the bias into the GEMM (addmm) for 3-D input. The
// C++ frontend's Linear::forward (F::linear) runs matmul and then `output += bias`: one more
// pass over every linear layer's output, which made our CPU forward slower than Python's.
torch::Tensor linear(const torch::nn::Linear& layer, const torch::Tensor& x) {
  return torch::linear(x, layer->weight, layer->bias);
}

using torch_compat::scaledDotProductAttention;

}  // namespace

torch::Tensor sincosPosEmbed(int dim, int grid) {
  PAIRCAST_CHECK(dim % 4 == 0);
  const int quarter = dim / 4;
  // omega_i = 1 / 10000^(i / quarter), in float64 as numpy computes it.
  auto omega = 1.0 / torch::pow(10000.0, torch::arange(quarter, torch::kFloat64) / quarter);
  auto pos = patchPositions(grid).to(torch::kFloat64);  // [N, 2] (row, col)
  auto embed1d = [&](const torch::Tensor& p) {          // [N] -> [N, dim / 2]
    auto out = torch::outer(p, omega);
    return torch::cat({torch::sin(out), torch::cos(out)}, 1);
  };
  // First half: the column (CroCo's grid[0] is w), second half: the row.
  return torch::cat({embed1d(pos.select(1, 1)), embed1d(pos.select(1, 0))}, 1).to(torch::kFloat32);
}

torch::Tensor patchPositions(int grid) {
  auto r = torch::arange(grid, torch::kInt64);
  auto rows = r.repeat_interleave(grid), cols = r.repeat({grid});
  return torch::stack({rows, cols}, 1);
}

torch::Tensor applyRope2d(const torch::Tensor& tokens, const torch::Tensor& positions,
                          double freq) {
  // tokens [B, H, N, Dh]; each half (D = Dh / 2) is a 1D RoPE over one coordinate.
  const int64_t D = tokens.size(3) / 2;
  auto invFreq =
      1.0 / torch::pow(freq, torch::arange(0, D, 2, torch::kFloat32).to(tokens.device()) / D);
  auto rope1d = [&](const torch::Tensor& x, const torch::Tensor& pos1d) {  // pos1d [B, N]
    auto freqs = pos1d.to(torch::kFloat32).unsqueeze(-1) * invFreq;        // [B, N, D/2]
    freqs = torch::cat({freqs, freqs}, -1).unsqueeze(1).to(x.dtype());     // [B, 1, N, D]
    auto halves = x.chunk(2, -1);
    auto rotated = torch::cat({-halves[1], halves[0]}, -1);
    return x * freqs.cos() + rotated * freqs.sin();
  };
  auto parts = tokens.chunk(2, -1);
  return torch::cat(
      {rope1d(parts[0], positions.select(2, 0)), rope1d(parts[1], positions.select(2, 1))}, -1);
}

MlpImpl::MlpImpl(int dim, int hidden) {
  fc1 = register_module("fc1", torch::nn::Linear(dim, hidden));
  fc2 = register_module("fc2", torch::nn::Linear(hidden, dim));
}

torch::Tensor MlpImpl::forward(const torch::Tensor& x) {
  return linear(fc2, F::gelu(linear(fc1, x)));
}

AttentionImpl::AttentionImpl(int dim, int heads_, double rope) : heads(heads_), ropeFreq(rope) {
  qkv =
      register_module("qkv", torch::nn::Linear(torch::nn::LinearOptions(dim, 3 * dim).bias(true)));
  proj = register_module("proj", torch::nn::Linear(dim, dim));
}

torch::Tensor AttentionImpl::forward(const torch::Tensor& x, const torch::Tensor& pos) {
  const int64_t B = x.size(0), N = x.size(1), C = x.size(2);
  auto qkvOut = linear(qkv, x)
                    .reshape({B, N, 3, heads, C / heads})
                    .permute({2, 0, 3, 1, 4});  // [3, B, H, N, Dh]
  auto q = qkvOut[0], k = qkvOut[1], v = qkvOut[2];
  if (ropeFreq > 0) {
    q = applyRope2d(q, pos, ropeFreq);
    k = applyRope2d(k, pos, ropeFreq);
  }
  return linear(proj, scaledDotProductAttention(q, k, v).transpose(1, 2).reshape({B, N, C}));
}

CrossAttentionImpl::CrossAttentionImpl(int dim, int heads_, double rope)
    : heads(heads_), ropeFreq(rope) {
  projq = register_module("projq", torch::nn::Linear(dim, dim));
  projk = register_module("projk", torch::nn::Linear(dim, dim));
  projv = register_module("projv", torch::nn::Linear(dim, dim));
  proj = register_module("proj", torch::nn::Linear(dim, dim));
}

torch::Tensor CrossAttentionImpl::forward(const torch::Tensor& query, const torch::Tensor& mem,
                                          const torch::Tensor& qpos, const torch::Tensor& kpos,
                                          torch::Tensor* scores) {
  const int64_t B = query.size(0), Nq = query.size(1), Nk = mem.size(1), C = query.size(2);
  auto split = [&](const torch::Tensor& t, int64_t n) {
    return t.reshape({B, n, heads, C / heads}).permute({0, 2, 1, 3});
  };
  auto q = split(linear(projq, query), Nq), k = split(linear(projk, mem), Nk),
       v = split(linear(projv, mem), Nk);
  if (ropeFreq > 0) {
    q = applyRope2d(q, qpos, ropeFreq);
    k = applyRope2d(k, kpos, ropeFreq);
  }
  if (scores)
    *scores = torch::matmul(q, k.transpose(-2, -1)) / std::sqrt(static_cast<double>(C / heads));
  return linear(proj, scaledDotProductAttention(q, k, v).transpose(1, 2).reshape({B, Nq, C}));
}

BlockImpl::BlockImpl(int dim, int heads, int mlpRatio, double rope) {
  norm1 = register_module("norm1", layerNorm(dim));
  attn = register_module("attn", Attention(dim, heads, rope));
  norm2 = register_module("norm2", layerNorm(dim));
  mlp = register_module("mlp", Mlp(dim, dim * mlpRatio));
}

torch::Tensor BlockImpl::forward(const torch::Tensor& x0, const torch::Tensor& pos) {
  auto x = x0 + attn(norm1(x0), pos);
  return x + mlp(norm2(x));
}

DecoderBlockImpl::DecoderBlockImpl(int dim, int heads, int mlpRatio, bool normMem, double rope) {
  norm1 = register_module("norm1", layerNorm(dim));
  attn = register_module("attn", Attention(dim, heads, rope));
  cross_attn = register_module("cross_attn", CrossAttention(dim, heads, rope));
  norm2 = register_module("norm2", layerNorm(dim));
  norm3 = register_module("norm3", layerNorm(dim));
  mlp = register_module("mlp", Mlp(dim, dim * mlpRatio));
  if (normMem) norm_y = register_module("norm_y", layerNorm(dim));
}

torch::Tensor DecoderBlockImpl::forward(const torch::Tensor& x0, const torch::Tensor& y,
                                        const torch::Tensor& xpos, const torch::Tensor& ypos,
                                        torch::Tensor* crossScores) {
  auto x = x0 + attn(norm1(x0), xpos);
  if (y.defined())
    x = x + cross_attn->forward(norm2(x), norm_y ? norm_y(y) : y, xpos, ypos, crossScores);
  return x + mlp(norm3(x));
}

PatchEmbedImpl::PatchEmbedImpl(int patch, int dim) {
  proj = register_module("proj",
                         torch::nn::Conv2d(torch::nn::Conv2dOptions(3, dim, patch).stride(patch)));
}

torch::Tensor PatchEmbedImpl::forward(const torch::Tensor& img) {
  return proj(img).flatten(2).transpose(1, 2);  // [B, D, G, G] -> [B, N, D]
}

CroCoNetImpl::CroCoNetImpl(const CroCoConfig& c) : config_(c) {
  c.validate();
  const double rope = c.ropeFrequency();
  patch_embed = register_module("patch_embed", PatchEmbed(c.patch_size, c.enc_embed_dim));
  if (!c.rope()) {
    enc_pos_embed = register_buffer("enc_pos_embed", sincosPosEmbed(c.enc_embed_dim, c.gridSize()));
    dec_pos_embed = register_buffer("dec_pos_embed", sincosPosEmbed(c.dec_embed_dim, c.gridSize()));
  }
  enc_blocks = register_module("enc_blocks", torch::nn::ModuleList());
  for (int i = 0; i < c.enc_depth; ++i)
    enc_blocks->push_back(Block(c.enc_embed_dim, c.enc_num_heads, c.mlp_ratio, rope));
  enc_norm = register_module("enc_norm", layerNorm(c.enc_embed_dim));
  mask_token = register_parameter("mask_token", torch::zeros({1, 1, c.dec_embed_dim}));
  decoder_embed =
      register_module("decoder_embed", torch::nn::Linear(c.enc_embed_dim, c.dec_embed_dim));
  dec_blocks = register_module("dec_blocks", torch::nn::ModuleList());
  for (int i = 0; i < c.dec_depth; ++i) {
    if (c.decoder == "cross")
      dec_blocks->push_back(
          DecoderBlock(c.dec_embed_dim, c.dec_num_heads, c.mlp_ratio, c.norm_im2_in_dec, rope));
    else
      dec_blocks->push_back(Block(c.dec_embed_dim, c.dec_num_heads, c.mlp_ratio, rope));
  }
  if (c.decoder == "cat") {
    view_embed1 = register_parameter("view_embed1", torch::zeros({1, 1, c.dec_embed_dim}));
    view_embed2 = register_parameter("view_embed2", torch::zeros({1, 1, c.dec_embed_dim}));
  }
  dec_norm = register_module("dec_norm", layerNorm(c.dec_embed_dim));
  prediction_head =
      register_module("prediction_head", torch::nn::Linear(c.dec_embed_dim, c.patchDim()));
  positions_ = patchPositions(c.gridSize());
  initializeWeights();
}

void CroCoNetImpl::initializeWeights() {
  torch::NoGradGuard noGrad;
  // The patch-embed conv: xavier_uniform on its [D, 3 p p] view; its bias keeps torch's default.
  auto w = patch_embed->proj->weight;
  w.view({w.size(0), -1})
      .copy_(torch::nn::init::xavier_uniform_(torch::empty({w.size(0), w[0].numel()})));
  torch::nn::init::normal_(mask_token, 0.0, 0.02);
  if (view_embed1.defined()) {
    torch::nn::init::normal_(view_embed1, 0.0, 0.02);
    torch::nn::init::normal_(view_embed2, 0.0, 0.02);
  }
  for (auto& m : modules(/*include_self=*/false)) {
    if (auto* lin = m->as<torch::nn::Linear>()) {
      torch::nn::init::xavier_uniform_(lin->weight);
      if (lin->bias.defined()) torch::nn::init::zeros_(lin->bias);
    } else if (auto* ln = m->as<torch::nn::LayerNorm>()) {
      torch::nn::init::ones_(ln->weight);
      torch::nn::init::zeros_(ln->bias);
    }
  }
}

torch::Tensor CroCoNetImpl::randomMask(int64_t batch, const torch::Device& device) const {
  auto noise = torch::rand({batch, config_.numPatches()}, torch::TensorOptions().device(device));
  return torch::argsort(noise, /*dim=*/1, /*descending=*/false) < config_.numMasked();
}

torch::Tensor CroCoNetImpl::encode(const torch::Tensor& img, const torch::Tensor& mask) {
  const int S = config_.img_size;
  if (img.dim() != 4 || img.size(1) != 3 || img.size(2) != S || img.size(3) != S)
    throw Error("CroCo input must be [B, 3, " + std::to_string(S) + ", " + std::to_string(S) + "]");
  auto x = residualStream(patch_embed(img));  // [B, N, D]
  if (enc_pos_embed.defined()) x = x + enc_pos_embed.unsqueeze(0);
  const int64_t B = x.size(0), C = x.size(2);
  auto pos = positions_.to(x.device()).unsqueeze(0).expand({B, -1, 2});  // [B, N, 2]
  if (mask.defined()) {
    auto visible = mask.logical_not();
    x = x.index({visible}).view({B, -1, C});  // [B, Nv, D], order kept
    pos = pos.index({visible}).view({B, -1, 2});
  }
  for (auto& blk : *enc_blocks) x = blk->as<Block>()->forward(x, pos);
  return enc_norm(x);
}

CroCoOutput CroCoNetImpl::forward(const torch::Tensor& img1, const torch::Tensor& img2) {
  return forward(img1, img2, randomMask(img1.size(0), img1.device()));
}

CroCoOutput CroCoNetImpl::forward(const torch::Tensor& img1, const torch::Tensor& img2,
                                  const torch::Tensor& mask, torch::Tensor* crossScores) {
  if (crossScores && (config_.decoder != "cross" || !img2.defined()))
    throw Error("cross-attention scores need the cross decoder and a second image");
  if (crossScores) *crossScores = torch::Tensor();
  const int64_t B = img1.size(0), N = config_.numPatches();
  if (mask.dim() != 2 || mask.size(0) != B || mask.size(1) != N ||
      mask.scalar_type() != torch::kBool)
    throw Error("mask must be [B, " + std::to_string(N) + "] bool");
  // Image 1's decoder tokens: its visible features, mask tokens elsewhere. Image 2's, when it
  // is given, are all its patches' features.
  auto vis1 = residualStream(linear(decoder_embed, encode(img1, mask)));  // [B, Nv, Dd]
  const int64_t Dd = vis1.size(2);
  auto f1 = mask_token.to(vis1.dtype()).expand({B, N, Dd}).clone();
  f1.index_put_({mask.logical_not()}, vis1.reshape({-1, Dd}));
  torch::Tensor f2;
  if (img2.defined())
    f2 = residualStream(linear(decoder_embed, encode(img2, torch::Tensor())));  // [B, N, Dd]
  if (dec_pos_embed.defined()) {
    f1 = f1 + dec_pos_embed;
    if (f2.defined()) f2 = f2 + dec_pos_embed;
  }
  torch::Tensor pos;
  if (config_.rope()) pos = positions_.to(img1.device()).unsqueeze(0).expand({B, -1, 2});
  torch::Tensor out;
  if (config_.decoder == "cross") {
    out = f1;
    torch::Tensor layer;
    for (auto& blk : *dec_blocks) {
      out = blk->as<DecoderBlock>()->forward(out, f2, pos, pos, crossScores ? &layer : nullptr);
      if (crossScores) {
        auto mean = layer.mean(1);  // over heads: [B, N, N]
        *crossScores = crossScores->defined() ? *crossScores + mean : mean;
      }
    }
    if (crossScores) *crossScores = *crossScores / static_cast<double>(dec_blocks->size());
  } else if (f2.defined()) {
    out = torch::cat({f1 + view_embed1, f2 + view_embed2}, 1);  // [B, 2N, Dd]
    auto pos2 = pos.defined() ? torch::cat({pos, pos}, 1) : pos;
    for (auto& blk : *dec_blocks) out = blk->as<Block>()->forward(out, pos2);
    out = out.narrow(1, 0, N);  // the first image's tokens
  } else {
    out = f1 + view_embed1;
    for (auto& blk : *dec_blocks) out = blk->as<Block>()->forward(out, pos);
  }
  CroCoOutput result;
  result.prediction = linear(prediction_head, dec_norm(out));
  result.mask = mask;
  result.target = patchify(img1, config_.patch_size);
  return result;
}

torch::Tensor taskReference(const std::string& task, const torch::Tensor& img2) {
  return task == "mae" ? torch::Tensor() : img2;
}

torch::Tensor patchify(const torch::Tensor& imgs, int p) {
  const int64_t B = imgs.size(0), h = imgs.size(2) / p, w = imgs.size(3) / p;
  PAIRCAST_CHECK(imgs.size(2) % p == 0 && imgs.size(3) % p == 0);
  auto x = imgs.reshape({B, 3, h, p, w, p}).permute({0, 2, 4, 3, 5, 1});  // nchpwq -> nhwpqc
  return x.reshape({B, h * w, p * p * 3});
}

torch::Tensor unpatchify(const torch::Tensor& x, int p, int channels) {
  const int64_t B = x.size(0), h = static_cast<int64_t>(std::lround(std::sqrt(x.size(1))));
  PAIRCAST_CHECK(h * h == x.size(1));
  auto y = x.reshape({B, h, h, p, p, channels}).permute({0, 5, 1, 3, 2, 4});  // nhwpqc -> nchpwq
  return y.reshape({B, channels, h * p, h * p});
}

torch::Tensor normalizePatches(const torch::Tensor& target) {
  auto mean = target.mean(-1, true);
  auto var = target.var(-1, /*unbiased=*/true, /*keepdim=*/true);
  return (target - mean) / torch::sqrt(var + 1e-6);
}

torch::Tensor maskedMse(const torch::Tensor& prediction, const torch::Tensor& mask,
                        const torch::Tensor& target, bool normPix) {
  auto perPatch = patchLosses(prediction, target, normPix);  // [B, N]
  auto m = mask.to(perPatch.dtype());
  return (perPatch * m).sum() / m.sum();
}

torch::Tensor patchLosses(const torch::Tensor& prediction, const torch::Tensor& target,
                          bool normPix) {
  auto t = normPix ? normalizePatches(target) : target;
  return (prediction - t).pow(2).mean(-1);
}

torch::Tensor imagenetNormalize(const torch::Tensor& x) {
  auto mean = torch::tensor({0.485f, 0.456f, 0.406f}, x.options()).view({1, 3, 1, 1});
  auto std = torch::tensor({0.229f, 0.224f, 0.225f}, x.options()).view({1, 3, 1, 1});
  return (x - mean) / std;
}

torch::Tensor imagenetDenormalize(const torch::Tensor& x) {
  auto mean = torch::tensor({0.485f, 0.456f, 0.406f}, x.options()).view({1, 3, 1, 1});
  auto std = torch::tensor({0.229f, 0.224f, 0.225f}, x.options()).view({1, 3, 1, 1});
  return x * std + mean;
}

int64_t countParameters(torch::nn::Module& module) {
  int64_t n = 0;
  for (const auto& p : module.parameters()) n += p.numel();
  return n;
}

}  // namespace paircast
