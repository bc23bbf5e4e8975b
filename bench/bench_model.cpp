// bench_model: forward and forward+backward time of CroCo (tiny, small, base) at batch 8 on
// CPU, with GFLOP/s, side by side with the official CroCoNet in python3-torch at the same
// configuration, batch and thread count (when --croco-dir names a checkout of naver/croco).
#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <nlohmann/json.hpp>

#include "model/autocast.h"
#include "model/croco_net.h"
#include "model/flops.h"
#include "util/blas_core.h"

using namespace paircast;
using Clock = std::chrono::steady_clock;

namespace {

// Wall-clock seconds, or with `cpuTime` this process's CPU seconds: with one thread, the latter
// leaves out the time other processes take the core, which a shared machine's wall clock counts.
double now(bool cpuTime) {
  if (!cpuTime) return std::chrono::duration<double>(Clock::now().time_since_epoch()).count();
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

template <typename F>
double best(F&& fn, int repeat, bool cpuTime) {
  fn();  // warm-up
  double b = 1e30;
  for (int r = 0; r < repeat; ++r) {
    const double t = now(cpuTime);
    fn();
    b = std::min(b, now(cpuTime) - t);
  }
  return b;
}

nlohmann::json pythonBench(const std::string& crocoDir, const std::string& preset, int batch,
                           int threads, int repeat, bool cpuTime) {
  if (crocoDir.empty()) return {};
  const std::string cmd = "/usr/bin/python3 " + std::string(PAIRCAST_SOURCE_DIR) +
                          "/tests/model/croco_ref.py bench --preset " + preset + " --batch " +
                          std::to_string(batch) + " --threads " + std::to_string(threads) +
                          " --repeat " + std::to_string(repeat) + (cpuTime ? " --cpu-time" : "") +
                          " --croco-dir '" + crocoDir + "' 2>/dev/null | grep ^SUMMARY";
  std::string line;
  if (FILE* p = popen(cmd.c_str(), "r")) {
    char buf[1024];
    while (fgets(buf, sizeof buf, p)) line += buf;
    pclose(p);
  }
  nlohmann::json out;
  for (const char* key : {"forward_s=", "train_s="}) {
    const size_t at = line.find(key);
    if (at != std::string::npos)
      out[std::string(key).substr(0, std::string(key).size() - 1)] =
          std::stod(line.substr(at + std::strlen(key)));
  }
  return out;
}

struct Options {
  std::vector<std::string> presets = {"tiny", "small", "base"};
  int batch = 8, threads = 2, repeat = 3, rounds = 2;
  std::string crocoDir, deviceName = "cpu";
  bool bf16 = false, cpuTime = false;
  double peakTflops = 800.0;
};

void addOptions(CLI::App& app, Options& o) {
  app.add_option("--device", o.deviceName, "cpu or cuda")->check(CLI::IsMember({"cpu", "cuda"}));
  app.add_flag("--bf16", o.bf16, "Autocast to bf16 (CPU or CUDA), with TF32 matmuls on CUDA");
  app.add_option("--peak-tflops", o.peakTflops,
                 "The device's dense bf16 peak, for the utilisation (H100: ~800)");
  app.add_option("--presets", o.presets, "Presets to time");
  app.add_option("--batch", o.batch, "Batch size");
  app.add_option("--threads", o.threads, "Intra-op threads (torch::set_num_threads)");
  app.add_option("--repeat", o.repeat, "Timed repetitions per round (best is kept)");
  app.add_option("--rounds", o.rounds, "Rounds, each timing the official model then ours")
      ->check(CLI::Range(1, 100));
  app.add_option("--croco-dir", o.crocoDir,
                 "A checkout of naver/croco, to time its CroCoNet alongside");
  app.add_flag("--cpu-time", o.cpuTime,
               "Time in process CPU seconds, not wall-clock (CPU, with --threads 1: a shared "
               "machine's other processes then drop out of the figures)");
}

// The official CroCoNet's best times beside ours (`fwd`, `train`), printed and added to `row`.
void addOfficial(const std::string& preset, const nlohmann::json& py, double fwd, double train,
                 nlohmann::json& row) {
  if (!py.contains("forward_s") || !py.contains("train_s")) {
    std::printf(
        "%-6s official comparison skipped (give --croco-dir DIR, a checkout of naver/croco)\n",
        preset.c_str());
    return;
  }
  const double pf = py["forward_s"], pt = py["train_s"];
  std::printf(
      "%-6s official CroCoNet (python3-torch): forward %7.3f s  forward+backward %7.3f s  -> "
      "ours %.2fx / %.2fx\n",
      preset.c_str(), pf, pt, pf / fwd, pt / train);
  row["official_forward_s"] = pf;
  row["official_train_s"] = pt;
  row["speedup_forward"] = pf / fwd;
  row["speedup_train"] = pt / train;
}

// Our forward and forward+backward on `preset` at 224 x 224, beside the official model's.
nlohmann::json timePreset(const Options& o, const torch::Device& device,
                          const std::string& preset) {
  const bool cuda = device.is_cuda();
  auto sync = [&] {
    if (cuda) torch::cuda::synchronize();
  };
  torch::manual_seed(0);
  CroCoConfig cfg = presetConfig(preset);
  CroCoNet net(cfg);
  net->to(device);
  auto img1 = torch::randn({o.batch, 3, 224, 224}, device);
  auto img2 = torch::randn({o.batch, 3, 224, 224}, device);
  auto forward = [&] {
    torch::NoGradGuard ng;
    AutocastGuard ac(device.type(), o.bf16);
    net->forward(img1, img2);
    sync();
  };
  auto trainStep = [&] {
    torch::Tensor loss;
    {
      AutocastGuard ac(device.type(), o.bf16);
      auto out = net->forward(img1, img2);
      loss = maskedMse(out.prediction.to(torch::kFloat32), out.mask, out.target);
    }
    net->zero_grad();
    loss.backward();
    sync();
  };
  // Rounds alternate the official model and ours, and each side keeps its best over all of
  // them: both get as many samples, and a busy spell of the machine hits both alike.
  double fwd = 1e30, train = 1e30;
  nlohmann::json py = nlohmann::json::object();
  for (int round = 0; round < o.rounds; ++round) {
    const nlohmann::json p =
        pythonBench(o.crocoDir, preset, o.batch, o.threads, o.repeat, o.cpuTime);
    for (const char* k : {"forward_s", "train_s"})
      if (p.contains(k)) py[k] = std::min(py.value(k, 1e30), p[k].get<double>());
    fwd = std::min(fwd, best(forward, o.repeat, o.cpuTime));
    train = std::min(train, best(trainStep, o.repeat, o.cpuTime));
  }
  const double flops = countFlops(cfg).flops_full * o.batch;
  std::printf(
      "%-6s ours:   forward %7.3f s (%6.1f GFLOP/s)  forward+backward %7.3f s (%6.1f GFLOP/s, 3x "
      "forward FLOPs)\n",
      preset.c_str(), fwd, flops / fwd / 1e9, train, 3 * flops / train / 1e9);
  nlohmann::json row = {{"preset", preset},
                        {"forward_s", fwd},
                        {"train_s", train},
                        {"gflops_forward", flops / fwd / 1e9},
                        {"gflops_train", 3 * flops / train / 1e9},
                        {"pairs_per_s_train", o.batch / train}};
  if (cuda) {
    // Model FLOP utilisation of the train step, with the paper's FLOP convention (weight layers).
    const double mfu = 3 * countFlops(cfg).flops * o.batch / train / (o.peakTflops * 1e12);
    std::printf("%-6s train step: %.1f pairs/s, model FLOP utilisation %.1f%% of %.0f TFLOP/s\n",
                preset.c_str(), o.batch / train, 100 * mfu, o.peakTflops);
    row["mfu"] = mfu;
  }
  addOfficial(preset, py, fwd, train, row);
  return row;
}

}  // namespace

int main(int argc, char** argv) {
  paircast::checkBlasCore("bench_model", argv);  // OpenBLAS's right kernels (util/blas_core.h)
  Options o;
  CLI::App app{"CroCo forward / forward+backward speed"};
  addOptions(app, o);
  CLI11_PARSE(app, argc, argv);
  if (o.cpuTime && (o.deviceName != "cpu" || o.threads != 1)) {
    std::fprintf(stderr, "bench_model: --cpu-time needs --device cpu --threads 1\n");
    return 2;
  }
  torch::set_num_threads(o.threads);
  const bool cuda = o.deviceName == "cuda";
  if (cuda && !torch::cuda::is_available()) {
    std::fprintf(stderr, "bench_model: no CUDA device\n");
    return 1;
  }
  const torch::Device device = cuda ? torch::Device(torch::kCUDA) : torch::Device(torch::kCPU);
  if (cuda) allowTf32();
  std::printf("batch %d, %d threads, 224x224, 90%% masking, %s%s%s\n", o.batch, o.threads,
              cuda ? "CUDA" : "CPU", o.bf16 ? ", bf16 autocast" : "",
              o.cpuTime ? ", process CPU seconds" : "");
  nlohmann::json rows = nlohmann::json::array();
  for (const auto& preset : o.presets) rows.push_back(timePreset(o, device, preset));
  std::printf("%s\n", nlohmann::json({{"batch", o.batch},
                                      {"threads", o.threads},
                                      {"rounds", o.rounds},
                                      {"cpu_time", o.cpuTime},
                                      {"results", rows}})
                          .dump()
                          .c_str());
  return 0;
}
