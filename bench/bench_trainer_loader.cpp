// bench_trainer_loader: the C++ pre-trainer's batch loader alone (PairDataset over shards, crops
// decoded straight from the JPEGs, CroCo's colour jitter, normalisation and masks), in pairs/s
// and pairs/s per worker thread. bench/bench_loader.py runs it beside the Python loaders; it
// prints one JSON line, with the minor page faults per pair in the steady state.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <nlohmann/json.hpp>

#include "trainer/batch_loader.h"
#include "trainer/pair_dataset.h"
#include "util/heap.h"
#include "util/timer.h"

using namespace paircast;

int main(int argc, char** argv) {
  std::vector<std::string> shards;
  int workers = 1, batch = 64, imgSize = 224, batches = 10;
  std::string format = "float32";
  CLI::App app{"pairs/s of the pre-trainer's batch loader alone"};
  app.add_option("--shards", shards, "Shards or glob patterns")->required();
  app.add_option("--workers", workers, "Loader threads")->check(CLI::Range(1, 256));
  app.add_option("--batch-size", batch, "Pairs per batch")->check(CLI::Range(1, 4096));
  app.add_option("--img-size", imgSize, "Crop side")->check(CLI::Range(16, 4096));
  app.add_option("--batches", batches, "Batches timed after the first")
      ->check(CLI::Range(1, 1 << 20));
  app.add_option("--batch-format", format, "float32 (normalised) or uint8 (crops and draws)")
      ->check(CLI::IsMember({"float32", "uint8"}));
  CLI11_PARSE(app, argc, argv);
  try {
    torch::set_num_threads(1);  // the loader's threads are the only parallelism measured
    const PairDataset ds = PairDataset::fromShards(shards);
    TrainConfig c;
    c.model = presetConfig("base");
    c.model.img_size = imgSize;
    c.batchSize = batch;
    c.workers = workers;
    c.batchFormat = format;
    c.epochs = 1 << 20;
    BatchLoader loader({{&ds, 1.0, "shards"}}, c, 0, 0, 1);
    for (int b = 0; b < 3; ++b) loader.get(b);  // the threads' start and the ring's first fill
    const long faults = minorPageFaults();
    const auto start = SteadyClock::now();
    for (int b = 3; b < 3 + batches; ++b) loader.get(b);
    const double seconds = secondsSince(start);
    const double faultsPerPair =
        static_cast<double>(minorPageFaults() - faults) / (batches * batch);
    const double rate = batches * batch / seconds;
    std::printf("%s\n", nlohmann::json({{"bench", "trainer_loader"},
                                        {"workers", workers},
                                        {"batch_format", format},
                                        {"pairs", batches * batch},
                                        {"seconds", seconds},
                                        {"pairs_per_second", rate},
                                        {"pairs_per_second_per_thread", rate / workers},
                                        {"minor_faults_per_pair", faultsPerPair}})
                            .dump()
                            .c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_trainer_loader: %s\n", e.what());
    return 1;
  }
  return 0;
}
