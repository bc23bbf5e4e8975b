// bench_train: pairs/s of the whole pre-training step (data included), from shards and with
// pairs rendered live, side by side with the official CroCo train step (naver/croco's CroCoNet,
// MaskedMSE and AdamW, model only) in Python when --croco-dir names a checkout of naver/croco.
// CPU by default (tiny and small at batch 16); on CUDA (--device cuda --amp bf16) it also gives
// the model FLOP utilisation, with the paper's FLOP convention and with the full count.
// On the CPU one run gives, for the same preset, size, batch and threads: ours at the precision
// --amp auto picks and ours in float32, the official step in float32 and under
// torch.autocast("cpu", dtype=torch.bfloat16), the machine's GEMM peak at both precisions
// (a 2048^3 matmul through LibTorch) and each step's model FLOP/s as a fraction of the peak at
// its precision.
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

#include "model/autocast.h"
#include "model/flops.h"
#include "model/precision.h"
#include "trainer/trainer.h"
#include "util/blas_core.h"
#include "util/error.h"
#include "util/heap.h"
#include "util/timer.h"
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
  std::string crocoDir, python = "/usr/bin/python3", device = "cpu", amp = "auto";
  std::vector<std::string> data;  // shards; none: generated from scenes/ (full build)
  bool live = true, fusedAdamW = true, finetune = false, profile = false;
  double peakTflops = 800.0;
};

// Prints a profile written by the training loop (trainer/op_profile.h): the stages, the kinds of
// operator and the slowest operators, in ms a step; returns it.
nlohmann::json printProfile(const std::string& preset, const std::string& file) {
  std::ifstream in(file);
  const nlohmann::json p = nlohmann::json::parse(in);
  std::printf("%-6s profile, %s, %lld steps: %.1f ms a step, %.1f in operators\n", preset.c_str(),
              p["precision"].value("ran", "").c_str(), p["steps"].get<long long>(),
              p["wall_ms_per_step"].get<double>(), p["ms_per_step"].get<double>());
  const std::pair<const char*, const char*> tables[] = {
      {"stages", "stage"}, {"kinds", "kind"}, {"ops", "op"}};
  for (const auto& [table, key] : tables)
    for (const auto& r : p[table])
      std::printf("  %-6s %-34s %8.2f ms %5.1f%% %9.1f calls\n", table,
                  r[key].get<std::string>().c_str(), r["ms_per_step"].get<double>(),
                  100 * r["share"].get<double>(), r["calls_per_step"].get<double>());
  return p;
}

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
// device, batch and thread count, under autocast to `amp` (bf16, fp16 or none); 0 when it could
// not run.
double officialTrainSeconds(const Options& o, const std::string& preset, const std::string& amp) {
  if (o.crocoDir.empty()) return 0;
  const std::string cmd = o.python + " " + std::string(PAIRCAST_SOURCE_DIR) +
                          "/tests/model/croco_ref.py bench --preset " + preset + " --batch " +
                          std::to_string(o.batch) + " --threads " + std::to_string(o.threads) +
                          " --device " + o.device + " --amp " + amp + " --optimizer --repeat " +
                          std::to_string(o.device == "cuda" ? 20 : 3) + " --croco-dir '" +
                          o.crocoDir + "'";
  return summarySeconds(cmd);
}

// The device's GEMM peak at `dtype`, GFLOP/s: the best of 5 n^3 matmuls through LibTorch (at
// the threads set), after one to warm up.
double gemmPeakGflops(const torch::Device& device, torch::ScalarType dtype, int n = 2048) {
  torch::NoGradGuard ng;
  const auto a = torch::randn({n, n}, device).to(dtype), b = torch::randn({n, n}, device).to(dtype);
  const auto sync = [&] {
    if (device.is_cuda()) torch::cuda::synchronize();
  };
  double best = 1e30;
  for (int rep = 0; rep < 6; ++rep) {
    sync();
    const auto t0 = SteadyClock::now();
    torch::mm(a, b);
    sync();
    if (rep > 0) best = std::min(best, secondsSince(t0));
  }
  return 2.0 * n * n * n / best / 1e9;
}

