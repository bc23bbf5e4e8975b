#include "model/downstream.h"

#include <set>

#include "util/error.h"

namespace paircast {
namespace {

bool startsWith(const std::string& s, const std::string& prefix) {
  return s.rfind(prefix, 0) == 0;
}

// The keys of a CroCo state_dict that belong to the encoder or the decoder.
bool encoderKey(const std::string& k) {
  return startsWith(k, "patch_embed.") || startsWith(k, "enc_blocks.") ||
         startsWith(k, "enc_norm.");
}
bool decoderKey(const std::string& k) {
  return startsWith(k, "decoder_embed.") || startsWith(k, "dec_blocks.") ||
         startsWith(k, "dec_norm.");
}

// CroCoNet's constructor arguments (naver/croco), as CroCo v2's released checkpoints store them.
nlohmann::json crocoKwargs(const CroCoConfig& c) {
  nlohmann::json j = configToJson(c);
  j.erase("decoder");  // paircast's own: the official model has the cross decoder only
  return j;
}

}  // namespace

int DownstreamConfig::channels() const {
  if (task == "depth") return 1;
  if (task == "flow") return head == "dpt" ? 3 : 2;
  return 12;
}

int64_t DownstreamConfig::headParameters() const {
  auto linear = [](int64_t in, int64_t out) { return in * out + out; };
  const int64_t E = croco.enc_embed_dim, D = croco.dec_embed_dim, C = channels();
  const int64_t p = croco.patch_size;
  if (head == "linear") return linear(binocular() ? D : E, p * p * C);
  if (head == "pose") return linear(D, 64) + linear(croco.numPatches() * 64, 12);
  // DPT (model/dpt_head.cpp): per map a 1x1 projection, a resampling (transposed 4x4 and 2x2,
  // none, strided 3x3) and layer_rn (3x3, no bias); four fusion blocks; the regression head.
  const DptOptions o;
  const int64_t F = o.featureDim, last = o.lastDim;
  const std::vector<int> h =
      hooks.empty() ? defaultDptHooks(croco.enc_depth, binocular() ? croco.dec_depth : 0) : hooks;
  const int64_t resample[4] = {16, 4, 0, 9};
  int64_t n = 0;
  for (int k = 0; k < 4; ++k) {
    const int64_t dim = layerDims.at(k), tokens = h.at(k) < croco.enc_depth ? E : D;
    n += linear(tokens, dim) + (resample[k] ? linear(dim * resample[k], dim) : 0) + dim * F * 9;
  }
  n += 4 * (linear(F, F) + 4 * linear(F * 9, F));
  return n + linear(F * 9, F / 2) + linear(F / 2 * 9, last) + linear(last, C);
}

double defaultFlowScale(int imgSize) {
  return imgSize / 16.0;
}

double DownstreamConfig::flowScaleInUse() const {
  return flowScale > 0 ? flowScale : defaultFlowScale(croco.img_size);
}

void DownstreamConfig::validate() const {
  croco.validate();
  if (!(flowScale >= 0 && flowScale <= 1e4))
    throw OptionError("flow_scale", "the flow scale must be in (0, 10000] pixels (0: default)");
  if (task != "flow" && task != "depth" && task != "pose")
    throw OptionError("task", "the task must be flow, depth or pose, not '" + task + "'");
  const bool ok = task == "pose" ? head == "pose" : (head == "dpt" || head == "linear");
  if (!ok)
    throw OptionError("head",
                      "--task " + task + " takes --head " +
                          (task == "pose" ? std::string("pose") : std::string("dpt or linear")) +
                          ", not '" + head + "'");
  if (croco.decoder != "cross")
    throw OptionError("decoder", "fine-tuning takes the cross decoder (naver/croco's), not '" +
                                     croco.decoder + "'");
  if (head == "dpt") {
    const std::string why = dptSizeProblem(croco.img_size, croco.patch_size);
    if (!why.empty()) throw OptionError("img_size", why + "; --head linear takes any size");
    const int blocks = croco.enc_depth + (binocular() ? croco.dec_depth : 0);
    if (!hooks.empty() && hooks.size() != 4)
      throw OptionError("hooks", "the DPT head takes 4 hooks");
    for (int h : hooks)
      if (h < 0 || h >= blocks)
        throw OptionError("hooks", "DPT hook " + std::to_string(h) + " is not a block (0 to " +
                                       std::to_string(blocks - 1) + ")");
    if (layerDims.size() != 4) throw OptionError("layer_dims", "the DPT head takes 4 layer_dims");
    for (int d : layerDims)
      if (d < 1 || d > kMaxLayerDim)
        throw OptionError("layer_dims", "DPT layer_dims are 1 to " + std::to_string(kMaxLayerDim) +
                                            ", not " + std::to_string(d));
  }
}

PoseHeadImpl::PoseHeadImpl(int dim, int patches, int hidden) {
  fc1 = register_module("fc1", torch::nn::Linear(dim, hidden));
  fc2 = register_module("fc2", torch::nn::Linear(patches * hidden, 12));
}

torch::Tensor PoseHeadImpl::forward(const torch::Tensor& tokens) {
  // Each patch's features keep their place: where the content moved is what the pose is.
  auto features = torch::gelu(fc1(tokens)).flatten(1);  // [B, N hidden]
  // [B, 12], in float32 under bf16 autocast too: torch::eye and the SVD take no bfloat16.
  auto out = fc2(features).to(torch::kFloat32);
  // 2 I + the output: the head starts near the identity.
  auto m = out.narrow(1, 0, 9).reshape({-1, 3, 3}) + 2.0 * torch::eye(3, out.options());
  auto rotation = procrustesRotation(m);
  return torch::cat({rotation.reshape({-1, 9}), out.narrow(1, 9, 3)}, 1);
}

namespace {

// R = U diag(1, 1, d) V^T with d = det(U V^T), and its gradient in closed form. Write U' for U
// with its last column times d and s' for the singular values with the last times d, so that
// M = U' diag(s') V^T and R = U' V^T. Then dR = U' W V^T, W skew with
// W_ij = (X_ij - X_ji) / (s'_i + s'_j), X = U'^T dM V; so dL/dM = U' K V^T with
// K_ij = (H_ij - H_ji) / (s'_i + s'_j), H = U'^T dL/dR V. The sums s'_i + s'_j stay near 4 where
// the head starts (M near 2 I), whereas LibTorch's SVD gradient divides by differences of
// squared singular values, which vanish there (and is NaN at M = c I).
struct ProcrustesFunction : torch::autograd::Function<ProcrustesFunction> {
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, const torch::Tensor& m) {
    auto [u, s, vh] = torch::linalg_svd(m.to(torch::kFloat64), /*full_matrices=*/false);
    const auto d = torch::det(torch::matmul(u, vh));  // +-1
    const auto ones = torch::ones_like(d);
    const auto flip = torch::stack({ones, ones, d}, 1);  // [B, 3]
    const auto uFlipped = u * flip.unsqueeze(1);
    ctx->save_for_backward({uFlipped, s * flip, vh});
    return torch::matmul(uFlipped, vh).to(m.scalar_type());
  }

  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grads) {
    const auto saved = ctx->get_saved_variables();
    const auto &u = saved[0], &s = saved[1], &vh = saved[2];
    const auto h = torch::matmul(torch::matmul(u.transpose(1, 2), grads[0].to(torch::kFloat64)),
                                 vh.transpose(1, 2));
    // s'_i + s'_j >= 0; it is 0 only where the nearest rotation is not unique.
    const auto sums = (s.unsqueeze(2) + s.unsqueeze(1)).clamp_min(1e-12);
    const auto k = (h - h.transpose(1, 2)) / sums;
    return {torch::matmul(torch::matmul(u, k), vh).to(grads[0].scalar_type())};
  }
};

}  // namespace

