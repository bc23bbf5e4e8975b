#include "model/flops.h"

namespace paircast {
namespace {

// Per-element costs used by flops_full.
constexpr double kLayerNorm = 8;  // mean, variance, normalise, scale, shift
constexpr double kGelu = 8;       // erf-based GELU, as counted by fvcore-like tools
constexpr double kSoftmax = 4;    // subtract max, exp, sum, divide

struct Counter {
  double weights = 0;  // 2 * MACs of weight layers
  double other = 0;    // everything else, for flops_full
  void linear(double tokens, double in, double out, bool bias = true) {
    weights += 2 * tokens * in * out;
    if (bias) other += tokens * out;
  }
  void attention(double nq, double nk, double dim) {  // scores, scaling, softmax, weighted sum
    other += 2 * nq * nk * dim + nq * nk * (1 + kSoftmax) + 2 * nq * nk * dim;
  }
  void norm(double tokens, double dim) { other += kLayerNorm * tokens * dim; }
  void add(double tokens, double dim) { other += tokens * dim; }
};

// Pre-norm self-attention sub-block with its residual.
void selfAttention(Counter& c, double n, double d) {
  c.norm(n, d);
  c.linear(n, d, 3 * d);
  c.attention(n, n, d);
  c.linear(n, d, d);
  c.add(n, d);
}

// Pre-norm GELU MLP sub-block with its residual.
void mlpBlock(Counter& c, double n, double d, int mlp) {
  c.norm(n, d);
  c.linear(n, d, mlp * d);
  c.other += kGelu * n * mlp * d;
  c.linear(n, mlp * d, d);
  c.add(n, d);
}

void block(Counter& c, double n, double d, int mlp) {
  selfAttention(c, n, d);
  mlpBlock(c, n, d, mlp);
}

void crossBlock(Counter& c, double n, double m, double d, int mlp, bool normMem) {
  selfAttention(c, n, d);
  if (normMem) c.norm(m, d);
  c.norm(n, d);
  c.linear(n, d, d);      // projq
  c.linear(m, d, 2 * d);  // projk, projv
  c.attention(n, m, d);
  c.linear(n, d, d);
  c.add(n, d);
  mlpBlock(c, n, d, mlp);
}

int64_t params(const CroCoConfig& c) {
  const int64_t D = c.enc_embed_dim, Dd = c.dec_embed_dim, P = c.patchDim(), m = c.mlp_ratio;
  auto lin = [](int64_t in, int64_t out) { return in * out + out; };
  auto ln = [](int64_t d) { return 2 * d; };
  auto blk = [&](int64_t d) {
    return ln(d) + lin(d, 3 * d) + lin(d, d) + ln(d) + lin(d, m * d) + lin(m * d, d);
  };
  int64_t n = lin(P, D);  // the patch-embed conv
  n += c.enc_depth * blk(D) + ln(D);
  n += Dd + lin(D, Dd);  // mask token, decoder_embed
  for (int i = 0; i < c.dec_depth; ++i) {
    if (c.decoder == "cross")
      n += blk(Dd) + 3 * lin(Dd, Dd) + lin(Dd, Dd) + ln(Dd) + (c.norm_im2_in_dec ? ln(Dd) : 0);
    else
      n += blk(Dd);
  }
  if (c.decoder == "cat") n += 2 * Dd;
  return n + ln(Dd) + lin(Dd, P);
}

}  // namespace

FlopCount countFlops(const CroCoConfig& cfg) {
  const double N = cfg.numPatches(), Nv = N - cfg.numMasked(), D = cfg.enc_embed_dim,
               Dd = cfg.dec_embed_dim, P = cfg.patchDim();
  Counter c;
  // Encoders: image 1 on its visible patches, image 2 whole; the patch embedding runs on both
  // whole images.
  c.linear(2 * N, P, D);
  c.add(2 * N, D);  // positional embeddings
  for (double n : {Nv, N}) {
    for (int i = 0; i < cfg.enc_depth; ++i) block(c, n, D, cfg.mlp_ratio);
    c.norm(n, D);
  }
  c.linear(Nv + N, D, Dd);  // decoder_embed
  c.add(2 * N, Dd);
  if (cfg.decoder == "cross") {
    for (int i = 0; i < cfg.dec_depth; ++i)
      crossBlock(c, N, N, Dd, cfg.mlp_ratio, cfg.norm_im2_in_dec);
  } else {
    c.add(2 * N, Dd);  // view embeddings
    for (int i = 0; i < cfg.dec_depth; ++i) block(c, 2 * N, Dd, cfg.mlp_ratio);
  }
  c.norm(N, Dd);
  c.linear(N, Dd, P);
  FlopCount out;
  out.params = params(cfg);
  out.flops = c.weights;
  out.flops_full = c.weights + c.other;
  return out;
}

}  // namespace paircast
