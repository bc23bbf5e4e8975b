// generate_pairs: CroCo pre-training pairs from mesh scenes, as tar shards and/or CroCo's own
// folder layout. Its last line of output is the summary JSON.
#include <cstdio>

#include "dataset/dataset_report.h"
#include "dataset/generate_job.h"
#include "dataset/replay.h"
#include "pair_flags.h"
#include "render/scene_loader.h"
#include "tool_main.h"

using namespace paircast;

namespace {

// 0: done. 1 (with an error line): nothing could be made. 4: done, but some inputs (scenes, or
// metadata files with --from-metadata) were skipped (they are listed in summary.json), unless
// --allow-skipped-scenes.
int exitStatus(size_t made, size_t skipped, const char* inputs, const std::string& out,
               bool allowSkipped) {
  if (made == 0)
    throw Error(out + "/summary.json", "nothing could be made (" + std::to_string(skipped) + " " +
                                           inputs + " skipped; reasons listed there)");
  if (skipped == 0 || allowSkipped) return 0;
  std::fprintf(stderr,
               "generate_pairs: %zu %s skipped (listed in %s/summary.json); exit status 4 "
               "(--allow-skipped-scenes makes it 0)\n",
               skipped, inputs, out.c_str());
  return 4;
}

// What the command line holds besides the GenerateConfig and ReplayConfig it fills.
struct Args {
  std::string up = "y", format = "shards";
  bool allowSkipped = false, quiet = false, report = false;
  CLI::Option *upOpt = nullptr, *replayOpt = nullptr, *shardIndexOpt = nullptr,
              *numShardsOpt = nullptr;
};

// The inputs: scenes, or the metadata files to replay, and how to load them.
void addInputFlags(CLI::App& app, GenerateConfig& cfg, ReplayConfig& replay, Args& args) {
  auto* scenesOpt = app.add_option("--scenes", cfg.scenes,
                                   "Scene files, folders (searched recursively) or .txt lists");
  args.replayOpt =
      app.add_option("--from-metadata", replay.metadata,
                     "Render the poses of these metadata.json files (CroCo's or ours; folders "
                     "are searched) instead of sampling")
          ->excludes(scenesOpt);
  app.add_option("--scene-root", replay.sceneRoot,
                 "With --from-metadata: folder under which the metadata's scene paths are found");
  args.upOpt =
      app.add_option("--up", args.up, std::string("Up axis of the scenes: y, z, or ") + kUpAutoHelp)
          ->check(CLI::IsMember({"y", "z", "auto"}));
  app.add_option("--scale", cfg.load.scale, "Multiply scene positions by this (to metres)");
}

// The job: how many samples, where they go and in what form, and this machine's part of it.
// Ranges are checked by GenerateConfig::validate(), the one place they are written.
void addJobFlags(CLI::App& app, GenerateConfig& cfg, Args& args) {
  app.add_option("--out", cfg.out, "Output folder")->required();
  app.add_option("--pairs-per-scene", cfg.pairsPerScene, "Pairs to make in each scene");
  app.add_flag("--save-depth", cfg.saveDepth,
               "Also write z-depth EXR (and camera JSON in croco layout)");
  app.add_flag("--save-flow", cfg.saveFlow,
               "Also write exact optical flow, Middlebury .flo in pixels: view 1's into view 2 "
               "(_1_flow.flo, K.1.flow.flo) and each other view's into view 1 (_k_flow.flo); "
               "+inf where a pixel has no depth or lies behind the other camera");
  app.add_option("--seed", cfg.seed,
                 "Random seed; the output depends only on it and the arguments");
  app.add_option("--jobs", cfg.jobs, "Worker threads (default: all cores)")
      ->check(CLI::Range(0, 1024));
  app.add_option("--format", args.format, "shards, croco or both")
      ->check(CLI::IsMember({"shards", "croco", "both"}));
  app.add_option("--shard-size", cfg.shardSize, "Pairs per tar shard");
  args.shardIndexOpt = app.add_option(
      "--shard-index", cfg.shardIndex,
      "This machine's part of the scene list (0-based; default: from SLURM_ARRAY_TASK_ID or "
      "JOB_COMPLETION_INDEX, docs/scale.md)");
  args.numShardsOpt =
      app.add_option(
             "--num-shards", cfg.numShards,
             "Number of parts the scene list is split into (default: "
             "SLURM_ARRAY_TASK_COUNT in a Slurm array; required in a Kubernetes Indexed Job)")
          ->check(CLI::Range(1, 100000));
  app.add_option("--jpeg-quality", cfg.jpegQuality, "JPEG quality (1..100)");
  app.add_flag("--allow-skipped-scenes", args.allowSkipped,
               "Exit 0 when some scenes were skipped (default: exit 4)");
  app.add_flag("--quiet", args.quiet, "No progress line");
  app.add_flag("--report", args.report, "Write OUT/report.html (dataset_report) at the end");
}

// --from-metadata: renders the poses of the given metadata files.
int replayMetadata(const GenerateConfig& cfg, ReplayConfig replay, const Args& args) {
  replay.out = cfg.out;
  replay.load = cfg.load;
  replay.upGiven = args.upOpt->count() > 0;
  replay.jpegQuality = cfg.jpegQuality;
  replay.render = cfg.pair.render;
  replay.progress = !args.quiet;
  const nlohmann::json summary = runReplay(replay);
  std::printf("%s\n", summary.dump().c_str());
  return exitStatus(summary["samples"].get<size_t>(), summary["skipped"].size(), "metadata file(s)",
                    cfg.out, args.allowSkipped);
}

// Samples pairs in this machine's part of the scenes.
int generateFromScenes(GenerateConfig cfg, const Args& args) {
  if (cfg.scenes.empty()) throw Error("--scenes (or --from-metadata) is required");
  const JobPart part =
      jobPart(processEnvironment(),
              args.shardIndexOpt->count() ? std::optional<int>(cfg.shardIndex) : std::nullopt,
              args.numShardsOpt->count() ? std::optional<int>(cfg.numShards) : std::nullopt);
  cfg.shardIndex = part.index;
  cfg.numShards = part.count;
  if (!args.quiet) logLaunch("generate_pairs", part.describe());
  cfg.shards = args.format != "croco";
  cfg.croco = args.format != "shards";
  cfg.progress = !args.quiet;
  nlohmann::json summary = runGenerate(cfg);
  if (args.report) {
    ReportOptions ro;
    ro.dir = cfg.out;
    summary["report"] = writeDatasetReport(ro)["report"];
  }
  std::printf("%s\n", summary.dump().c_str());
  return exitStatus(summary["pairs"].get<size_t>(), summary["skipped_scenes"].size(), "scene(s)",
                    cfg.out, args.allowSkipped);
}

}  // namespace

int main(int argc, char** argv) {
  GenerateConfig cfg;
  ReplayConfig replay;
  Args args;
  CLI::App app{"Render CroCo pre-training pairs (co-visibility in a band) from mesh scenes"};
  addInputFlags(app, cfg, replay, args);
  addJobFlags(app, cfg, args);
  addPairFlags(app, cfg.pair);
  return runTool("generate_pairs", app, argc, argv, [&] {
    cfg.load.up = parseUpAxis(args.up);
    return args.replayOpt->count() ? replayMetadata(cfg, replay, args)
                                   : generateFromScenes(cfg, args);
  });
}