torch::Tensor procrustesRotation(const torch::Tensor& m) {
  return ProcrustesFunction::apply(m);
}

DownstreamNetImpl::DownstreamNetImpl(const DownstreamConfig& c) : config_(c) {
  c.validate();
  // The CroCo parts, initialised as CroCoNet initialises them (the same draws for a seed).
  const CroCoNet croco(c.croco);
  patch_embed = register_module("patch_embed", croco->patch_embed);
  if (!c.croco.rope()) {
    enc_pos_embed = register_buffer("enc_pos_embed", croco->enc_pos_embed);
    dec_pos_embed = register_buffer("dec_pos_embed", croco->dec_pos_embed);
  }
  enc_blocks = register_module("enc_blocks", croco->enc_blocks);
  enc_norm = register_module("enc_norm", croco->enc_norm);
  if (c.binocular()) {
    decoder_embed = register_module("decoder_embed", croco->decoder_embed);
    dec_blocks = register_module("dec_blocks", croco->dec_blocks);
    dec_norm = register_module("dec_norm", croco->dec_norm);
  }
  const int E = c.croco.enc_depth, D = c.binocular() ? c.croco.dec_depth : 0;
  if (c.head == "dpt") {
    DptOptions o;
    o.hooks = c.hooks.empty() ? defaultDptHooks(E, D) : c.hooks;
    o.layerDims = c.layerDims;
    for (int h : o.hooks)
      o.tokenDims.push_back(h < E ? c.croco.enc_embed_dim : c.croco.dec_embed_dim);
    o.numChannels = c.channels();
    hooks_ = o.hooks;
    dpt_head = register_module("head", PixelwiseDpt(o));
  } else if (c.head == "linear") {
    const int p = c.croco.patch_size;
    const int width = c.binocular() ? c.croco.dec_embed_dim : c.croco.enc_embed_dim;
    prediction_head =
        register_module("prediction_head", torch::nn::Linear(width, p * p * c.channels()));
    torch::NoGradGuard noGrad;
    torch::nn::init::xavier_uniform_(prediction_head->weight);
    torch::nn::init::zeros_(prediction_head->bias);
  } else {
    pose_head = register_module("head", PoseHead(c.croco.dec_embed_dim, c.croco.numPatches()));
  }
  positions_ = patchPositions(c.croco.gridSize());
}

