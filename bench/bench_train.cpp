// bench_train: pairs/s of the whole pre-training step (data included) for tiny and small at
// batch 16 on CPU, from shards and with pairs rendered live, side by side with the official
// CroCo train step in python3-torch (model only) when --croco-dir names a checkout of naver/croco.
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "dataset/generate_job.h"
#include "trainer/trainer.h"

using namespace paircast;
namespace fs = std::filesystem;

namespace {

double officialTrainSeconds(const std::string& crocoDir, const std::string& preset, int batch,
                            int threads) {
  if (crocoDir.empty()) return 0;
  const std::string cmd = "/usr/bin/python3 " + std::string(PAIRCAST_SOURCE_DIR) +
                          "/tests/model/croco_ref.py bench --preset " + preset + " --batch " +
                          std::to_string(batch) + " --threads " + std::to_string(threads) +
                          " --repeat 3 --croco-dir '" + crocoDir + "' 2>/dev/null | grep ^SUMMARY";
  std::string line;
  if (FILE* p = popen(cmd.c_str(), "r")) {
    char buf[1024];
    while (fgets(buf, sizeof buf, p)) line += buf;
    pclose(p);
  }
  const size_t at = line.find("train_s=");
  return at == std::string::npos ? 0 : std::stod(line.substr(at + 8));
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> presets = {"tiny", "small"};
  int batch = 16, steps = 12, threads = 2;
  std::string crocoDir;
  bool live = true;
  CLI::App app{"Pre-training step speed, data included"};
  app.add_option("--presets", presets, "Presets");
  app.add_option("--batch", batch, "Batch size");
  app.add_option("--steps", steps, "Timed iterations per run");
  app.add_option("--threads", threads, "Torch threads");
  app.add_option("--croco-dir", crocoDir,
                 "A checkout of naver/croco, to time its train step alongside");
  app.add_flag("!--no-live", live, "Skip the live-rendering runs");
  CLI11_PARSE(app, argc, argv);
  try {
    torch::set_num_threads(threads);
    const std::string tmp =
        (fs::temp_directory_path() / ("bench_train_" + std::to_string(::getpid()))).string();
    GenerateConfig g;
    g.scenes = {std::string(PAIRCAST_SOURCE_DIR) + "/scenes"};
    g.out = tmp + "/pairs";
    g.pairsPerScene = (batch * (steps + 2)) / 3 + 8;
    g.pair.resolution = 256;
    g.progress = false;
    runGenerate(g);
    nlohmann::json rows = nlohmann::json::array();
    std::printf("batch %d, %d torch threads, 224x224 crops of 256x256 pairs, %d steps\n", batch,
                threads, steps);
    for (const auto& preset : presets) {
      for (const bool isLive : {false, true}) {
        if (isLive && !live) continue;
        TrainConfig c;
        if (isLive)
          c.live = {std::string(PAIRCAST_SOURCE_DIR) + "/scenes"};
        else
          c.shards = {tmp + "/pairs/pairs-*.tar"};
        c.model = presetConfig(preset);
        c.batchSize = batch;
        c.maxSteps = steps;
        c.epochs = 100;
        c.saveEvery = 1000000;
        c.out = tmp + "/run-" + preset + (isLive ? "-live" : "-shards");
        c.workers = 2;
        c.progress = false;
        const nlohmann::json s = runPretrain(c);
        const double pps = s["pairs_per_s"], wait = s["data_wait"];
        std::printf("%-6s %-7s %6.2f pairs/s  data-wait %5.1f%%\n", preset.c_str(),
                    isLive ? "live" : "shards", pps, 100 * wait);
        nlohmann::json row = {{"preset", preset},
                              {"source", isLive ? "live" : "shards"},
                              {"pairs_per_s", pps},
                              {"data_wait", wait}};
        if (!isLive) {
          const double off = officialTrainSeconds(crocoDir, preset, batch, threads);
          if (off > 0) {
            std::printf(
                "%-6s official CroCo train step (model only, python3-torch): %6.2f pairs/s -> ours "
                "%.2fx\n",
                preset.c_str(), batch / off, pps / (batch / off));
            row["official_pairs_per_s"] = batch / off;
            row["ratio"] = pps / (batch / off);
          }
        }
        rows.push_back(row);
      }
    }
    fs::remove_all(tmp);
    std::printf(
        "%s\n",
        nlohmann::json({{"batch", batch}, {"threads", threads}, {"results", rows}}).dump().c_str());
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_train: error: %s\n", e.what());
    return 1;
  }
}
