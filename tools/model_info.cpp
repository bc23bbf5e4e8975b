// model_info: parameters and FLOPs of a CroCo configuration. Last line: JSON.
#include <cstdio>
#include <nlohmann/json.hpp>

#include "model/croco_net.h"
#include "model/flops.h"
#include "tool_main.h"

using namespace paircast;

int main(int argc, char** argv) {
  std::string preset = "base", decoder = "cross", posEmbed = "cosine";
  int imgSize = 224;
  CLI::App app{"Parameter count and FLOPs of a CroCo model (one pair, forward, 90% masking)"};
  app.add_option("--preset", preset, "tiny, small or base")
      ->check(CLI::IsMember({"tiny", "small", "base"}));
  app.add_option("--decoder", decoder, "cross (CrossBlock) or cat (CatBlock)")
      ->check(CLI::IsMember({"cross", "cat"}));
  app.add_option("--pos-embed", posEmbed, "cosine or RoPE100");
  app.add_option("--img-size", imgSize, "Image size");
  return runTool("model_info", app, argc, argv, [&] {
    CroCoConfig cfg = presetConfig(preset);
    cfg.decoder = decoder;
    cfg.pos_embed = posEmbed;
    cfg.img_size = imgSize;
    cfg.validate();
    const FlopCount f = countFlops(cfg);
    CroCoNet net(cfg);  // the real module's count, to check the formula
    const int64_t counted = countParameters(*net);
    std::printf("CroCo %s, %s decoder, %s, %dx%d, patch %d, mask ratio %.2f\n", preset.c_str(),
                decoder.c_str(), posEmbed.c_str(), imgSize, imgSize, cfg.patch_size,
                cfg.mask_ratio);
    std::printf("parameters: %lld (%.1fM)%s\n", static_cast<long long>(counted), counted / 1e6,
                counted == f.params ? "" : "  [formula disagrees!]");
    std::printf("FLOPs, paper convention (weight layers, masked encoder): %.2f G\n", f.flops / 1e9);
    std::printf("FLOPs, every operation of the forward pass:             %.2f G\n",
                f.flops_full / 1e9);
    std::printf("%s\n", nlohmann::json(
                            {{"params", counted}, {"flops", f.flops}, {"flops_full", f.flops_full}})
                            .dump()
                            .c_str());
    return counted == f.params ? 0 : 3;
  });
}
