// bench_train: pairs/s of the whole pre-training step (data included), from shards and with
// pairs rendered live, side by side with the official CroCo train step (naver/croco's CroCoNet,
// MaskedMSE and AdamW, model only) in Python when --croco-dir names a checkout of naver/croco.
// CPU by default (tiny and small at batch 16); on CUDA (--device cuda --amp bf16) it also gives
// the model FLOP utilisation, with the paper's FLOP convention and with the full count.
// --finetune times finetune's flow step instead (DPT head, LaplacianLossBounded, data included)
// beside naver/croco's CroCo-Flow step (CroCoDownstreamBinocular with PixelwiseTaskWithDPT,
// model only), same preset, size, batch and threads.
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "model/flops.h"
#include "trainer/trainer.h"
#include "util/error.h"
#include "util/heap.h"
#if PAIRCAST_WITH_RENDER
#include "dataset/generate_job.h"
#endif
#if PAIRCAST_WITH_FINETUNE
#include "finetune/finetune.h"
#endif

using namespace paircast;
namespace fs = std::filesystem;

namespace {

struct Options {
  std::vector<std::string> presets = {"tiny", "small"};
  int batch = 16, steps = 12, warmupSteps = 2, threads = 2, workers = 2, imgSize = 224;
  std::string crocoDir, python = "/usr/bin/python3", device = "cpu", amp = "bf16";
  std::vector<std::string> data;  // shards; none: generated from scenes/ (full build)
  bool live = true, fusedAdamW = true, finetune = false;
  double peakTflops = 800.0;
};

// The SUMMARY line a timing script prints ("" when it printed none).
std::string summaryLine(const std::string& cmd) {
  std::string line;
  if (FILE* p = popen((cmd + " 2>&1 | grep ^SUMMARY").c_str(), "r")) {
    char buf[1024];
    while (fgets(buf, sizeof buf, p)) line += buf;
    pclose(p);
  }
  return line;
}

// The number after `key`= in a SUMMARY line; 0 when it has none.
double summaryValue(const std::string& line, const std::string& key) {
  const size_t at = line.find(" " + key + "=");
  return at == std::string::npos ? 0 : std::stod(line.substr(at + key.size() + 2));
}

double summarySeconds(const std::string& cmd) {
  return summaryValue(summaryLine(cmd), "train_s");
}

// The official step's seconds per iteration, timed by tests/model/croco_ref.py on the same
// device, batch and thread count; 0 when it could not run.
double officialTrainSeconds(const Options& o, const std::string& preset) {
  if (o.crocoDir.empty()) return 0;
  const std::string cmd =
      o.python + " " + std::string(PAIRCAST_SOURCE_DIR) +
      "/tests/model/croco_ref.py bench --preset " + preset + " --batch " + std::to_string(o.batch) +
      " --threads " + std::to_string(o.threads) + " --device " + o.device + " --amp " +
      (o.device == "cuda" ? o.amp : "none") + " --optimizer --repeat " +
      std::to_string(o.device == "cuda" ? 20 : 3) + " --croco-dir '" + o.crocoDir + "'";
  return summarySeconds(cmd);
}

// Steady-state pairs/s and data wait from OUT/log.jsonl, leaving out the first `skip` steps
// (CUDA context, cuBLAS handles and the caching allocator warm up there).
std::pair<double, double> steadyRate(const std::string& out, int batch, int skip) {
  std::ifstream in(out + "/log.jsonl");
  std::string line;
  double seconds = 0, wait = 0;
  int n = 0;
  while (std::getline(in, line)) {
    const auto j = nlohmann::json::parse(line, nullptr, false);
    if (!j.is_object() || j.value("step", int64_t{0}) < skip) continue;
    const double s = batch / j["pairs_per_s"].get<double>();
    seconds += s;
    wait += s * j["data_wait"].get<double>();
    ++n;
  }
  if (n == 0) return {0, 0};
  return {n * batch / seconds, wait / seconds};
}

// glibc's settings that keep freed memory (util/heap.h), for a Python process.
const char* const kKeepMemoryTunables =
    "GLIBC_TUNABLES=glibc.malloc.mmap_max=0:glibc.malloc.trim_threshold=18446744073709551615 ";

struct StepFigures {
  double seconds = 0;      // per step; 0 when it could not run
  double minorFaults = 0;  // per step
};

// naver/croco's CroCo-Flow step (bench/croco_flow_step.py), as Python runs it, or with glibc
// keeping freed memory as finetune does (`keepMemory`).
StepFigures officialFlowStep(const Options& o, const std::string& preset,
                             const std::vector<int>& hooks, bool keepMemory) {
  if (o.crocoDir.empty()) return {};
  std::string cmd = (keepMemory ? kKeepMemoryTunables : "") + o.python + " " +
                    std::string(PAIRCAST_SOURCE_DIR) + "/bench/croco_flow_step.py --preset " +
                    preset + " --batch " + std::to_string(o.batch) + " --threads " +
                    std::to_string(o.threads) + " --img-size " + std::to_string(o.imgSize) +
                    " --croco-dir '" + o.crocoDir + "' --hooks";
  for (int h : hooks) cmd += " " + std::to_string(h);
  const std::string line = summaryLine(cmd);
  return {summaryValue(line, "train_s"), summaryValue(line, "minflt_per_step")};
}

#if PAIRCAST_WITH_FINETUNE
// Prints and adds to `row` the official step's figures, under `label`, its keys `prefix`... and
// `ratioKey` (ours over it).
void addOfficialColumns(nlohmann::json& row, const std::string& preset, const StepFigures& off,
                        double batch, double ours, const char* label, const std::string& prefix,
                        const char* ratioKey) {
  const double pps = batch / off.seconds;
  std::printf("%-6s %s: %8.2f pairs/s  %9.0f minor faults/step -> ours %.2fx\n", preset.c_str(),
              label, pps, off.minorFaults, ours / pps);
  row[prefix + "pairs_per_s"] = pps;
  row[prefix + "minor_faults_per_step"] = off.minorFaults;
  row[ratioKey] = ours / pps;
}

// finetune's flow step (DPT head) on `preset`: pairs/s, data wait and minor faults per step.
nlohmann::json timeFinetune(const Options& o, const std::vector<std::string>& shards,
                            const std::string& tmp, const std::string& preset,
                            std::vector<int>* hooks) {
  FinetuneConfig c;
  c.data = shards;
  c.model.croco = presetConfig(preset);
  c.model.croco.img_size = o.imgSize;
  c.train.batchSize = o.batch;
  c.train.maxSteps = o.steps;
  c.train.epochs = 100;
  c.train.saveEvery = 1000000;
  c.train.out = tmp + "/finetune-" + preset;
  c.train.device = o.device;
  c.train.amp = o.amp;
  c.train.progress = false;
  const long faults0 = minorPageFaults();
  const nlohmann::json s = runFinetune(c);
  const double faults = static_cast<double>(minorPageFaults() - faults0) / o.steps;
  auto [pps, wait] = steadyRate(c.train.out, o.batch, o.warmupSteps);
  std::printf(
      "%-6s finetune flow (dpt) %8.2f pairs/s  data-wait %5.1f%%  %9.0f minor faults/step\n",
      preset.c_str(), pps, 100 * wait, faults);
  *hooks = s["hooks"].get<std::vector<int>>();
  return {{"preset", preset},   {"task", "flow"},    {"head", "dpt"},
          {"pairs_per_s", pps}, {"data_wait", wait}, {"minor_faults_per_step", faults}};
}

// finetune's flow step (DPT head) for each preset, beside the official one as Python runs it
// and with glibc keeping freed memory as ours does.
nlohmann::json finetuneRows(const Options& o, const std::vector<std::string>& shards,
                            const std::string& tmp) {
  nlohmann::json rows = nlohmann::json::array();
  for (const auto& preset : o.presets) {
    std::vector<int> hooks;
    nlohmann::json row = timeFinetune(o, shards, tmp, preset, &hooks);
    const double ours = row["pairs_per_s"].get<double>();
    const StepFigures off = officialFlowStep(o, preset, hooks, false);
    if (off.seconds > 0) {
      addOfficialColumns(row, preset, off, o.batch, ours,
                         "official CroCo-Flow train step (model only)", "official_", "ratio");
      const StepFigures kept = officialFlowStep(o, preset, hooks, true);
      if (kept.seconds > 0)
        addOfficialColumns(row, preset, kept, o.batch, ours,
                           "the same, glibc keeping freed memory as ours", "official_kept_memory_",
                           "ratio_kept_memory");
    } else if (!o.crocoDir.empty()) {
      std::printf("%-6s official CroCo-Flow step did not run (%s with torch, --croco-dir)\n",
                  preset.c_str(), o.python.c_str());
    }
    rows.push_back(row);
  }
  return rows;
}
#endif

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{"Pre-training step speed, data included"};
  app.add_option("--presets", o.presets, "Presets");
  app.add_option("--batch", o.batch, "Batch size");
  app.add_option("--steps", o.steps, "Iterations per run");
  app.add_option("--warmup-steps", o.warmupSteps, "First iterations left out of the rate");
  app.add_option("--threads", o.threads, "Torch threads");
  app.add_option("--workers", o.workers, "Data worker threads");
  app.add_option("--img-size", o.imgSize, "Training crop size");
  app.add_option("--data", o.data,
                 "Tar shards or globs to train from (default: pairs generated from scenes/)");
  app.add_option("--device", o.device, "cpu or cuda")->check(CLI::IsMember({"cpu", "cuda"}));
  app.add_option("--amp", o.amp, "On CUDA: bf16, fp16 or none")
      ->check(CLI::IsMember({"bf16", "fp16", "none"}));
  app.add_flag("!--no-fused-adamw", o.fusedAdamW, "On CUDA, LibTorch's unfused AdamW step");
  app.add_option("--peak-tflops", o.peakTflops,
                 "The device's dense bf16 peak for the utilisation (H100 and H200: ~800 measured)");
  app.add_option("--croco-dir", o.crocoDir,
                 "A checkout of naver/croco, to time its train step alongside");
  app.add_option("--python", o.python, "The Python with torch that runs the official step");
  app.add_flag("!--no-live", o.live, "Skip the live-rendering runs");
  app.add_flag(
      "--finetune", o.finetune,
      "Time finetune's flow step (DPT head) instead, beside naver/croco's CroCo-Flow step");
  CLI11_PARSE(app, argc, argv);
  try {
    torch::set_num_threads(o.threads);
    const std::string tmp =
        (fs::temp_directory_path() / ("bench_train_" + std::to_string(::getpid()))).string();
    std::vector<std::string> shards = o.data;
#if PAIRCAST_WITH_RENDER
    const std::string scenes = std::string(PAIRCAST_SOURCE_DIR) + "/scenes";
    if (shards.empty()) {
      GenerateConfig g;
      g.scenes = {scenes};
      g.out = tmp + "/pairs";
      g.pairsPerScene = (o.batch * (o.steps + 2)) / 3 + 8;
      g.pair.resolution = 256;
      g.saveFlow = g.saveDepth = o.finetune;
      g.progress = false;
      runGenerate(g);
      shards = {tmp + "/pairs/pairs-*.tar"};
    }
#else
    if (shards.empty()) throw Error("this trainer-only build renders nothing: give --data shards");
    o.live = false;
#endif
    nlohmann::json rows = nlohmann::json::array();
#if PAIRCAST_WITH_FINETUNE
    if (o.finetune) {
      std::printf("batch %d, %s, %d torch threads, %dx%d crops, %d steps (%d left out)\n", o.batch,
                  o.device.c_str(), o.threads, o.imgSize, o.imgSize, o.steps, o.warmupSteps);
      rows = finetuneRows(o, shards, tmp);
      o.presets.clear();
    }
#else
    if (o.finetune) throw Error("this build has no finetune");
#endif
    std::printf(
        "batch %d, %s%s, %d torch threads, %d workers, %dx%d crops, %d steps (%d left out)\n",
        o.batch, o.device.c_str(), o.device == "cuda" ? (" " + o.amp).c_str() : "", o.threads,
        o.workers, o.imgSize, o.imgSize, o.steps, o.warmupSteps);
    for (const auto& preset : o.presets) {
      for (const bool isLive : {false, true}) {
        if (isLive && !o.live) continue;
        TrainConfig c;
#if PAIRCAST_WITH_RENDER
        if (isLive) c.live = {scenes};
#endif
        if (!isLive) c.shards = shards;
        c.model = presetConfig(preset);
        c.model.img_size = o.imgSize;
        c.batchSize = o.batch;
        c.maxSteps = o.steps;
        c.epochs = 100;
        c.saveEvery = 1000000;
        c.out = tmp + "/run-" + preset + (isLive ? "-live" : "-shards");
        c.workers = o.workers;
        c.device = o.device;
        c.amp = o.amp;
        c.fusedAdamW = o.fusedAdamW;
        c.progress = false;
        const nlohmann::json s = runPretrain(c);
        auto [pps, wait] = steadyRate(c.out, o.batch, o.warmupSteps);
        if (pps <= 0) pps = s["pairs_per_s"], wait = s["data_wait"];
        std::printf("%-6s %-7s %8.2f pairs/s  data-wait %5.1f%%", preset.c_str(),
                    isLive ? "live" : "shards", pps, 100 * wait);
        nlohmann::json row = {{"preset", preset},   {"source", isLive ? "live" : "shards"},
                              {"pairs_per_s", pps}, {"data_wait", wait},
                              {"loss", s["loss"]},  {"fused_adamw", s.value("fused_adamw", false)}};
        if (o.device == "cuda") {
          // Forward and backward: 3x the forward FLOPs.
          const FlopCount f = countFlops(c.model);
          const double mfuPaper = 3 * f.flops * pps / (o.peakTflops * 1e12);
          const double mfuFull = 3 * f.flops_full * pps / (o.peakTflops * 1e12);
          std::printf("  MFU %.1f%% (paper's FLOPs), %.1f%% (full count) of %.0f TFLOP/s",
                      100 * mfuPaper, 100 * mfuFull, o.peakTflops);
          row["mfu_paper"] = mfuPaper;
          row["mfu_full"] = mfuFull;
        }
        std::printf("\n");
        if (!isLive) {
          const double off = officialTrainSeconds(o, preset);
          if (off > 0) {
            std::printf(
                "%-6s official CroCo train step (model only): %8.2f pairs/s -> ours %.2fx\n",
                preset.c_str(), o.batch / off, pps / (o.batch / off));
            row["official_pairs_per_s"] = o.batch / off;
            row["ratio"] = pps / (o.batch / off);
          } else if (!o.crocoDir.empty()) {
            std::printf("%-6s official step did not run (%s with torch, --croco-dir)\n",
                        preset.c_str(), o.python.c_str());
          }
        }
        rows.push_back(row);
      }
    }
    fs::remove_all(tmp);
    std::printf("%s\n", nlohmann::json({{"batch", o.batch},
                                        {"threads", o.threads},
                                        {"device", o.device},
                                        {"amp", o.device == "cuda" ? o.amp : "none"},
                                        {"img_size", o.imgSize},
                                        {"peak_tflops", o.peakTflops},
                                        {"results", rows}})
                            .dump()
                            .c_str());
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_train: error: %s\n", e.what());
    return 1;
  }
}