// The peaks of both precisions, and the one a step at `precision` ("float32", "bf16", "fp16")
// is measured against.
struct GemmPeaks {
  double float32 = 0, bf16 = 0;  // GFLOP/s
  double at(const std::string& precision) const { return precision == "float32" ? float32 : bf16; }
};

// A training step's model FLOP/s (3x the forward's, the full count) at `pairsPerS`, as a
// fraction of the peak at its precision.
double gemmFraction(double forwardFlops, double pairsPerS, const GemmPeaks& peaks,
                    const std::string& precision) {
  return 3 * forwardFlops * pairsPerS / (peaks.at(precision) * 1e9);
}

// Prints and adds the GEMM-peak fraction of a step at `pps` pairs/s and `precision` under `key`.
void addFraction(nlohmann::json& row, const char* key, double flops, double pps,
                 const GemmPeaks& peaks, const std::string& precision) {
  const double f = gemmFraction(flops, pps, peaks, precision);
  std::printf("  %.1f%% of the %s GEMM peak", 100 * f, precision.c_str());
  row[key] = f;
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
                             const std::vector<int>& hooks, bool keepMemory,
                             const std::string& amp = "none") {
  if (o.crocoDir.empty()) return {};
  std::string cmd = (keepMemory ? kKeepMemoryTunables : "") + o.python + " " +
                    std::string(PAIRCAST_SOURCE_DIR) + "/bench/croco_flow_step.py --preset " +
                    preset + " --batch " + std::to_string(o.batch) + " --threads " +
                    std::to_string(o.threads) + " --img-size " + std::to_string(o.imgSize) +
                    " --amp " + amp + " --croco-dir '" + o.crocoDir + "' --hooks";
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

// finetune's flow step (DPT head) on `preset` at --amp `amp`: pairs/s, data wait and minor
// faults per step.
nlohmann::json timeFinetune(const Options& o, const std::vector<std::string>& shards,
                            const std::string& tmp, const std::string& preset,
                            const std::string& amp, std::vector<int>* hooks) {
  FinetuneConfig c;
  c.data = shards;
  c.model.croco = presetConfig(preset);
  c.model.croco.img_size = o.imgSize;
  c.train.batchSize = o.batch;
  c.train.maxSteps = o.steps;
  c.train.epochs = 100;
  c.train.saveEvery = 1000000;
  c.train.out = tmp + "/finetune-" + preset + "-" + amp;
  c.train.device = o.device;
  c.train.amp = amp;
  c.train.progress = false;
  const long faults0 = minorPageFaults();
  const nlohmann::json s = runFinetune(c);
  const double faults = static_cast<double>(minorPageFaults() - faults0) / o.steps;
  auto [pps, wait] = steadyRate(c.train.out, o.batch, o.warmupSteps);
  const std::string ran = s["precision"]["ran"];
  std::printf(
      "%-6s finetune flow (dpt), %-7s %8.2f pairs/s  data-wait %5.1f%%  %9.0f minor faults/step\n",
      preset.c_str(), ran.c_str(), pps, 100 * wait, faults);
  *hooks = s["hooks"].get<std::vector<int>>();
  return {{"preset", preset},   {"task", "flow"},    {"head", "dpt"},
          {"pairs_per_s", pps}, {"data_wait", wait}, {"minor_faults_per_step", faults},
          {"precision", ran}};
}

// The flow step's forward FLOPs, backbone only: both views encoded whole, the decoder, no DPT
// head (model/flops.h counts the pre-training head).
double flowBackboneFlops(const Options& o, const std::string& preset) {
  CroCoConfig c = presetConfig(preset);
  c.img_size = o.imgSize;
  c.mask_ratio = 0;
  return countFlops(c).flops_full;
}

// finetune's flow step (DPT head) for each preset, beside the official one as Python runs it
// and with glibc keeping freed memory as ours does.
nlohmann::json finetuneRows(const Options& o, const std::vector<std::string>& shards,
                            const std::string& tmp, const GemmPeaks& peaks) {
  nlohmann::json rows = nlohmann::json::array();
  for (const auto& preset : o.presets) {
    std::vector<int> hooks;
    nlohmann::json row = timeFinetune(o, shards, tmp, preset, o.amp, &hooks);
    const double ours = row["pairs_per_s"].get<double>();
    const double flops = flowBackboneFlops(o, preset);
    const std::string ran = row["precision"];
    std::printf("%-6s ours, %s:", preset.c_str(), ran.c_str());
    addFraction(row, "gemm_fraction", flops, ours, peaks, ran);
    std::printf(" (backbone FLOPs, DPT head not counted)\n");
    if (ran != "float32") {
      std::vector<int> unused;
      const nlohmann::json f32 = timeFinetune(o, shards, tmp, preset, "none", &unused);
      row["float32_pairs_per_s"] = f32["pairs_per_s"];
      std::printf("%-6s ours, float32 -> %s is %.2fx it;", preset.c_str(), ran.c_str(),
                  ours / f32["pairs_per_s"].get<double>());
      addFraction(row, "float32_gemm_fraction", flops, f32["pairs_per_s"].get<double>(), peaks,
                  "float32");
      std::printf("\n");
    }
    const StepFigures off = officialFlowStep(o, preset, hooks, false);
    if (off.seconds > 0) {
      addOfficialColumns(row, preset, off, o.batch, ours,
                         "official CroCo-Flow train step (model only)", "official_", "ratio");
      if (o.device == "cpu") {
        const StepFigures offBf16 = officialFlowStep(o, preset, hooks, false, "bf16");
        if (offBf16.seconds > 0) {
          addOfficialColumns(row, preset, offBf16, o.batch, ours,
                             "official CroCo-Flow step under CPU bf16 autocast", "official_bf16_",
                             "ratio_bf16");
          std::printf("%-6s official float32:", preset.c_str());
          addFraction(row, "official_gemm_fraction", flops, o.batch / off.seconds, peaks,
                      "float32");
          std::printf("; official bf16:");
          addFraction(row, "official_bf16_gemm_fraction", flops, o.batch / offBf16.seconds, peaks,
                      "bf16");
          std::printf("\n");
        }
      }
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

// What every run of the pre-training step shares: the options, the data and the peaks.
struct Bench {
  Options o;
  Precision precision;
  GemmPeaks peaks;
  std::vector<std::string> shards;
  std::string tmp;     // scratch folder, removed at the end
  std::string scenes;  // the shipped scenes, for live rendering
};

void addOptions(CLI::App& app, Options& o) {
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
  app.add_option("--amp", o.amp,
                 "Our step's precision: auto (bf16 on CUDA and on CPUs with bf16 units), bf16, "
                 "fp16 (CUDA) or none; a second run times it in float32")
      ->check(CLI::IsMember({"auto", "bf16", "fp16", "none"}));
  app.add_flag("!--no-fused-adamw", o.fusedAdamW,
               "LibTorch's per-parameter AdamW step instead of the fused kernel (CUDA) or the "
               "flat buffers (CPU)");
  app.add_flag("--profile", o.profile,
               "Also run our step once more under the operator profiler and print where its "
               "time goes, by stage and by kind of operator (not in the timed runs)");
  app.add_option("--peak-tflops", o.peakTflops,
                 "The device's dense bf16 peak for the utilisation (H100 and H200: ~800 measured)");
  app.add_option("--croco-dir", o.crocoDir,
                 "A checkout of naver/croco, to time its train step alongside");
  app.add_option("--python", o.python, "The Python with torch that runs the official step");
  app.add_flag("!--no-live", o.live, "Skip the live-rendering runs");
  app.add_flag(
      "--finetune", o.finetune,
      "Time finetune's flow step (DPT head) instead, beside naver/croco's CroCo-Flow step");
}

// The shards to train from: --data's, or pairs rendered from the shipped scenes into b.tmp.
void prepareData(Bench& b) {
  b.shards = b.o.data;
#if PAIRCAST_WITH_RENDER
  b.scenes = std::string(PAIRCAST_SOURCE_DIR) + "/scenes";
  if (!b.shards.empty()) return;
  GenerateConfig g;
  g.scenes = {b.scenes};
  g.out = b.tmp + "/pairs";
  g.pairsPerScene = (b.o.batch * (b.o.steps + 2)) / 3 + 8;
  g.pair.resolution = 256;
  g.saveFlow = g.saveDepth = b.o.finetune;
  g.progress = false;
  runGenerate(g);
  b.shards = {b.tmp + "/pairs/pairs-*.tar"};
#else
  if (b.shards.empty()) throw Error("this trainer-only build renders nothing: give --data shards");
  b.o.live = false;
#endif
}

struct Rate {
  double pairsPerS = 0, dataWait = 0;
  nlohmann::json summary;
};

// Ours on `preset` at --amp `amp`: steady pairs/s, data wait and summary.json.
Rate runOurs(const Bench& b, const std::string& preset, bool isLive, const std::string& amp,
             bool fusedAdamW, const std::string& profile) {
  TrainConfig c;
#if PAIRCAST_WITH_RENDER
  if (isLive) c.live = {b.scenes};
#endif
  if (!isLive) c.shards = b.shards;
  c.model = presetConfig(preset);
  c.model.img_size = b.o.imgSize;
  c.batchSize = b.o.batch;
  c.maxSteps = b.o.steps;
  c.epochs = 100;
  c.saveEvery = 1000000;
  c.out = b.tmp + "/run-" + preset + (isLive ? "-live-" : "-shards-") + amp;
  c.workers = b.o.workers;
  c.device = b.o.device;
  c.amp = amp;
  c.fusedAdamW = fusedAdamW;
  c.profile = profile;
  c.progress = false;
  Rate r;
  r.summary = runPretrain(c);
  std::tie(r.pairsPerS, r.dataWait) = steadyRate(c.out, b.o.batch, b.o.warmupSteps);
  if (r.pairsPerS <= 0) r.pairsPerS = r.summary["pairs_per_s"], r.dataWait = r.summary["data_wait"];
  return r;
}

// Our step on `preset` at --amp, from shards or live, with its MFU (CUDA) or GEMM-peak fraction.
nlohmann::json oursRow(const Bench& b, const std::string& preset, bool isLive, const FlopCount& f,
                       double* pps) {
  const Rate r = runOurs(b, preset, isLive, b.o.amp, b.o.fusedAdamW, "");
  const std::string& ran = b.precision.ran;
  std::printf("%-6s %-7s %-7s %8.2f pairs/s  data-wait %5.1f%%", preset.c_str(),
              isLive ? "live" : "shards", ran.c_str(), r.pairsPerS, 100 * r.dataWait);
  nlohmann::json row = {{"preset", preset},
                        {"source", isLive ? "live" : "shards"},
                        {"pairs_per_s", r.pairsPerS},
                        {"data_wait", r.dataWait},
                        {"loss", r.summary["loss"]},
                        {"fused_adamw", r.summary.value("fused_adamw", false)},
                        {"precision", ran}};
  if (b.o.device == "cuda") {
    // Forward and backward: 3x the forward FLOPs.
    const double mfuPaper = 3 * f.flops * r.pairsPerS / (b.o.peakTflops * 1e12);
    const double mfuFull = 3 * f.flops_full * r.pairsPerS / (b.o.peakTflops * 1e12);
    std::printf("  MFU %.1f%% (paper's FLOPs), %.1f%% (full count) of %.0f TFLOP/s", 100 * mfuPaper,
                100 * mfuFull, b.o.peakTflops);
    row["mfu_paper"] = mfuPaper;
    row["mfu_full"] = mfuFull;
  } else {
    addFraction(row, "gemm_fraction", f.flops_full, r.pairsPerS, b.peaks, ran);
  }
  std::printf("\n");
  *pps = r.pairsPerS;
  return row;
}

// Our own variants from shards, beside `pps`: float32 when --amp ran another precision, the
// per-parameter AdamW, and the operator profile when asked.
void addOurVariants(const Bench& b, const std::string& preset, const FlopCount& f, double pps,
                    nlohmann::json& row) {
  const std::string& ran = b.precision.ran;
  if (b.o.device == "cpu" && ran != "float32") {
    const Rate r32 = runOurs(b, preset, false, "none", b.o.fusedAdamW, "");
    std::printf("%-6s shards  float32 %8.2f pairs/s  data-wait %5.1f%%", preset.c_str(),
                r32.pairsPerS, 100 * r32.dataWait);
    addFraction(row, "float32_gemm_fraction", f.flops_full, r32.pairsPerS, b.peaks, "float32");
    std::printf("  -> %s is %.2fx\n", ran.c_str(), pps / r32.pairsPerS);
    row["float32_pairs_per_s"] = r32.pairsPerS;
    row["float32_data_wait"] = r32.dataWait;
  }
  if (b.o.device == "cpu" && b.o.fusedAdamW) {
    const Rate own = runOurs(b, preset, false, b.o.amp, false, "");
    std::printf(
        "%-6s shards  %-7s %8.2f pairs/s  with LibTorch's per-parameter AdamW "
        "-> flat buffers %.2fx\n",
        preset.c_str(), ran.c_str(), own.pairsPerS, pps / own.pairsPerS);
    row["per_parameter_adamw_pairs_per_s"] = own.pairsPerS;
  }
  if (b.o.profile) {
    const std::string file = b.tmp + "/profile-" + preset + ".json";
    runOurs(b, preset, false, b.o.amp, b.o.fusedAdamW, file);
    row["profile"] = printProfile(preset, file);
  }
}

// The official CroCo train step beside `pps`: on CUDA at our precision; on the CPU in float32
// and under torch.autocast's bf16.
void addOfficialRates(const Bench& b, const std::string& preset, const FlopCount& f, double pps,
                      nlohmann::json& row) {
  const bool cuda = b.o.device == "cuda";
  const std::string amp =
      cuda ? (b.precision.ran == "float32" ? "none" : b.precision.ran) : std::string("none");
  const double off = officialTrainSeconds(b.o, preset, amp);
  if (off > 0) {
    const double offPps = b.o.batch / off;
    std::printf("%-6s official CroCo train step (model only), %s: %8.2f pairs/s -> ours %.2fx",
                preset.c_str(), cuda ? amp.c_str() : "float32", offPps, pps / offPps);
    row["official_pairs_per_s"] = offPps;
    row["ratio"] = pps / offPps;
    if (!cuda) addFraction(row, "official_gemm_fraction", f.flops_full, offPps, b.peaks, "float32");
    std::printf("\n");
  } else if (!b.o.crocoDir.empty()) {
    std::printf("%-6s official step did not run (%s with torch, --croco-dir)\n", preset.c_str(),
                b.o.python.c_str());
  }
  const double offBf16 = cuda ? 0 : officialTrainSeconds(b.o, preset, "bf16");
  if (offBf16 <= 0) return;
  const double bf16Pps = b.o.batch / offBf16;
  std::printf("%-6s official step under torch.autocast(\"cpu\", bf16): %8.2f pairs/s -> ours %.2fx",
              preset.c_str(), bf16Pps, pps / bf16Pps);
  row["official_bf16_pairs_per_s"] = bf16Pps;
  row["ratio_bf16"] = pps / bf16Pps;
  addFraction(row, "official_bf16_gemm_fraction", f.flops_full, bf16Pps, b.peaks, "bf16");
  std::printf("\n");
}

// The pre-training step for each preset: from shards (with our variants and the official step
// beside it) and, unless --no-live, with pairs rendered live.
nlohmann::json pretrainRows(const Bench& b) {
  nlohmann::json rows = nlohmann::json::array();
  for (const auto& preset : b.o.presets) {
    CroCoConfig c = presetConfig(preset);
    c.img_size = b.o.imgSize;
    const FlopCount f = countFlops(c);
    for (const bool isLive : {false, true}) {
      if (isLive && !b.o.live) continue;
      double pps = 0;
      nlohmann::json row = oursRow(b, preset, isLive, f, &pps);
      if (!isLive) {
        addOurVariants(b, preset, f, pps, row);
        addOfficialRates(b, preset, f, pps, row);
      }
      rows.push_back(row);
    }
  }
  return rows;
}

void printSummary(const Bench& b, const nlohmann::json& rows) {
  const nlohmann::json summary = {
      {"batch", b.o.batch},
      {"threads", b.o.threads},
      {"device", b.o.device},
      {"amp", b.o.amp},
      {"precision", b.precision.toJson()},
      {"gemm_peak_gflops", {{"float32", b.peaks.float32}, {"bf16", b.peaks.bf16}}},
      {"img_size", b.o.imgSize},
      {"peak_tflops", b.o.peakTflops},
      {"results", rows}};
  std::printf("%s\n", summary.dump().c_str());
}

int run(Bench& b) {
  torch::set_num_threads(b.o.threads);
  const torch::Device device(b.o.device == "cuda" ? torch::kCUDA : torch::kCPU);
  b.precision = resolvePrecision(b.o.amp, device.type(), "bench_train");
  if (b.o.device == "cpu") {
    b.peaks.float32 = gemmPeakGflops(device, torch::kFloat32);
    b.peaks.bf16 = gemmPeakGflops(device, torch::kBFloat16);
    std::printf("GEMM peak, 2048^3 matmul, %d threads: float32 %.0f GFLOP/s, bf16 %.0f GFLOP/s\n",
                b.o.threads, b.peaks.float32, b.peaks.bf16);
  }
  b.tmp = (fs::temp_directory_path() / ("bench_train_" + std::to_string(::getpid()))).string();
  prepareData(b);
  nlohmann::json rows = nlohmann::json::array();
  if (b.o.finetune) {
#if PAIRCAST_WITH_FINETUNE
    std::printf("batch %d, %s, %d torch threads, %dx%d crops, %d steps (%d left out)\n", b.o.batch,
                b.o.device.c_str(), b.o.threads, b.o.imgSize, b.o.imgSize, b.o.steps,
                b.o.warmupSteps);
    rows = finetuneRows(b.o, b.shards, b.tmp, b.peaks);
#else
    throw Error("this build has no finetune");
#endif
  } else {
    std::printf(
        "batch %d, %s %s, %d torch threads, %d workers, %dx%d crops, %d steps (%d left out)\n",
        b.o.batch, b.o.device.c_str(), b.precision.ran.c_str(), b.o.threads, b.o.workers,
        b.o.imgSize, b.o.imgSize, b.o.steps, b.o.warmupSteps);
    rows = pretrainRows(b);
  }
  fs::remove_all(b.tmp);
  printSummary(b, rows);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  // OpenBLAS's right kernels for both steps: the official one inherits OPENBLAS_CORETYPE.
  checkBlasCore("bench_train", argv);
  Bench b;
  CLI::App app{"Pre-training step speed, data included"};
  addOptions(app, b.o);
  CLI11_PARSE(app, argc, argv);
  try {
    return run(b);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_train: error: %s\n", e.what());
    return 1;
  }
}