std::vector<torch::Tensor> DownstreamNetImpl::encodeBlocks(const torch::Tensor& img, bool all) {
  auto x = residualStream(patch_embed(img));  // [B, N, D]
  if (enc_pos_embed.defined()) x = x + enc_pos_embed.unsqueeze(0);
  auto pos = positions_.to(x.device()).unsqueeze(0).expand({x.size(0), -1, 2});
  std::vector<torch::Tensor> out;
  for (auto& blk : *enc_blocks) {
    x = blk->as<Block>()->forward(x, pos);
    if (all) out.push_back(x);
  }
  if (!all) out.push_back(x);
  out.back() = enc_norm(out.back());
  return out;
}

std::vector<torch::Tensor> DownstreamNetImpl::decodeBlocks(const torch::Tensor& feat1,
                                                           const torch::Tensor& feat2) {
  auto f1 = residualStream(decoder_embed(feat1)), f2 = residualStream(decoder_embed(feat2));
  if (dec_pos_embed.defined()) {
    f1 = f1 + dec_pos_embed;
    f2 = f2 + dec_pos_embed;
  }
  torch::Tensor pos;
  if (config_.croco.rope())
    pos = positions_.to(f1.device()).unsqueeze(0).expand({f1.size(0), -1, 2});
  std::vector<torch::Tensor> out;
  for (auto& blk : *dec_blocks) {
    f1 = blk->as<DecoderBlock>()->forward(f1, f2, pos, pos);
    out.push_back(f1);
  }
  out.back() = dec_norm(out.back());
  return out;
}

