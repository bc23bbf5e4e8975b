// finetune: a CroCo checkpoint (or random weights) fine-tuned for optical flow, monocular depth or
// relative pose on pairs with exact ground truth; --predict runs a fine-tuned model on one pair.
#include <cstdio>

#include "finetune/finetune.h"
#include "tool_main.h"
#include "train_flags.h"

using namespace paircast;

namespace {

struct Flags {
  FinetuneConfig c;
  std::string preset = "tiny";
  int imgSize = 224, patchSize = 16;
  std::string posEmbed = "cosine";
  bool quiet = false, predict = false, evaluate = false, noJitter = false;
  std::string checkpoint, image1, image2, out, tiling = "nearest";
  CLI::Option* blrOpt = nullptr;
};

void addTrainingFlags(CLI::App& app, Flags& f) {
  TrainConfig& t = f.c.train;
  app.add_option("--data", f.c.data,
                 "Training shards (files or globs) written with generate_pairs --save-flow "
                 "--save-depth");
  app.add_option("--eval-data", f.c.evalData,
                 "Held-out shards (other scenes): figures against a trivial baseline at the end");
  app.add_option("--eval-pairs", f.c.evalPairs, "Held-out pairs measured (0: all)");
  app.add_option("--eval-every", f.c.evalEvery,
                 "Also measure the held-out figures every N steps, into OUT/log.jsonl (learning "
                 "curves; 0: at the end only)");
  app.add_option("--task", f.c.model.task, "flow, depth or pose")
      ->check(CLI::IsMember({"flow", "depth", "pose"}));
  app.add_option("--head", f.c.model.head,
                 "flow: dpt (CroCo-Flow's PixelwiseTaskWithDPT, LaplacianLossBounded; needs "
                 "--img-size divisible by 32, e.g. 128 or 224, and 16-pixel patches) or linear "
                 "(the paper's: the prediction head regresses 2 channels per pixel, MSE; any "
                 "size); depth: dpt or linear (1 channel per pixel from the encoder); pose: pose "
                 "(default: "
                 "dpt for flow and depth, pose for pose)");
  app.add_option("--init", f.c.init,
                 "random, or a pre-training checkpoint: its encoder, and its decoder when it was "
                 "trained on cross-view completion (an mae checkpoint leaves the decoder random)");
  app.add_option("--hooks", f.c.model.hooks, "The DPT head's 4 block indices (default: see docs)");
  app.add_option("--flow-scale", f.c.model.flowScale,
                 "Flow: the head regresses flow divided by this many pixels (default: --img-size "
                 "/ 16; docs/finetune.md)");
  app.add_option("--preset", f.preset, "tiny, small or base")
      ->check(CLI::IsMember({"tiny", "small", "base"}));
  app.add_option("--img-size", f.imgSize, "Training crop size; prediction tiles by it");
  app.add_option("--patch-size", f.patchSize,
                 "ViT patch size (16; 8 gives 64 patches at --img-size 64, for --head linear or "
                 "pose: the DPT head needs 16)")
      ->check(CLI::Range(1, 64));
  app.add_option("--pos-embed", f.posEmbed,
                 "cosine or RoPE100, as the --init checkpoint was pre-trained (pretrain "
                 "--pos-embed)");
  addLoopFlags(app, t);
  f.blrOpt = app.get_option("--blr");
  f.blrOpt->description(
      "Base learning rate (lr = blr * effective batch / 256; default by task: 1e-2 for flow and "
      "depth, 2e-3 for pose, docs/finetune.md)");
  app.add_flag("--no-jitter", f.noJitter, "No colour jitter");
  app.add_flag("--quiet", f.quiet, "No progress lines");
}

void addPredictFlags(CLI::App& app, Flags& f) {
  app.add_flag("--predict", f.predict,
               "Run --checkpoint on --image1 (and --image2) and write --out: .flo and a PNG for "
               "flow, .exr for depth, .json for pose");
  app.add_flag("--evaluate", f.evaluate,
               "Measure --checkpoint on --eval-data alone (held-out figures as JSON)");
  app.add_option("--checkpoint", f.checkpoint, "A fine-tuned checkpoint (--predict, --evaluate)");
  app.add_option("--image1", f.image1, "The first image (--predict)");
  app.add_option("--image2", f.image2, "The second image (--predict; not for depth)");
  app.add_option("--out", f.out, "Output folder (training) or file (--predict)");
  app.add_option("--tiling", f.tiling,
                 "How --predict combines overlapping tiles of images larger than --img-size: "
                 "nearest (each pixel from the tile whose centre is nearest, the paper's) or "
                 "confidence (weighted by the flow head's confidence, as naver/croco's tiled_pred)")
      ->check(CLI::IsMember({"nearest", "confidence"}));
}

int train(Flags& f) {
  FinetuneConfig& c = f.c;
  c.train.out = f.out;
  c.train.progress = !f.quiet;
  c.colorJitter = !f.noJitter;
  c.model.croco = presetConfig(f.preset);
  c.model.croco.img_size = f.imgSize;
  c.model.croco.patch_size = f.patchSize;
  c.model.croco.pos_embed = f.posEmbed;
  if (c.model.head.empty()) c.model.head = c.model.task == "pose" ? "pose" : "dpt";
  if (f.blrOpt->count() == 0) c.train.blr = defaultFinetuneBlr(c.model.task);
  if (!f.quiet) logLaunch("finetune", launchRole(processEnvironment()).describe());
  std::printf("%s\n", runFinetune(c).dump().c_str());
  return 0;
}

int predictOrEvaluate(const Flags& f) {
  if (f.checkpoint.empty()) throw OptionError("checkpoint", "--checkpoint is required");
  if (f.evaluate) {
    if (f.c.evalData.empty()) throw OptionError("eval_data", "--evaluate needs --eval-data");
    std::printf("%s\n",
                evaluateCheckpoint(f.checkpoint, f.c.evalData, f.c.evalPairs, f.c.train.device)
                    .dump()
                    .c_str());
    return 0;
  }
  if (f.image1.empty() || f.out.empty())
    throw OptionError("image1", "--predict needs --image1 (and --image2) and --out");
  std::printf("%s\n", predictToFile(f.checkpoint, f.image1, f.image2, f.out, f.c.train.device,
                                    parseTiling(f.tiling))
                          .dump()
                          .c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Flags f;
  f.c.train.epochs = 10;
  f.c.model.head.clear();  // by task: dpt, or pose for pose
  CLI::App app{"Fine-tune CroCo for optical flow, depth or relative pose (naver/croco's names)"};
  addTrainingFlags(app, f);
  addPredictFlags(app, f);
  return runTool("finetune", app, argc, argv, [&] {
    if (f.predict || f.evaluate) return predictOrEvaluate(f);
    if (f.out.empty()) throw OptionError("out", "--out is required");
    return train(f);
  });
}
