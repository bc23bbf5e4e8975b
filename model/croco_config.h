// Hyper-parameters of a CroCo network, with the official names (CroCoNet's constructor
// arguments), presets, and JSON for checkpoints ('args').
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>

namespace paircast {

struct CroCoConfig {
  // What validate() accepts at most: bounds on untrusted checkpoints, far above any model built.
  static constexpr int kMaxWidth = 8192;
  static constexpr int kMaxDepth = 256;
  static constexpr int kMaxMlpRatio = 16;
  static constexpr int kMaxPatch = 256;
  static constexpr int kMaxImage = 8192;
  static constexpr int64_t kMaxPatches = 1 << 16;

  int img_size = 224;
  int patch_size = 16;
  double mask_ratio = 0.9;
  int enc_embed_dim = 768;
  int enc_depth = 12;
  int enc_num_heads = 12;
  int dec_embed_dim = 512;
  int dec_depth = 8;
  int dec_num_heads = 16;
  int mlp_ratio = 4;
  bool norm_im2_in_dec = true;
  std::string pos_embed = "cosine";  // "cosine" or "RoPE100" (any RoPE<freq>)
  std::string decoder = "cross";     // "cross" (official DecoderBlock) or "cat" (paper appendix)

  int gridSize() const { return img_size / patch_size; }
  int numPatches() const { return gridSize() * gridSize(); }
  int numMasked() const { return static_cast<int>(mask_ratio * numPatches()); }
  int patchDim() const { return patch_size * patch_size * 3; }
  bool rope() const { return pos_embed.rfind("RoPE", 0) == 0; }
  double ropeFrequency() const;
  // Throws paircast::Error on inconsistent values (e.g. width not divisible by heads).
  void validate() const;
};

// "base" (the paper), "small", "tiny". Throws paircast::Error for another name.
CroCoConfig presetConfig(const std::string& name);

nlohmann::json configToJson(const CroCoConfig& c);
// Missing keys keep their defaults; wrong types throw paircast::Error naming `source`.
CroCoConfig configFromJson(const nlohmann::json& j, const std::string& source);

}  // namespace paircast