torch::Tensor DownstreamNetImpl::forward(const torch::Tensor& img1, const torch::Tensor& img2) {
  const int S = config_.croco.img_size;
  auto checkImage = [&](const torch::Tensor& t, const char* name) {
    if (!t.defined() || t.dim() != 4 || t.size(1) != 3 || t.size(2) != S || t.size(3) != S)
      throw Error(std::string("fine-tuning input ") + name + " must be [B, 3, " +
                  std::to_string(S) + ", " + std::to_string(S) + "]");
  };
  checkImage(img1, "image 1");
  const bool dpt = config_.head == "dpt";
  const int p = config_.croco.patch_size;
  if (!config_.binocular()) {
    if (dpt) return dpt_head->forward(encodeBlocks(img1, true), S, S);
    return unpatchify(prediction_head(encodeBlocks(img1, false).back()), p, 1);
  }
  checkImage(img2, "image 2");
  const int64_t B = img1.size(0);
  // Both images through the encoder in one batch, as naver/croco's encode_image_pairs.
  std::vector<torch::Tensor> enc = encodeBlocks(torch::cat({img1, img2}, 0), dpt);
  std::vector<torch::Tensor> enc1;
  for (const auto& t : enc) enc1.push_back(t.narrow(0, 0, B));
  const torch::Tensor enc2 = enc.back().narrow(0, B, B);
  std::vector<torch::Tensor> dec = decodeBlocks(enc1.back(), enc2);
  if (dpt) {
    enc1.insert(enc1.end(), dec.begin(), dec.end());
    return inPixels(dpt_head->forward(enc1, S, S));
  }
  if (config_.head == "linear") return inPixels(unpatchify(prediction_head(dec.back()), p, 2));
  return pose_head(dec.back());
}

torch::Tensor DownstreamNetImpl::inPixels(const torch::Tensor& flow) const {
  const double scale = config_.flowScaleInUse();
  if (scale == 1.0) return flow;
  const torch::Tensor uv = flow.narrow(1, 0, 2) * scale;
  if (flow.size(1) == 2) return uv;
  return torch::cat({uv, flow.narrow(1, 2, flow.size(1) - 2)}, 1);
}

nlohmann::json DownstreamNetImpl::checkpointEntries() const {
  nlohmann::json j = {{"croco_kwargs", crocoKwargs(config_.croco)},
                      {"task", config_.task},
                      {"head", config_.head},
                      {"args", configToJson(config_.croco)}};
  if (config_.head == "dpt") j["head_kwargs"] = dptHeadKwargs(dpt_head->dpt->options);
  if (config_.task == "flow") j["flow_scale"] = config_.flowScaleInUse();
  return j;
}

std::vector<std::pair<std::string, torch::Tensor>> DownstreamNetImpl::uniqueParameters() const {
  std::vector<std::pair<std::string, torch::Tensor>> out;
  std::set<const void*> seen;
  for (const auto& p : named_parameters())
    if (seen.insert(p.value().unsafeGetTensorImpl()).second) out.emplace_back(p.key(), p.value());
  return out;
}

