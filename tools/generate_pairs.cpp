// generate_pairs: CroCo pre-training pairs from mesh scenes, as tar shards and/or CroCo's own
// folder layout. Its last line of output is the summary JSON.
#include <cstdio>

#include "dataset/dataset_report.h"
#include "dataset/generate_job.h"
#include "dataset/replay.h"
#include "tool_main.h"

using namespace paircast;

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

int main(int argc, char** argv) {
  GenerateConfig cfg;
  std::string up = "y", format = "shards", normalize = "valid";
  CLI::App app{"Render CroCo pre-training pairs (co-visibility in a band) from mesh scenes"};
  auto* scenesOpt = app.add_option("--scenes", cfg.scenes,
                                   "Scene files, folders (searched recursively) or .txt lists");
  ReplayConfig replay;
  auto* replayOpt =
      app.add_option("--from-metadata", replay.metadata,
                     "Render the poses of these metadata.json files (CroCo's or ours; folders "
                     "are searched) instead of sampling")
          ->excludes(scenesOpt);
  app.add_option("--scene-root", replay.sceneRoot,
                 "With --from-metadata: folder under which the metadata's scene paths are found");
  app.add_option("--out", cfg.out, "Output folder")->required();
  app.add_option("--pairs-per-scene", cfg.pairsPerScene, "Pairs to make in each scene");
  // Ranges are checked by GenerateConfig::validate(), the one place they are written.
  app.add_option("--resolution", cfg.pair.resolution, "Image width and height, pixels (16..4096)");
  app.add_option("--hfov", cfg.pair.hfov, "Horizontal field of view, degrees (1..179)");
  app.add_option("--min-covis", cfg.pair.minCovis, "Keep pairs with covis >= this");
  app.add_option("--max-covis", cfg.pair.maxCovis, "Keep pairs with covis <= this");
  app.add_option(
         "--covis-normalize", normalize,
         "valid: divide by valid pixels (the paper); all: by all pixels (CroCo's generator)")
      ->check(CLI::IsMember({"valid", "all"}));
  auto* upOpt =
      app.add_option("--up", up,
                     "Up axis of the scenes: y, z, or auto (the axis with the larger floor and "
                     "ceiling area)")
          ->check(CLI::IsMember({"y", "z", "auto"}));
  app.add_option("--scale", cfg.load.scale, "Multiply scene positions by this (to metres)");
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
  app.add_option("--format", format, "shards, croco or both")
      ->check(CLI::IsMember({"shards", "croco", "both"}));
  app.add_option("--shard-size", cfg.shardSize, "Pairs per tar shard");
  auto* shardIndexOpt = app.add_option(
      "--shard-index", cfg.shardIndex,
      "This machine's part of the scene list (0-based; default: from SLURM_ARRAY_TASK_ID or "
      "JOB_COMPLETION_INDEX, docs/scale.md)");
  auto* numShardsOpt =
      app.add_option(
             "--num-shards", cfg.numShards,
             "Number of parts the scene list is split into (default: "
             "SLURM_ARRAY_TASK_COUNT in a Slurm array; required in a Kubernetes Indexed Job)")
          ->check(CLI::Range(1, 100000));
  app.add_option("--jpeg-quality", cfg.jpegQuality, "JPEG quality (1..100)");
  app.add_option("--supersample", cfg.pair.render.supersample, "s x s colour samples per pixel")
      ->check(CLI::Range(1, 4));
  app.add_option("--max-attempts", cfg.pair.maxAttempts, "Second views tried per reference view");
  app.add_option("--min-valid", cfg.pair.minValidFraction, "Minimum fraction of pixels with depth");
  app.add_option("--views", cfg.pair.views,
                 "Views per sample (CroCo's views_count): view 1 and views-1 others, each with "
                 "covis in the band with view 1");
  app.add_option("--screen-resolution", cfg.pair.screenResolution,
                 "Screen candidates on depth at this resolution first, then at twice it while at "
                 "most a quarter of --resolution (0: off; default: a sixteenth of --resolution, "
                 "at least 16, off below 64)")
      ->check(CLI::NonNegativeNumber);  // -1 is the library's "automatic", not a user's value
  app.add_option("--screen-margin", cfg.pair.screenCovisMargin,
                 "Screening keeps candidates whose 32x32 covis estimate is within this of the band "
                 "(16x16: 2.5 times it; other sides: see --screen-fine-margin)");
  app.add_option("--screen-fine-margin", cfg.pair.screenFineMargin,
                 "The same margin for a 64x64 estimate; half of it per doubling beyond");
  app.add_flag_callback(
      "--screen-plain-tolerance", [&cfg] { cfg.pair.screenScaleTolerance = false; },
      "Screening estimates take covis' own depth tolerances at every side (default: "
      "scaled with the side, docs/dataset.md); they then need wider margins: "
      "--screen-margin 0.18 --screen-fine-margin 0.04 --screen-glance-margin 0.25");
  app.add_option("--screen-frame-margin", cfg.pair.screenFrameMargin,
                 "Before rendering, turn down candidates whose share of the reference inside their "
                 "frame is below --min-covis by more than this (default: off; 0.03 turns it on)");
  app.add_option("--screen-sight-margin", cfg.pair.screenSightMargin,
                 "Before rendering, turn down candidates that see (shadow rays) a share of the "
                 "reference's points below --min-covis by more than this");
  app.add_option("--screen-glance-margin", cfg.pair.screenGlanceCovisMargin,
                 "Turn down candidates whose 8x8 glance's share seen by the reference is below "
                 "--min-covis by more than this");
  app.add_flag("--screen-confirm", cfg.pair.screenConfirm,
               "Screen candidates whose last estimate is near a bound of the band once more, at "
               "twice its side (costs more than it saves at 256, docs/dataset.md)");
  app.add_option("--give-up-after", cfg.pair.giveUpAfter,
                 "Give a reference up after this many of its candidates in a row are turned down "
                 "before any render beyond 8x8 (0: never; the default)")
      ->check(CLI::NonNegativeNumber);
  app.add_flag("--save-covis-mask", cfg.pair.covisMasks,
               "Also write 8-bit co-visibility masks (255: seen by the other view)");
  bool allowSkipped = false;
  app.add_flag("--allow-skipped-scenes", allowSkipped,
               "Exit 0 when some scenes were skipped (default: exit 4)");
  bool quiet = false;
  app.add_flag("--quiet", quiet, "No progress line");
  bool report = false;
  app.add_flag("--report", report, "Write OUT/report.html (dataset_report) at the end");
  return runTool("generate_pairs", app, argc, argv, [&] {
    cfg.load.up = parseUpAxis(up);
    if (replayOpt->count()) {
      replay.out = cfg.out;
      replay.load = cfg.load;
      replay.upGiven = upOpt->count() > 0;
      replay.jpegQuality = cfg.jpegQuality;
      replay.render = cfg.pair.render;
      replay.progress = !quiet;
      const nlohmann::json summary = runReplay(replay);
      std::printf("%s\n", summary.dump().c_str());
      return exitStatus(summary["samples"].get<size_t>(), summary["skipped"].size(),
                        "metadata file(s)", cfg.out, allowSkipped);
    }
    if (cfg.scenes.empty()) throw Error("--scenes (or --from-metadata) is required");
    const JobPart part =
        jobPart(processEnvironment(),
                shardIndexOpt->count() ? std::optional<int>(cfg.shardIndex) : std::nullopt,
                numShardsOpt->count() ? std::optional<int>(cfg.numShards) : std::nullopt);
    cfg.shardIndex = part.index;
    cfg.numShards = part.count;
    if (!quiet) logLaunch("generate_pairs", part.describe());
    cfg.shards = format != "croco";
    cfg.croco = format != "shards";
    cfg.pair.covis.normalize =
        normalize == "all" ? CovisOptions::Normalize::All : CovisOptions::Normalize::Valid;
    cfg.progress = !quiet;
    nlohmann::json summary = runGenerate(cfg);
    if (report) {
      ReportOptions ro;
      ro.dir = cfg.out;
      summary["report"] = writeDatasetReport(ro)["report"];
    }
    std::printf("%s\n", summary.dump().c_str());
    return exitStatus(summary["pairs"].get<size_t>(), summary["skipped_scenes"].size(), "scene(s)",
                      cfg.out, allowSkipped);
  });
}
