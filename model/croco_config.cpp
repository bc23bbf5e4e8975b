#include "model/croco_config.h"

#include <climits>
#include <cstdint>
#include <type_traits>

#include "util/error.h"

namespace paircast {

double CroCoConfig::ropeFrequency() const {
  if (!rope()) return 0;
  try {
    return std::stod(pos_embed.substr(4));
  } catch (...) {
    throw Error("invalid pos_embed '" + pos_embed + "' (use cosine or RoPE100)");
  }
}

void CroCoConfig::validate() const {
  auto fail = [](const std::string& m) { throw Error("invalid CroCo configuration: " + m); };
  if (patch_size <= 0 || img_size <= 0 || img_size % patch_size)
    fail("img_size must be a multiple of patch_size");
  if (enc_embed_dim <= 0 || enc_num_heads <= 0 || enc_embed_dim % enc_num_heads)
    fail("enc_embed_dim must be a multiple of enc_num_heads");
  if (dec_embed_dim <= 0 || dec_num_heads <= 0 || dec_embed_dim % dec_num_heads)
    fail("dec_embed_dim must be a multiple of dec_num_heads");
  if (enc_depth < 1 || dec_depth < 1 || mlp_ratio < 1)
    fail("depths and mlp_ratio must be positive");
  if (!(mask_ratio >= 0 && mask_ratio < 1)) fail("mask_ratio must be in [0, 1)");
  // Upper bounds, far above any ViT built (ViT-22B is 6,144 wide and 48 deep): a checkpoint's
  // configuration is untrusted, and it sizes the model before any weight is read.
  if (enc_embed_dim > kMaxWidth || dec_embed_dim > kMaxWidth)
    fail("embedding widths are at most " + std::to_string(kMaxWidth));
  if (enc_depth > kMaxDepth || dec_depth > kMaxDepth)
    fail("depths are at most " + std::to_string(kMaxDepth));
  if (mlp_ratio > kMaxMlpRatio) fail("mlp_ratio is at most " + std::to_string(kMaxMlpRatio));
  if (patch_size > kMaxPatch || img_size > kMaxImage)
    fail("patch_size and img_size are at most " + std::to_string(kMaxPatch) + " and " +
         std::to_string(kMaxImage));
  if (int64_t(img_size / patch_size) * (img_size / patch_size) > kMaxPatches)
    fail("at most " + std::to_string(kMaxPatches) + " patches an image");
  if (pos_embed == "cosine") {
    if (enc_embed_dim % 4 || dec_embed_dim % 4)
      fail("cosine embeddings need widths divisible by 4");
  } else if (rope()) {
    if (!(ropeFrequency() > 0 && ropeFrequency() < 1e30)) fail("RoPE frequency must be positive");
    if ((enc_embed_dim / enc_num_heads) % 4 || (dec_embed_dim / dec_num_heads) % 4)
      fail("RoPE needs head widths divisible by 4");
  } else {
    fail("pos_embed must be cosine or RoPE<freq>");
  }
  if (decoder != "cross" && decoder != "cat") fail("decoder must be cross or cat");
}

CroCoConfig presetConfig(const std::string& name) {
  CroCoConfig c;
  if (name == "base") return c;
  if (name == "small") {
    c.enc_embed_dim = 384, c.enc_depth = 12, c.enc_num_heads = 6;
    c.dec_embed_dim = 256, c.dec_depth = 4, c.dec_num_heads = 8;
    return c;
  }
  if (name == "tiny") {
    c.enc_embed_dim = 192, c.enc_depth = 6, c.enc_num_heads = 3;
    c.dec_embed_dim = 128, c.dec_depth = 2, c.dec_num_heads = 4;
    return c;
  }
  throw Error("unknown preset '" + name + "' (use tiny, small or base)");
}

nlohmann::json configToJson(const CroCoConfig& c) {
  return {{"img_size", c.img_size},
          {"patch_size", c.patch_size},
          {"mask_ratio", c.mask_ratio},
          {"enc_embed_dim", c.enc_embed_dim},
          {"enc_depth", c.enc_depth},
          {"enc_num_heads", c.enc_num_heads},
          {"dec_embed_dim", c.dec_embed_dim},
          {"dec_depth", c.dec_depth},
          {"dec_num_heads", c.dec_num_heads},
          {"mlp_ratio", c.mlp_ratio},
          {"norm_im2_in_dec", c.norm_im2_in_dec},
          {"pos_embed", c.pos_embed},
          {"decoder", c.decoder}};
}

CroCoConfig configFromJson(const nlohmann::json& j, const std::string& source) {
  if (!j.is_object()) throw Error(source, "model configuration is not a JSON object");
  CroCoConfig c;
  try {
    // Each value must have its field's type: a float such as 1e20 read as an int is undefined.
    auto get = [&](const char* key, auto& field) {
      using T = std::decay_t<decltype(field)>;
      if (!j.contains(key)) return;
      const auto& v = j.at(key);
      if constexpr (std::is_same_v<T, int>) {
        if (!v.is_number_integer() || v.get<int64_t>() < INT_MIN || v.get<int64_t>() > INT_MAX)
          throw Error(source, std::string("model configuration: '") + key +
                                  "' is not an integer in range: " + v.dump().substr(0, 40));
      }
      field = v.get<T>();
    };
    get("img_size", c.img_size);
    get("patch_size", c.patch_size);
    get("mask_ratio", c.mask_ratio);
    get("enc_embed_dim", c.enc_embed_dim);
    get("enc_depth", c.enc_depth);
    get("enc_num_heads", c.enc_num_heads);
    get("dec_embed_dim", c.dec_embed_dim);
    get("dec_depth", c.dec_depth);
    get("dec_num_heads", c.dec_num_heads);
    get("mlp_ratio", c.mlp_ratio);
    get("norm_im2_in_dec", c.norm_im2_in_dec);
    get("pos_embed", c.pos_embed);
    get("decoder", c.decoder);
  } catch (const nlohmann::json::exception& e) {
    throw Error(source, std::string("bad model configuration: ") + e.what());
  }
  c.validate();
  return c;
}

}  // namespace paircast
