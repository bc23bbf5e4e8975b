// covis_sweep: CroCo's co-visibility ablation on your scenes, from one command.
#include <cstdio>

#include "render/scene_loader.h"
#include "sweep/covis_sweep.h"
#include "sweep/sweep_merge.h"
#include "tool_main.h"

using namespace paircast;

namespace {

int mergeParts(const std::vector<std::string>& parts, const std::string& out, bool otherDraws) {
  const nlohmann::json r = mergeSweepParts(parts, out, otherDraws);
  std::printf("%s\n", nlohmann::json({{"results", out + "/results.csv"},
                                      {"summary", out + "/summary.html"},
                                      {"seeds", r["config"]["seeds"]},
                                      {"parts", parts.size()}})
                          .dump()
                          .c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  SweepConfig c;
  std::vector<double> mechanismCovis = {c.mechanismMinCovis, c.mechanismMaxCovis};
  CLI::App app{
      "Pre-train on sets of pairs binned by co-visibility, and evaluate each on held-out scenes"};
  app.add_option("--scenes", c.scenes,
                 "Training scenes (files, folders or .txt lists); required but with --merge");
  app.add_option("--heldout", c.heldout,
                 "Held-out scenes for evaluation (never trained on); required but with --merge");
  app.add_option("--out", c.out, "Output folder (rerun with the same folder to resume)")
      ->required();
  app.add_option("--mode", c.modes, "bin, uniform, or bin,uniform")
      ->delimiter(',')
      ->check(CLI::IsMember({"bin", "uniform"}));
  app.add_option("--centers", c.centers, "Covis centres, e.g. 0.05,0.15,...,0.95")->delimiter(',');
  app.add_option("--sets", c.sets,
                 "Explicit sets instead of --mode x --centers, e.g. "
                 "bin_0.15,bin_0.55,uniform_0.50")
      ->delimiter(',');
  app.add_option("--pairs-per-set", c.pairsPerSet, "Pairs in every set")
      ->check(CLI::Range(1, 10000000));
  app.add_option("--steps", c.steps, "Training iterations per set")
      ->check(CLI::Range(1, 100000000));
  app.add_option("--preset", c.preset, "Model: tiny, small or base")
      ->check(CLI::IsMember({"tiny", "small", "base"}));
  app.add_option("--img-size", c.imgSize, "Training crop and probe size");
  app.add_option("--patch-size", c.patchSize, "ViT patch size");
  app.add_option("--resolution", c.resolution, "Rendered pair size");
  app.add_option("--batch-size", c.batchSize, "Pairs per iteration and process")
      ->check(CLI::Range(1, 65536));
  app.add_option("--device", c.device, "Training device (evaluation runs on the CPU)")
      ->check(CLI::IsMember({"cpu", "cuda"}));
  app.add_option("--amp", c.amp,
                 "Training and evaluation precision: auto (the default: bf16 on CUDA and on CPUs "
                 "with bf16 units, else float32), none (float32), bf16 or fp16 (CUDA training)")
      ->check(CLI::IsMember({"auto", "bf16", "fp16", "none"}));
  app.add_option("--blr", c.blr, "Base learning rate (lr = blr * batch / 256)");
  app.add_option(
      "--seed", c.seed,
      "Random seed of the pool and held-out data; run k of every set trains with seed + k");
  app.add_option("--seeds", c.seeds, "Runs per set and baseline, for the 95 % intervals");
  app.add_option("--first-seed", c.firstSeed,
                 "Seed index of the first run: this sweep runs seeds first-seed .. first-seed + "
                 "seeds - 1, a part of a study that --merge joins");
  std::vector<std::string> merge;
  CLI::Option* mergeOption =
      app.add_option("--merge", merge,
                     "Merge finished sweeps of one study, each with its own seeds (their folders "
                     "or results.json files), into the report of --out; no other option but "
                     "--other-draws is used");
  mergeOption->expected(1, -1);
  bool otherDraws = false;
  app.add_flag("--other-draws", otherDraws,
               "With --merge: merge parts whose settings agree but whose pairs were drawn apart "
               "(the same seed draws some other pairs on a CPU of another kind)")
      ->needs(mergeOption);
  app.add_option("--baseline", c.baselines,
                 "Baselines trained like the sets: mae (view 1 alone, no reference view)")
      ->delimiter(',');
  std::string up = "y";
  app.add_option("--up", up, std::string("Up axis of the scenes: y, z, or ") + kUpAutoHelp)
      ->check(CLI::IsMember({"y", "z", "auto"}));
  app.add_option("--jobs", c.jobs, "Render threads (0: all cores)");
  app.add_option("--eval-pairs", c.evalPairs, "Held-out pairs at covis ~0.5");
  app.add_option("--mechanism-pairs", c.mechanismPairs,
                 "Held-out pairs per held-out scene for the mechanism probes");
  app.add_option("--mechanism-covis", mechanismCovis,
                 "Covis band of the mechanism probes' pairs, lo,hi")
      ->delimiter(',')
      ->expected(2);
  app.add_option("--probe-views", c.probeViews,
                 "Held-out views for the depth probe (two halves, each fits the other's probe)");
  app.add_option("--min-walk-scale", c.minWalkScale,
                 "Smallest walk scale of the pool's second views (metres)");
  app.add_option("--downstream", c.downstream,
                 "Also fine-tune every run, and each seed's random weights, for flow, depth or "
                 "flow,depth (linear heads), and judge the claims on held-out pairs (added to a "
                 "finished sweep, only the fine-tunes run)")
      ->delimiter(',');
  app.add_option("--finetune-steps", c.finetuneSteps, "Steps of every fine-tune")
      ->check(CLI::Range(int64_t{1}, int64_t{100000000}));
  app.add_option("--finetune-pairs", c.finetunePairs,
                 "Fine-tuning pairs from the training scenes (covis >= 0.5), one set for all")
      ->check(CLI::Range(1, 10000000));
  app.add_option("--finetune-eval-pairs", c.finetuneEvalPairs,
                 "Held-out pairs from the held-out scenes (covis 0.1-1) the fine-tunes are "
                 "measured on")
      ->check(CLI::Range(1, 10000000));
  app.add_option("--finetune-flow-motion", c.finetuneFlowMotion,
                 "Flow's pairs: near (flow-style pairs of their own, generate_pairs --motion near, "
                 "covis >= 0.6, the default) or walk (the depth fine-tunes' pairs)")
      ->check(CLI::IsMember({"near", "walk"}));
  app.add_option("--finetune-batch", c.finetuneBatch, "Pairs per fine-tuning step and process")
      ->check(CLI::Range(1, 65536));
  app.add_option("--finetune-blr", c.finetuneBlr,
                 "Fine-tuning base learning rate (lr = blr * batch / 256)")
      ->check(CLI::PositiveNumber);
  app.add_option("--processes", c.processes,
                 "Worker processes that share the training and fine-tuning, one run each at a "
                 "time, each on 1/N of the threads (OMP_NUM_THREADS, else the cores; on 2 cores, "
                 "2 run about 1.7x faster than 1)")
      ->check(CLI::Range(1, 64));
  app.add_option("--worker", c.worker, "")->group("");  // set by --processes for its workers
  bool noReports = false, quiet = false;
  app.add_flag("--no-reports", noReports, "No dataset report per set");
  app.add_flag("--quiet", quiet, "No progress lines");
  return runTool("covis_sweep", app, argc, argv, [&] {
    c.load.up = parseUpAxis(up);
    c.mechanismMinCovis = mechanismCovis[0];
    c.mechanismMaxCovis = mechanismCovis[1];
    c.reports = !noReports;
    c.progress = !quiet;
    c.command.assign(argv, argv + argc);
    if (!merge.empty()) return mergeParts(merge, c.out, otherDraws);
    if (!quiet && c.worker == 0)
      logLaunch("covis_sweep", launchRole(processEnvironment()).describe());
    const nlohmann::json r = runCovisSweep(c);
    if (r.contains("worker")) return 0;  // the command that started it reports
    if (r.contains("rank")) {  // a rank > 0 of a multi-process sweep: rank 0 writes the results
      std::printf("%s\n", r.dump().c_str());
      return 0;
    }
    std::printf("%s\n", nlohmann::json({{"results", c.out + "/results.csv"},
                                        {"summary", c.out + "/summary.html"},
                                        {"seconds", r.at("seconds_this_run")}})
                            .dump()
                            .c_str());
    return 0;
  });
}
