// pretrain: CroCo pre-training from shards, a CroCo folder, or pairs rendered live.
#include <cstdio>

#include "tool_main.h"
#include "train_flags.h"
#include "trainer/trainer.h"

using namespace paircast;

int main(int argc, char** argv) {
  TrainConfig c;
  std::string preset = "tiny", decoder = "cross";
  int imgSize = 224;
  CLI::App app{"Pre-train CroCo on image pairs (checkpoints that PyTorch loads)"};
  app.add_option("--data", c.shards, "Tar shards or glob patterns");
  app.add_option("--keys", c.keysFile, "Train only on the shard keys listed in this file");
  app.add_option("--croco-dir", c.crocoDir, "A CroCo pairs folder (pairs.txt)");
  app.add_option("--live", c.live, "Scenes: pairs rendered on the fly");
  app.add_option("--data-weight", c.shardsWeight, "Share of samples from --data when mixing");
  app.add_option("--croco-weight", c.crocoWeight, "Share of samples from --croco-dir when mixing");
  app.add_option("--live-weight", c.liveWeight, "Share of samples from --live when mixing");
  app.add_option("--preset", preset, "tiny, small or base")
      ->check(CLI::IsMember({"tiny", "small", "base"}));
  app.add_option("--task", c.task,
                 "croco (complete view 1 with view 2) or mae (view 1 alone: no reference)");
  app.add_option("--decoder", decoder, "cross or cat")->check(CLI::IsMember({"cross", "cat"}));
  app.add_option("--img-size", imgSize, "Training crop size (224 as the paper)");
  int patchSize = 16;
  app.add_option("--patch-size", patchSize, "ViT patch size (16 as the paper)")
      ->check(CLI::Range(1, 64));
  std::string posEmbed = "cosine";
  app.add_option("--pos-embed", posEmbed,
                 "cosine (CroCo v1's absolute sin-cos) or RoPE100 (CroCo v2's rotary: relative "
                 "positions in every attention)");
  addLoopFlags(app, c);
  app.add_option("--accum-iter", c.accumIter, "Iterations per optimizer step")
      ->check(CLI::Range(1, 4096));
  app.add_option("--out", c.out, "Output folder")->required();
  app.add_option("--workers", c.workers, "Data worker threads")->check(CLI::Range(1, 256));
  app.add_option("--batch-format", c.batchFormat,
                 "What the data threads hand over: float32 (normalised), uint8 (crops, jittered "
                 "and normalised on the device: a quarter of the bytes), or auto (uint8 on CUDA)")
      ->check(CLI::IsMember({"auto", "float32", "uint8"}));
  app.add_option("--keep-every", c.keepEvery, "Keep checkpoint-<epoch>.pth every K epochs");
  app.add_option("--recon-every", c.reconEvery,
                 "Iterations between reconstruction grids (0: never)");
  app.add_option("--live-epoch-pairs", c.liveEpochPairs, "Pairs per epoch with --live");
  bool quiet = false;
  app.add_flag("--quiet", quiet, "No progress lines");
  return runTool("pretrain", app, argc, argv, [&] {
    c.model = presetConfig(preset);
    c.model.decoder = decoder;
    c.model.img_size = imgSize;
    c.model.patch_size = patchSize;
    c.model.pos_embed = posEmbed;
    c.progress = !quiet;
    if (!quiet) logLaunch("pretrain", launchRole(processEnvironment()).describe());
    const nlohmann::json summary = runPretrain(c);
    std::printf("%s\n", summary.dump().c_str());
    return 0;
  });
}
