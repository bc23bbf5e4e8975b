#include "model/croco_config.h"

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
  if (pos_embed == "cosine") {
    if (enc_embed_dim % 4 || dec_embed_dim % 4)
      fail("cosine embeddings need widths divisible by 4");
  } else if (rope()) {
    if (ropeFrequency() <= 0) fail("RoPE frequency must be positive");
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
    auto get = [&](const char* key, auto& field) {
      if (j.contains(key)) field = j.at(key).get<std::decay_t<decltype(field)>>();
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