std::string DownstreamNetImpl::initFromPretrained(const Checkpoint& ck, const std::string& source) {
  const std::string trained = trainedTask(ck);
  if (trained != "croco" && trained != "mae")
    throw Error(source, "is a fine-tuning checkpoint (task " + trained +
                            "); --init takes a pre-training checkpoint (pretrain, mae or "
                            "official CroCo)");
  CroCoConfig theirs;
  if (ck.hasArgs)
    theirs = configFromJson(ck.args, source);
  else if (ck.extra.contains("croco_kwargs"))
    theirs = configFromJson(ck.extra["croco_kwargs"], source);
  else
    theirs = CroCoConfig{};  // CroCo v1's release: CroCoNet's defaults
  const CroCoConfig& ours = config_.croco;
  auto differ = [&](const char* name, int a, int b) {
    if (a != b)
      throw Error(source, std::string("checkpoint of another model: ") + name + " " +
                              std::to_string(a) + ", not " + std::to_string(b) + " (use the " +
                              (std::string(name) == "patch_size" ? "--patch-size" : "--preset") +
                              " it was trained with)");
  };
  differ("enc_embed_dim", theirs.enc_embed_dim, ours.enc_embed_dim);
  differ("enc_depth", theirs.enc_depth, ours.enc_depth);
  differ("enc_num_heads", theirs.enc_num_heads, ours.enc_num_heads);
  differ("patch_size", theirs.patch_size, ours.patch_size);
  const bool decoder = config_.binocular() && trained == "croco";
  if (decoder) {
    differ("dec_embed_dim", theirs.dec_embed_dim, ours.dec_embed_dim);
    differ("dec_depth", theirs.dec_depth, ours.dec_depth);
    differ("dec_num_heads", theirs.dec_num_heads, ours.dec_num_heads);
  }
  if (theirs.pos_embed != ours.pos_embed)
    throw Error(source, "checkpoint of another model: pos_embed " + theirs.pos_embed + ", not " +
                            ours.pos_embed + " (use the --pos-embed it was trained with)");
  torch::NoGradGuard noGrad;
  for (auto& [k, t] : stateDict(*this)) {
    if (!(encoderKey(k) || (decoder && decoderKey(k)))) continue;
    const auto it = ck.model.find(k);
    if (it == ck.model.end()) throw Error(source, "checkpoint has no '" + k + "'");
    if (it->second.sizes() != t.sizes())
      throw Error(source, "checkpoint's '" + k + "' has another shape than the model's");
    t.copy_(it->second.to(t.dtype()));
  }
  return decoder ? "encoder+decoder" : "encoder";
}

namespace {

// A list of integers from an untrusted file: a float such as 1e12 read as an int is undefined.
std::vector<int> smallInts(const nlohmann::json& list, const char* key, const std::string& source) {
  if (!list.is_array())
    throw Error(source, std::string("head_kwargs: '") + key + "' is not a list");
  std::vector<int> out;
  for (const auto& v : list) {
    if (!v.is_number_integer() || v.get<int64_t>() < -(int64_t(1) << 30) ||
        v.get<int64_t>() > (int64_t(1) << 30))
      throw Error(source, std::string("head_kwargs: '") + key + "' holds " +
                              v.dump().substr(0, 40) + ", not an integer in range");
    out.push_back(v.get<int>());
  }
  return out;
}

}  // namespace

DownstreamConfig downstreamConfigOf(const Checkpoint& ck, const std::string& source) {
  const std::string task = trainedTask(ck);
  if (task != "flow" && task != "depth" && task != "pose")
    throw Error(source, "is not a fine-tuning checkpoint (task " + task + ")");
  DownstreamConfig c;
  c.task = task;
  c.croco = ck.hasArgs ? configFromJson(ck.args, source)
                       : configFromJson(ck.extra.value("croco_kwargs", nlohmann::json()), source);
  try {
    c.head = ck.extra.value("head", std::string("dpt"));
    c.flowScale = 1.0;  // checkpoints from before the scale regressed pixels
    if (ck.extra.contains("flow_scale")) {
      const auto& v = ck.extra["flow_scale"];
      if (!v.is_number() || !(v.get<double>() > 0))
        throw Error(source, "flow_scale is not a positive number: " + v.dump().substr(0, 40));
      c.flowScale = v.get<double>();
    }
    if (ck.extra.contains("head_kwargs")) {
      const auto& h = ck.extra["head_kwargs"];
      c.hooks = smallInts(h.at("hooks_idx"), "hooks_idx", source);
      c.layerDims = smallInts(h.at("layer_dims"), "layer_dims", source);
    }
  } catch (const nlohmann::json::exception& e) {
    throw Error(source, std::string("bad head or head_kwargs: ") + e.what());
  }
  try {
    c.validate();
  } catch (const Error& e) {
    throw Error(source, e.what());
  }
  return c;
}

}  // namespace paircast
