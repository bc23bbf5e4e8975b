// reconstruct: the paper's figure-2 grid for one pair: reference, masked input, reconstruction,
// target.
#include <cstdio>

#include "model/reconstruct.h"
#include "tool_main.h"
#include "util/image_io.h"

using namespace paircast;

int main(int argc, char** argv) {
  ReconstructOptions o;
  std::string out, savePrediction, preset;
  CroCoConfig flags;
  CLI::App app{"Cross-view completion of one pair with a CroCo checkpoint"};
  app.add_option("--checkpoint", o.checkpoint, "Checkpoint (.pth): ours or an official CroCo one")
      ->required();
  app.add_option("--image1", o.image1, "The image to complete (masked)")->required();
  app.add_option("--image2", o.image2, "The reference view")->required();
  app.add_option("--mask-file", o.maskFile,
                 "0/1 per patch, row-major, 1 = masked (default: random)");
  app.add_option("--seed", o.seed, "Seed of the random mask");
  app.add_option("--amp", o.amp,
                 "auto (bf16 on CPUs with bf16 units, else float32), bf16 or none (float32)")
      ->check(CLI::IsMember({"auto", "bf16", "none"}));
  app.add_option("--out", out, "Output grid (.png)")->required();
  app.add_option("--save-prediction", savePrediction, "Raw head output as float32 .npy [N, p*p*3]");
  app.add_option("--preset", preset, "Hyper-parameters for foreign checkpoints: tiny, small, base");
  auto* encDim = app.add_option("--enc-dim", flags.enc_embed_dim, "Encoder width");
  auto* encDepth = app.add_option("--enc-depth", flags.enc_depth, "Encoder blocks");
  auto* encHeads = app.add_option("--enc-heads", flags.enc_num_heads, "Encoder heads");
  auto* decDim = app.add_option("--dec-dim", flags.dec_embed_dim, "Decoder width");
  auto* decDepth = app.add_option("--dec-depth", flags.dec_depth, "Decoder blocks");
  auto* decHeads = app.add_option("--dec-heads", flags.dec_num_heads, "Decoder heads");
  auto* img = app.add_option("--img-size", flags.img_size, "Image size");
  auto* patch = app.add_option("--patch-size", flags.patch_size, "Patch size");
  return runTool("reconstruct", app, argc, argv, [&] {
    const bool explicitFlags = encDim->count() || encDepth->count() || encHeads->count() ||
                               decDim->count() || decDepth->count() || decHeads->count() ||
                               img->count() || patch->count();
    if (!preset.empty()) {
      CroCoConfig p = presetConfig(preset);
      if (img->count()) p.img_size = flags.img_size;
      if (patch->count()) p.patch_size = flags.patch_size;
      o.config = p;
    } else if (explicitFlags) {
      o.config = flags;
    }
    if (o.config) o.config->validate();
    const Reconstruction r = reconstruct(o);
    writeImage(out, r.grid);
    if (!savePrediction.empty()) writeNpy(savePrediction, r.prediction);
    std::printf("wrote %s (masked MSE, norm_pix: %.4f)\n", out.c_str(), r.loss);
    return 0;
  });
}
