#include "sweep/covis_sweep.h"

#include <gtest/gtest.h>
#include <omp.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <regex>
#include <set>
#include <sstream>
#include <tuple>

#include "model/checkpoint.h"
#include "shard/shard_index.h"
#include "sweep/depth_probe.h"
#include "sweep/sweep_downstream.h"
#include "sweep/sweep_merge.h"
#include "sweep/sweep_report.h"
#include "sweep/sweep_stats.h"
#include "test_checkpoints.h"
#include "test_errors.h"
#include "test_paths.h"
#include "test_process.h"
#include "util/atomic_file.h"
#include "util/error.h"
#include "util/plot.h"
#include "util/work_claims.h"

namespace paircast {
namespace {

namespace fs = std::filesystem;

TEST(CovisSweep, BucketsAndSets) {
  EXPECT_EQ(covisBucket(0.0), 0);
  EXPECT_EQ(covisBucket(0.0499), 0);
  EXPECT_EQ(covisBucket(0.05), 1);
  EXPECT_EQ(covisBucket(0.5), 10);
  EXPECT_EQ(covisBucket(0.97), 19);
  EXPECT_EQ(covisBucket(1.0), 19);
  EXPECT_EQ(makeSweepSet("bin", 0.45).buckets, (std::vector<int>{8, 9}));    // [0.40, 0.50)
  EXPECT_EQ(makeSweepSet("bin", 0.95).buckets, (std::vector<int>{18, 19}));  // [0.90, 1.00]
  EXPECT_EQ(makeSweepSet("uniform", 0.75).buckets, (std::vector<int>{15, 16, 17, 18, 19}));
  EXPECT_EQ(makeSweepSet("uniform", 0.0).buckets.size(), 20u);
  EXPECT_EQ(makeSweepSet("bin", 0.15).name, "bin_0.15");
  EXPECT_EQ(makeSweepSet("bin", 0.5).buckets, (std::vector<int>{9, 10}));  // [0.45, 0.55)
  EXPECT_ERROR_CONTAINS(makeSweepSet("bin", 0.47),
                        "bin centre 0.47 must be a multiple of 0.05");  // off the 0.05 grid
  EXPECT_ERROR_CONTAINS(makeSweepSet("bin", 1.05), "bin centre 1.05 must be a multiple of 0.05");
  EXPECT_ERROR_CONTAINS(makeSweepSet("uniform", 0.33),
                        "uniform centre 0.33 must be a multiple of 0.05");
  EXPECT_ERROR_CONTAINS(makeSweepSet("spread", 0.5), "unknown sweep mode 'spread'");
}

TEST(CovisSweep, SetsByName) {
  EXPECT_EQ(parseSweepSet("uniform_0.50").buckets, makeSweepSet("uniform", 0.5).buckets);
  EXPECT_EQ(parseSweepSet("bin_0.55").name, "bin_0.55");
  for (const char* bad : {"bin", "bin_", "bin_0.5x", "_0.5"})
    EXPECT_ERROR_CONTAINS(parseSweepSet(bad), "is not <mode>_<centre>") << bad;
  EXPECT_ERROR_CONTAINS(parseSweepSet("bin_0.47"), "bin centre 0.47 must be a multiple of 0.05");
  SweepConfig c;
  c.sets = {"bin_0.15", "uniform_0.50"};
  const std::vector<SweepSet> sets = planSets(c);  // instead of every mode at every centre
  ASSERT_EQ(sets.size(), 2u);
  EXPECT_EQ(sets[1].name, "uniform_0.50");
  EXPECT_EQ(referenceSet(sets), "bin_0.15");
}

TEST(CovisSweep, SetsAreEqualInSizeAndEachPairIsInItsRange) {
  std::vector<SweepSet> sets;
  for (const char* mode : {"bin", "uniform"})
    for (double c : {0.05, 0.25, 0.45, 0.95}) sets.push_back(makeSweepSet(mode, c));
  const int n = 30;
  const std::vector<int> demand = bucketDemand(sets, n);
  // A pool that holds exactly the demand, in a scrambled order.
  std::vector<double> pool;
  for (int b = 0; b < kCovisBuckets; ++b)
    for (int i = 0; i < demand[b]; ++i)
      pool.push_back((b + (i * 0.37 - std::floor(i * 0.37))) / 20.0);
  std::vector<double> scrambled;
  for (size_t i = 0; i < pool.size(); ++i) scrambled.push_back(pool[(i * 7919) % pool.size()]);
  const auto drawn = drawSets(scrambled, sets, n);
  ASSERT_EQ(drawn.size(), sets.size());
  for (size_t s = 0; s < sets.size(); ++s) {
    EXPECT_EQ(drawn[s].size(), static_cast<size_t>(n)) << sets[s].name;
    std::vector<int> perBucket(kCovisBuckets, 0);
    for (size_t i : drawn[s]) {
      const double v = scrambled[i];
      if (sets[s].mode == "bin") {
        EXPECT_GE(v, sets[s].center - 0.05 - 1e-12) << sets[s].name;
        EXPECT_LT(v, sets[s].center + 0.05) << sets[s].name;
      } else {
        EXPECT_GE(v, sets[s].center - 1e-12) << sets[s].name;
      }
      perBucket[covisBucket(v)]++;
    }
    // Uniform sets are spread evenly: bucket counts differ by at most one.
    int lo = n, hi = 0;
    for (int b : sets[s].buckets) lo = std::min(lo, perBucket[b]), hi = std::max(hi, perBucket[b]);
    EXPECT_LE(hi - lo, 1) << sets[s].name;
  }
  // One pair short in a bucket: the error names it.
  scrambled.erase(std::find_if(scrambled.begin(), scrambled.end(),
                               [](double v) { return covisBucket(v) == 19; }));
  try {
    drawSets(scrambled, sets, n);
    ADD_FAILURE() << "a short bucket was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("[0.95, 1.00)"), std::string::npos) << e.what();
  }
}

TEST(DepthMetrics, HandComputedCases) {
  const auto gt = torch::tensor({1.0, 2.0, 4.0, 0.0}, torch::kFloat64);
  const auto pred =
      torch::tensor({1.0, 2.6, 3.0, 5.0}, torch::kFloat64);  // the last pixel has no depth
  const DepthMetrics m = depthMetrics(pred, gt);
  EXPECT_EQ(m.pixels, 3);
  EXPECT_NEAR(m.delta1, 1.0 / 3, 1e-12);  // ratios 1, 1.3, 1.333
  EXPECT_NEAR(m.absRel, (0 + 0.3 + 0.25) / 3, 1e-9);
  EXPECT_NEAR(m.rmse, std::sqrt((0 + 0.36 + 1.0) / 3), 1e-9);
  const DepthMetrics perfect = depthMetrics(gt, gt);
  EXPECT_EQ(perfect.delta1, 1.0);
  EXPECT_EQ(perfect.absRel, 0.0);
  EXPECT_ERROR_CONTAINS(depthMetrics(torch::ones({2}), torch::zeros({2})),
                        "no valid ground-truth pixel");
  EXPECT_ERROR_CONTAINS(depthMetrics(torch::ones({2}), torch::ones({3})),
                        "prediction and ground truth differ in shape");
}

TEST(DepthProbe, FitsDepthThatIsLinearInTheFeatures) {
  // A "model" whose encoder is the patch embedding alone cannot be built here; instead check the
  // probe's ridge fit through a tiny CroCo model on images whose depth is a function of colour.
  CroCoConfig c = presetConfig("tiny");
  c.img_size = 32;
  c.patch_size = 8;
  torch::manual_seed(0);
  CroCoNet model(c);
  torch::manual_seed(1);
  // Each image is one flat random colour; its depth is a function of that colour.
  const auto colour = torch::rand({40, 3, 1, 1});
  const auto images = colour.expand({40, 3, 32, 32}).contiguous();
  const auto depth = (1.0 + 3.0 * colour.select(1, 0)).expand({40, 32, 32}).contiguous();
  ProbeData train{images.slice(0, 0, 30), depth.slice(0, 0, 30)};
  ProbeData test{images.slice(0, 30), depth.slice(0, 30)};
  const DepthProbe probe(model, train);
  const DepthMetrics m = probe.evaluate(test);
  EXPECT_GT(m.delta1, 0.9) << m.toJson().dump();
  // Against predicting the mean depth everywhere, the probe is far better.
  const auto mean = torch::full_like(test.depth, train.depth.mean().item<double>());
  EXPECT_LT(m.absRel, 0.5 * depthMetrics(mean, test.depth).absRel);

  // Cross-fitting tests every view once: its metrics are over both halves' pixels, and equal
  // the two one-way fits' predictions scored together.
  const DepthMetrics both = crossFitProbe(model, train, test);
  EXPECT_EQ(both.pixels, 40 * 32 * 32);
  const auto pooled = depthMetrics(
      torch::cat({probe.predict(test.images), DepthProbe(model, test).predict(train.images)}),
      torch::cat({test.depth, train.depth}));
  EXPECT_DOUBLE_EQ(both.absRel, pooled.absRel);
  EXPECT_DOUBLE_EQ(both.delta1, pooled.delta1);
  EXPECT_GT(both.delta1, 0.9) << both.toJson().dump();
}

SweepConfig miniSweep(const std::string& out) {
  SweepConfig c;
  // Two held-out scenes, so that every pair has a reference from another scene.
  c.scenes = {testing::sourceDir() + "/scenes/room"};
  c.heldout = {testing::sourceDir() + "/scenes/studio", testing::sourceDir() + "/scenes/apartment"};
  c.out = out;
  c.centers = {0.45, 0.75};
  c.pairsPerSet = 16;
  c.batchSize = 8;
  c.steps = 4;
  c.imgSize = 32;
  c.patchSize = 8;
  c.resolution = 64;
  c.evalPairs = 8;
  c.probeViews = 8;
  c.mechanismPairs = 4;
  c.jobs = 2;
  c.workers = 1;
  c.progress = false;  // --amp auto, the default: bf16 where the CPU has bf16 units
  return c;
}

TEST(CovisSweep, HeldOutScenesMustNotBeTrainedOn) {
  SweepConfig c = miniSweep(testing::scratchDir("overlap"));
  c.heldout = {testing::sourceDir() + "/scenes/room/room.obj"};
  EXPECT_ERROR_CONTAINS(runCovisSweep(c),
                        c.heldout[0] + ": is both a training and a held-out scene");
  c.heldout = {};
  EXPECT_ERROR_CONTAINS(runCovisSweep(c), "give at least one held-out scene");
}

std::string covisSweepTool() {
  return std::string(PAIRCAST_BINARY_DIR) + "/tools/covis_sweep";
}

std::vector<std::string> miniArgs(const std::string& out) {
  const std::string s = testing::sourceDir();
  return {covisSweepTool(),
          "--scenes",
          s + "/scenes/room",
          "--heldout",
          s + "/scenes/studio",
          s + "/scenes/apartment",
          "--out",
          out,
          "--centers",
          "0.45,0.75",
          "--pairs-per-set",
          "16",
          "--batch-size",
          "8",
          "--steps",
          "4",
          "--img-size",
          "32",
          "--patch-size",
          "8",
          "--resolution",
          "64",
          "--eval-pairs",
          "8",
          "--probe-views",
          "8",
          "--mechanism-pairs",
          "4",
          "--jobs",
          "2",
          "--quiet"};  // --amp auto, as miniSweep
}

// `args` with `option` set to `value`: replaced where it is given, appended where it is not.
std::vector<std::string> withOption(std::vector<std::string> args, const std::string& option,
                                    const std::string& value) {
  const auto it = std::find(args.begin(), args.end(), option);
  if (it != args.end())
    *(it + 1) = value;
  else
    args.insert(args.end(), {option, value});
  return args;
}

TEST(CovisSweep, TwoRanksTrainEachSetLikeOneWithTheDoubledBatch) {
  const std::string dir = testing::scratchDir("ranks");
  // A small rate, as in Pretrain.TwoGlooProcessesEqualOneWithTheDoubledBatch: Adam scales every
  // step to about lr, so the two reduction orders' rounding differences grow with it.
  // Two seeds and mae: every rank must train the same runs in the same order.
  auto args = [&](const std::string& out, const char* batch) {
    auto a = withOption(miniArgs(out), "--batch-size", batch);
    // float32: the tolerances below are float32's rounding; bf16's are wider by a hundred.
    a.insert(a.end(), {"--blr", "1.5e-4", "--mode", "bin", "--seeds", "2", "--baseline", "mae",
                       "--amp", "none"});
    return a;
  };
  ASSERT_EQ(testing::runProcess(args(dir + "/one", "8")), 0);
  // Two processes over loopback; rank 1 waits for rank 0's pool and sets, then trains with it.
  const std::string port = "MASTER_PORT=" + std::to_string(20000 + (getpid() + 7) % 20000);
  std::vector<pid_t> ranks;
  for (int r = 1; r >= 0; --r)  // rank 1 first: it must wait
    ranks.push_back(testing::spawnProcess(
        args(dir + "/two", "4"),
        {"WORLD_SIZE=2", "RANK=" + std::to_string(r), "LOCAL_RANK=" + std::to_string(r),
         "MASTER_ADDR=127.0.0.1", port, "PAIRCAST_SWEEP_WAIT=300"}));
  for (pid_t p : ranks) ASSERT_EQ(testing::waitProcess(p), 0);
  const auto one = nlohmann::json::parse(readFile(dir + "/one/results.json"));
  const auto two = nlohmann::json::parse(readFile(dir + "/two/results.json"));
  ASSERT_EQ(one["runs"].size(), 6u);  // 2 bins and mae, 2 seeds each
  ASSERT_EQ(two["runs"].size(), one["runs"].size());
  for (size_t i = 0; i < one["runs"].size(); ++i) {
    const std::string run = one["runs"][i]["set"].get<std::string>() + "/seed-" +
                            std::to_string(one["runs"][i]["seed_index"].get<int>());
    EXPECT_LT(testing::weightDifference(dir + "/one/runs/" + run + "/checkpoint-last.pth",
                                        dir + "/two/runs/" + run + "/checkpoint-last.pth"),
              1e-5)
        << run;
    EXPECT_NEAR(one["runs"][i]["xv_loss"].get<double>(), two["runs"][i]["xv_loss"].get<double>(),
                1e-4)
        << run;
  }
  // A rank that never sees rank 0 gives up after PAIRCAST_SWEEP_WAIT instead of hanging.
  const auto start = std::chrono::steady_clock::now();
  EXPECT_EQ(testing::runProcess(miniArgs(dir + "/alone"), -1,
                                {"WORLD_SIZE=2", "RANK=1", "PAIRCAST_SWEEP_WAIT=1"}),
            1);
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(30));
}

// The sweep of the end-to-end test: two seeds, and the mae baseline.
SweepConfig seededSweep(const std::string& out) {
  SweepConfig c = miniSweep(out);
  c.seeds = 2;
  c.baselines = {"mae"};
  return c;
}

std::vector<std::string> seededArgs(const std::string& out) {
  std::vector<std::string> a = miniArgs(out);
  a.insert(a.end(), {"--seeds", "2", "--baseline", "mae"});
  return a;
}

std::string runDir(const std::string& out, const std::string& set, int seed) {
  return out + "/runs/" + set + "/seed-" + std::to_string(seed);
}

// A CSV file's rows, each as column name -> cell.
std::vector<std::map<std::string, std::string>> readCsvRows(const std::string& path) {
  auto cells = [](const std::string& line) {
    std::vector<std::string> out;
    std::stringstream in(line);
    for (std::string cell; std::getline(in, cell, ',');) out.push_back(cell);
    if (!line.empty() && line.back() == ',') out.emplace_back();
    return out;
  };
  std::stringstream in(readFile(path));
  std::string line;
  std::getline(in, line);
  const std::vector<std::string> header = cells(line);
  std::vector<std::map<std::string, std::string>> rows;
  while (std::getline(in, line)) {
    const std::vector<std::string> row = cells(line);
    EXPECT_EQ(row.size(), header.size()) << line;
    std::map<std::string, std::string> named;
    for (size_t i = 0; i < row.size() && i < header.size(); ++i) named[header[i]] = row[i];
    rows.push_back(std::move(named));
  }
  return rows;
}

// A metric's figures of each set (and of the random encoder) are the mean and 95 % interval of
// its runs' values, in results.json and in results.csv, where they agree with results_runs.csv's
// per-run values to the 6 digits written. Every value lies in [lo, hi].
void expectSetsAggregateTheirRuns(const nlohmann::json& r, const std::string& out,
                                  const std::string& metric, double lo, double hi) {
  std::map<std::string, std::vector<double>> jsonRuns, csvRuns;
  for (const char* list : {"runs", "random_runs"})
    for (const auto& run : r[list]) {
      const double v = numberOrNan(run, metric);
      if (std::isfinite(v)) {
        EXPECT_GE(v, lo) << run["set"];
        EXPECT_LE(v, hi) << run["set"];
      }
      jsonRuns[run["set"].get<std::string>()].push_back(v);
    }
  for (const auto& row : readCsvRows(out + "/results_runs.csv"))
    csvRuns[row.at("set")].push_back(std::stod(row.at(metric)));  // "nan" reads as NaN
  EXPECT_EQ(csvRuns.size(), jsonRuns.size());
  std::vector<nlohmann::json> rows(r["rows"].begin(), r["rows"].end());
  rows.push_back(r["random_encoder"]);
  std::map<std::string, std::map<std::string, std::string>> csvRows;
  for (const auto& row : readCsvRows(out + "/results.csv")) csvRows[row.at("set")] = row;
  for (const auto& row : rows) {
    const std::string set = row["set"];
    SCOPED_TRACE(set + " " + metric);
    ASSERT_TRUE(jsonRuns.count(set) && csvRuns.count(set) && csvRows.count(set));
    const Interval want = interval95(jsonRuns[set]);
    EXPECT_EQ(row["seeds"], jsonRuns[set].size());
    const double mean = numberOrNan(row, metric + "_mean");
    if (std::isnan(want.mean)) {
      EXPECT_TRUE(std::isnan(mean));
      continue;
    }
    EXPECT_NEAR(mean, want.mean, 1e-12);
    const double ci = numberOrNan(row, metric + "_ci95");
    if (std::isnan(want.halfWidth))
      EXPECT_TRUE(std::isnan(ci));
    else
      EXPECT_NEAR(ci, want.halfWidth, 1e-12);
    const double csvMean = std::stod(csvRows[set].at(metric + "_mean"));
    const double runsMean = interval95(csvRuns[set]).mean;
    EXPECT_NEAR(csvMean, runsMean, 1e-5 * std::max(1.0, std::abs(runsMean)));
    EXPECT_NEAR(csvMean, want.mean, 1e-5 * std::max(1.0, std::abs(want.mean)));
    EXPECT_GE(mean, lo);
    EXPECT_LE(mean, hi);
  }
}

// Every run's checkpoint and when it was written.
std::map<std::string, fs::file_time_type> checkpointTimes(const std::string& out) {
  std::map<std::string, fs::file_time_type> times;
  for (const auto& e : fs::recursive_directory_iterator(out + "/runs"))
    if (e.path().filename() == "checkpoint-last.pth")
      times[e.path().string()] = fs::last_write_time(e.path());
  return times;
}

// `after` holds `before`'s checkpoints, unchanged but for `redone`'s, which was written again.
void expectOnlyRedone(std::map<std::string, fs::file_time_type> after,
                      std::map<std::string, fs::file_time_type> before, const std::string& redone) {
  ASSERT_TRUE(after.count(redone)) << redone;
  after.erase(redone);
  before.erase(redone);
  EXPECT_EQ(after, before);
}

// A finished sweep run again reuses everything; with one seed's run gone, only that run trains
// again, to the same results.
void expectResumesRunByRun(const std::string& out) {
  const std::string csv = readFile(out + "/results.csv");
  const auto before = checkpointTimes(out);
  ASSERT_EQ(before.size(), 10u);
  // A rerun reuses everything: no checkpoint is rewritten.
  runCovisSweep(seededSweep(out));
  EXPECT_EQ(checkpointTimes(out), before);
  EXPECT_EQ(readFile(out + "/results.csv"), csv);
  // With one seed's run gone, only that run trains again, to the same result.
  const std::string gone = runDir(out, "uniform_0.75", 1);
  fs::remove_all(gone);
  runCovisSweep(seededSweep(out));
  const auto after = checkpointTimes(out);
  ASSERT_EQ(after.size(), 10u);
  expectOnlyRedone(after, before, gone + "/checkpoint-last.pth");
  EXPECT_EQ(readFile(out + "/results.csv"), csv);
}

// The real command, SIGKILLed at growing delays and restarted, gives `clean`'s results.
void expectKilledSweepEndsAsThisDid(const std::string& clean) {
  const std::string killed = clean + "-killed";
  fs::remove_all(killed);  // a previous run's
  int kills = 0;
  for (int delayMs = 300; delayMs < 60000 && !fs::exists(killed + "/results.csv"); delayMs *= 2) {
    const int rc = testing::runProcess(seededArgs(killed), delayMs);
    if (rc == -SIGKILL) ++kills;
  }
  EXPECT_GE(kills, 1);
  ASSERT_EQ(testing::runProcess(seededArgs(killed)), 0);
  EXPECT_EQ(readFile(killed + "/results.csv"), readFile(clean + "/results.csv"));
  EXPECT_EQ(readFile(killed + "/results_runs.csv"), readFile(clean + "/results_runs.csv"));
}

// Also: it resumes run by run, and after kills (the two functions above).
TEST(CovisSweep, SeedsAndMaeEndToEnd) {
  const std::string clean = testing::scratchDir("e2e");
  // Through the library: 4 sets and mae, each with 2 seeds.
  const nlohmann::json r = runCovisSweep(seededSweep(clean));
  ASSERT_EQ(r["rows"].size(), 5u);
  ASSERT_EQ(r["runs"].size(), 10u);
  for (const auto& row : r["rows"]) {
    EXPECT_EQ(row["pairs"], 16);
    EXPECT_EQ(row["seeds"], 2);
    EXPECT_TRUE(std::isfinite(row["xv_loss_mean"].get<double>()));
    EXPECT_TRUE(std::isfinite(row["xv_loss_ci95"].get<double>()));
    EXPECT_GE(row["probe_delta1_mean"].get<double>(), 0.0);
  }
  // mae trains on the pairs of the reference set (the bin set nearest 0.5), on its own task.
  EXPECT_EQ(r["reference_set"], "bin_0.45");
  EXPECT_EQ(r["rows"][4]["set"], "mae");
  EXPECT_EQ(r["rows"][4]["task"], "mae");
  EXPECT_EQ(r["rows"][4]["trained_on"], "bin_0.45");
  EXPECT_EQ(nlohmann::json::parse(readFile(runDir(clean, "mae", 1) + "/summary.json"))["task"],
            "mae");
  const std::string csv = readFile(clean + "/results.csv");
  EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 7);  // header, 4 sets, mae, random
  EXPECT_EQ(csv.substr(0, csv.find('\n')),
            "mode,center,set,task,trained_on,seeds,pairs,mean_covis,train_loss_mean,"
            "train_loss_ci95,xv_loss_mean,xv_loss_ci95,probe_delta1_mean,probe_delta1_ci95,"
            "probe_absrel_mean,probe_absrel_ci95,probe_rmse_mean,probe_rmse_ci95,ref_gain_mean,"
            "ref_gain_ci95,ref_gain_covisible_mean,ref_gain_covisible_ci95,ref_gain_hidden_mean,"
            "ref_gain_hidden_ci95,xattn_pck1_mean,xattn_pck1_ci95,xattn_epe_mean,xattn_epe_ci95,"
            "enc_pck1_mean,enc_pck1_ci95,ft_flow_aepe_mean,ft_flow_aepe_ci95,"
            "ft_flow_aepe_covisible_mean,ft_flow_aepe_covisible_ci95,ft_flow_px3_mean,"
            "ft_flow_px3_ci95,ft_flow_aepe_all_mean,ft_flow_aepe_all_ci95,ft_depth_delta1_mean,"
            "ft_depth_delta1_ci95,ft_depth_absrel_mean,ft_depth_absrel_ci95");
  // The mechanism probes: every cross-view run and random encoder has them, mae only enc_pck1.
  for (const auto& row : r["rows"]) {
    const bool mae = row["task"] == "mae";
    EXPECT_EQ(std::isnan(numberOrNan(row, "ref_gain_mean")), mae) << row["set"];
    EXPECT_EQ(std::isnan(numberOrNan(row, "xattn_pck1_mean")), mae) << row["set"];
    EXPECT_TRUE(std::isfinite(numberOrNan(row, "enc_pck1_mean"))) << row["set"];
  }
  expectSetsAggregateTheirRuns(r, clean, "enc_pck1", 0.0, 1.0);
  expectSetsAggregateTheirRuns(r, clean, "xattn_pck1", 0.0, 1.0);
  EXPECT_EQ(r["config"]["mechanism_pairs"], 8);  // 4 from each held-out scene
  const std::string byCovis = readFile(clean + "/probe_by_covis.csv");
  EXPECT_EQ(byCovis.substr(0, byCovis.find('\n')),
            "set,task,covis_lo,covis_hi,pairs,seeds,xattn_pck1_mean,xattn_pck1_ci95,"
            "xattn_epe_mean,xattn_epe_ci95,enc_pck1_mean,enc_pck1_ci95");
  EXPECT_NE(byCovis.find("\nrandom_encoder,croco,"), std::string::npos) << byCovis;
  const std::string runsCsv = readFile(clean + "/results_runs.csv");
  EXPECT_EQ(std::count(runsCsv.begin(), runsCsv.end(), '\n'), 13);  // header, 10 runs, 2 random
  for (const char* f :
       {"results.json", "plot_xv_loss.svg", "plot_probe_delta1.svg", "plot_xattn_pck1.svg",
        "plot_probe_by_covis.svg", "plot_probe_absrel.svg", "plot_probe_rmse.svg", "summary.html",
        "sets/bin_0.45/report.html", "sets/uniform_0.75.keys"})
    EXPECT_TRUE(fs::exists(clean + "/" + f)) << f;
  const std::string html = readFile(clean + "/summary.html");
  EXPECT_NE(html.find("Claim 2, cross-view completion beats auto-completion (MAE)"),
            std::string::npos);
  const std::regex ref("(src|href)='([^']+)'");
  for (auto it = std::sregex_iterator(html.begin(), html.end(), ref); it != std::sregex_iterator();
       ++it)
    EXPECT_TRUE(fs::exists(clean + "/" + (*it)[2].str())) << (*it)[2].str();

  // The seed changes the initialisation (the random encoders differ), and so every run.
  const auto& random = r["random_runs"];
  EXPECT_NE(random[0]["xv_loss"], random[1]["xv_loss"]);
  const Checkpoint s0 = loadCheckpoint(runDir(clean, "bin_0.45", 0) + "/checkpoint-last.pth");
  const Checkpoint s1 = loadCheckpoint(runDir(clean, "bin_0.45", 1) + "/checkpoint-last.pth");
  EXPECT_FALSE(torch::equal(s0.model.at("enc_blocks.0.attn.qkv.weight"),
                            s1.model.at("enc_blocks.0.attn.qkv.weight")));
  EXPECT_EQ(s0.extra["seed"], 0);
  EXPECT_EQ(s1.extra["seed"], 1);
  EXPECT_EQ(r["runs"][5]["set"], "bin_0.45");
  EXPECT_NE(r["runs"][0]["train_loss"], r["runs"][5]["train_loss"]);  // its seeds 0 and 1
  expectResumesRunByRun(clean);
  expectKilledSweepEndsAsThisDid(clean);
}

// The sweep of the worker tests: two bins and mae, flow fine-tunes; 3 runs and 4 fine-tunes.
std::vector<std::string> workersArgs(const std::string& out) {
  auto a = miniArgs(out);
  // float32, so that equal arithmetic gives equal bytes however the processes interleave.
  a.insert(a.end(), {"--sets", "bin_0.45,bin_0.75", "--baseline", "mae", "--no-reports",
                     "--downstream", "flow", "--finetune-steps", "4", "--finetune-pairs", "16",
                     "--finetune-eval-pairs", "24", "--amp", "none"});
  return a;
}

// The processes whose PAIRCAST_WORKER_PARENT is `lead`.
int workersOf(pid_t lead) {
  const std::string mark = std::string("PAIRCAST_WORKER_PARENT=") + std::to_string(lead);
  int n = 0;
  for (const auto& e : fs::directory_iterator("/proc")) {
    std::ifstream in(e.path() / "environ", std::ios::binary);
    std::string var;
    while (std::getline(in, var, '\0'))
      if (var == mark) ++n;
  }
  return n;
}

size_t lineCount(const std::string& path) {
  const std::string text = readFile(path);
  return std::count(text.begin(), text.end(), '\n');
}

// Every run and fine-tune of `out` has the weights of `ref`'s, and one training's log.
void expectSameWeightsAndLogs(const std::string& ref, const std::string& out) {
  int compared = 0;
  for (const auto& [path, time] : checkpointTimes(ref)) {
    const std::string rel = fs::relative(path, ref).string();
    EXPECT_LT(testing::weightDifference(path, out + "/" + rel), 1e-6) << rel;
    const std::string log = (fs::path(rel).parent_path() / "log.jsonl").string();
    EXPECT_EQ(lineCount(out + "/" + log), lineCount(ref + "/" + log))
        << log << ": trained more than once";
    ++compared;
  }
  EXPECT_EQ(compared, 7);  // 3 runs, 3 fine-tunes of them and 1 of the random weights
}

// The checkpoints under OUT/runs, counted while workers write there (no error stops the count).
size_t trainedRuns(const std::string& out) {
  std::error_code ec;
  size_t n = 0;
  for (fs::recursive_directory_iterator it(out + "/runs", ec), end; !ec && it != end;
       it.increment(ec))
    n += it->path().filename() == "checkpoint-last.pth";
  return n;
}

TEST(CovisSweep, WorkerProcessesShareTheRunsAndEndAsOneProcessDoes) {
  const std::string dir = testing::scratchDir("workers");
  // One process on as many threads as each of two workers: the same arithmetic, run by run.
  const std::string threads = std::to_string(std::max(1, omp_get_max_threads() / 2));
  ASSERT_EQ(testing::runProcess(workersArgs(dir + "/one"), -1, {"OMP_NUM_THREADS=" + threads}), 0);
  // Two workers; the first run's claim is held here, as by a worker killed before it trained it,
  // until they have trained the other two: then one of them trains it before its fine-tune.
  const std::string twoDir = dir + "/two";
  std::optional<WorkClaim> held = WorkClaim::tryTake(twoDir + "/claims/bin_0.45-seed-0.lock");
  ASSERT_TRUE(held.has_value());
  const pid_t lead = testing::spawnProcess(withOption(workersArgs(twoDir), "--processes", "2"));
  for (int i = 0; i < 12000 && trainedRuns(twoDir) < 2; ++i) usleep(10 * 1000);
  EXPECT_EQ(trainedRuns(twoDir), 2u) << "the workers did not train the other runs";
  EXPECT_FALSE(fs::exists(twoDir + "/runs/bin_0.45/seed-0/checkpoint-last.pth"));
  held.reset();
  ASSERT_EQ(testing::waitProcess(lead), 0);
  expectSameWeightsAndLogs(dir + "/one", dir + "/two");
  int claims = 0;
  for (const auto& e : fs::directory_iterator(dir + "/two/claims"))
    claims += e.path().extension() == ".lock";
  EXPECT_EQ(claims, 7);
  // The workers trained and fine-tuned it all between them, each its share, none twice.
  int trained = 0, finetuned = 0;
  for (int k = 1; k <= 2; ++k) {
    const auto w =
        nlohmann::json::parse(readFile(dir + "/two/claims/worker-" + std::to_string(k) + ".json"));
    EXPECT_GE(w["runs_trained"].get<int>() + w["finetunes"].get<int>(), 1) << "worker " << k;
    trained += w["runs_trained"].get<int>();
    finetuned += w["finetunes"].get<int>();
  }
  EXPECT_EQ(trained, 3);
  EXPECT_EQ(finetuned, 4);
  const auto one = nlohmann::json::parse(readFile(dir + "/one/results.json"));
  const auto two = nlohmann::json::parse(readFile(dir + "/two/results.json"));
  ASSERT_EQ(two["runs"].size(), 3u);
  for (size_t i = 0; i < 3; ++i)
    for (const char* figure : {"xv_loss", "ft_flow_aepe"})
      EXPECT_NEAR(two["runs"][i][figure].get<double>(), one["runs"][i][figure].get<double>(), 1e-4)
          << i << " " << figure;

  // The command stopped (SIGINT), then killed (SIGKILL), each time once its workers have trained
  // a run: they stop with it, before the work is done, and none is left behind. The same command
  // then finishes the sweep as the uninterrupted one did.
  const std::string killed = dir + "/killed";
  for (const int sig : {SIGINT, SIGKILL}) {
    const size_t before = trainedRuns(killed);
    const pid_t lead = testing::spawnProcess(withOption(workersArgs(killed), "--processes", "2"));
    for (int i = 0; i < 12000 && trainedRuns(killed) == before; ++i) usleep(10 * 1000);
    ASSERT_EQ(workersOf(lead), 2) << "the workers are not running";
    kill(lead, sig);
    EXPECT_EQ(testing::waitProcess(lead), sig == SIGINT ? 1 : -SIGKILL);
    for (int i = 0; i < 12000 && workersOf(lead) > 0; ++i) usleep(10 * 1000);
    ASSERT_EQ(workersOf(lead), 0) << "a worker outlived the command that started it";
    for (const char* record : {"/claims/worker-1.json", "/claims/worker-2.json"})
      EXPECT_FALSE(fs::exists(killed + record)) << "a worker did all its work after " << sig;
  }
  ASSERT_EQ(testing::runProcess(withOption(workersArgs(killed), "--processes", "2")), 0);
  expectSameWeightsAndLogs(dir + "/one", killed);
}

TEST(CovisSweep, BadProcessesAreRefused) {
  const std::string out = testing::scratchDir("bad_processes");
  for (const char* n : {"0", "65", "two"})
    EXPECT_EQ(testing::runProcess(withOption(miniArgs(out), "--processes", n)), 2) << n;
  EXPECT_EQ(testing::runProcess(withOption(miniArgs(out), "--processes", "2"), -1,
                                {"WORLD_SIZE=2", "RANK=0"}),
            2);
  SweepConfig c = miniSweep(out);
  c.processes = 2;  // without the command line to start workers with
  EXPECT_ERROR_CONTAINS(runCovisSweep(c), "--processes needs the command line");
  c.command = {"/bin/true"};
  c.worker = 3;
  EXPECT_ERROR_CONTAINS(runCovisSweep(c), "--worker is for the workers that --processes starts");
  EXPECT_FALSE(fs::exists(out + "/pool"));
  // A worker started by hand, not by --processes: refused before it claims anything.
  EXPECT_EQ(testing::runProcess(
                withOption(withOption(miniArgs(out), "--processes", "2"), "--worker", "1")),
            1);
  EXPECT_FALSE(fs::exists(out + "/claims"));
}

TEST(CovisSweep, BadSeedsAndBaselinesAreRefused) {
  SweepConfig c = miniSweep(testing::scratchDir("bad_seeds"));
  c.seeds = 0;
  EXPECT_ERROR_CONTAINS(runCovisSweep(c), "seeds must be in 1..1000");
  c.seeds = 2;
  c.baselines = {"simclr"};
  EXPECT_ERROR_CONTAINS(runCovisSweep(c), "unknown baseline 'simclr' (use mae)");
  c.baselines = {"mae", "mae"};
  EXPECT_ERROR_CONTAINS(runCovisSweep(c), "baseline 'mae' is given twice");
  c.baselines = {"mae"};
  c.firstSeed = 999;
  EXPECT_ERROR_CONTAINS(runCovisSweep(c),
                        "seed indices must lie in 0..999 (--first-seed 999, --seeds 2)");
  c.firstSeed = -1;
  EXPECT_ERROR_CONTAINS(runCovisSweep(c), "seed indices must lie in 0..999");
  c.firstSeed = 0;
  // The command refuses them before any work, with exit 2.
  for (const auto& [option, value] :
       {std::pair{"--seeds", "0"}, std::pair{"--baseline", "byol"}, std::pair{"--first-seed", "-1"},
        std::pair{"--first-seed", "999"}})
    EXPECT_EQ(testing::runProcess(withOption(seededArgs(c.out), option, value)), 2) << option;
  EXPECT_FALSE(fs::exists(c.out + "/pool"));
  c.baselines = {"mae"};
  c.sets = {"bin_0.45", "bin_0.45"};
  EXPECT_ERROR_CONTAINS(runCovisSweep(c), "set 'bin_0.45' is given twice");
  c.sets = {"bin_0.47"};
  EXPECT_ERROR_CONTAINS(runCovisSweep(c), "bin centre 0.47 must be a multiple of 0.05");
  c.sets = {};
  c.mechanismMinCovis = 0.8;
  EXPECT_ERROR_CONTAINS(runCovisSweep(c), "must be lo,hi with 0 <= lo < hi <= 1");
  auto args = seededArgs(c.out);
  args.insert(args.end(), {"--sets", "bin_0.45,binn_0.45"});
  EXPECT_EQ(testing::runProcess(args), 2);
  EXPECT_FALSE(fs::exists(c.out + "/pool"));
}

TEST(CovisSweep, RunsGoSeedBySeedAndMaeTrainsOnTheSetNearestHalf) {
  SweepConfig c = miniSweep("/tmp/out");
  c.modes = {"uniform", "bin"};
  c.centers = {0.15, 0.55, 0.95};
  c.seeds = 3;
  c.seed = 10;
  c.baselines = {"mae"};
  std::vector<SweepSet> sets;
  for (const auto& m : c.modes)
    for (double x : c.centers) sets.push_back(makeSweepSet(m, x));
  EXPECT_EQ(referenceSet(sets), "bin_0.55");  // a bin set before a uniform one at 0.55
  const std::vector<SweepRun> runs = planRuns(c, sets);
  ASSERT_EQ(runs.size(), 21u);
  EXPECT_EQ(runs[0].label(), "uniform_0.15 seed 0");
  EXPECT_EQ(runs[6].name, "mae");
  EXPECT_EQ(runs[6].task, "mae");
  EXPECT_EQ(runs[6].keysSet, "bin_0.55");
  EXPECT_EQ(runs[7].label(), "uniform_0.15 seed 1");
  EXPECT_EQ(runs[7].seed, 11u);
  EXPECT_EQ(runs[20].dir, fs::path("/tmp/out/runs/mae/seed-2"));
  // A part of the study from seed 3 (--first-seed 3): its seeds' runs, as the whole study has.
  c.firstSeed = 3;
  c.seeds = 2;
  const std::vector<SweepRun> part = planRuns(c, sets);
  ASSERT_EQ(part.size(), 14u);
  EXPECT_EQ(part[0].label(), "uniform_0.15 seed 3");
  EXPECT_EQ(part[0].seed, 13u);
  EXPECT_EQ(part[13].dir, fs::path("/tmp/out/runs/mae/seed-4"));
  EXPECT_EQ(c.seedIndices(), (std::vector<int>{3, 4}));
}

// ---- --downstream ----

// A sweep small enough to fine-tune every run: bins 0.45 and 0.75 and mae, with 2 seeds, and
// fine-tunes of 4 steps.
SweepConfig downstreamSweep(const std::string& out) {
  SweepConfig c = miniSweep(out);
  c.sets = {"bin_0.45", "bin_0.75"};
  c.seeds = 2;
  c.baselines = {"mae"};
  c.reports = false;
  c.finetuneSteps = 4;
  c.finetunePairs = 16;
  c.finetuneEvalPairs = 24;
  return c;
}

std::vector<std::string> downstreamArgs(const std::string& out) {
  std::vector<std::string> a = miniArgs(out);
  a.insert(a.end(), {"--sets", "bin_0.45,bin_0.75", "--seeds", "2", "--baseline", "mae",
                     "--no-reports", "--downstream", "flow,depth", "--finetune-steps", "4",
                     "--finetune-pairs", "16", "--finetune-eval-pairs", "24"});
  return a;
}

// The checkpoints of the fine-tunes (finetune-<task>/) or of the pre-training runs, with when
// each was written.
std::map<std::string, fs::file_time_type> times(const std::string& out, bool fineTunes) {
  auto all = checkpointTimes(out);
  for (auto it = all.begin(); it != all.end();)
    it = (it->first.find("/finetune-") != std::string::npos) == fineTunes ? std::next(it)
                                                                          : all.erase(it);
  return all;
}

// The covis of each pair of a fine-tuning data part (ds/<part>), read from its shards.
std::map<std::string, double> partCovis(const std::string& out, const std::string& part) {
  std::map<std::string, double> covis;
  for (const auto& e : fs::directory_iterator(out + "/ds/" + part))
    if (e.path().extension() == ".tar") {
      const ShardIndex index = ShardIndex::open(e.path().string());
      for (size_t i = 0; i < index.size(); ++i) covis[index[i].key] = index[i].record.covis;
    }
  return covis;
}

// A run's column is the mean of its fine-tune's per-pair figures over its held-out pairs: for
// depth those at covis 0.3-0.7 of ds/heldout, for flow every flow-style pair of
// ds/flow-heldout; and its flow bins count every flow-style held-out pair once.
void expectColumnsFromThePairs(const nlohmann::json& row, const std::string& out,
                               const std::string& runDir) {
  const auto wide = partCovis(out, "heldout"), flowStyle = partCovis(out, "flow-heldout");
  for (const auto& [task, figure, column] :
       {std::tuple{"flow", "aepe", "ft_flow_aepe"}, std::tuple{"flow", "px3", "ft_flow_px3"},
        std::tuple{"depth", "delta1", "ft_depth_delta1"},
        std::tuple{"flow", "aepe_covisible", "ft_flow_aepe_covisible"},
        std::tuple{"flow", "aepe", "ft_flow_aepe_all"}}) {
    const bool flow = std::string(task) == "flow";
    const auto& covis = flow ? flowStyle : wide;
    const double lo = flow ? 0.6 : 0.3, hi = flow ? 1.01 : 0.7;
    const auto h = nlohmann::json::parse(readFile(runDir + "/finetune-" + task + "/heldout.json"));
    double sum = 0;
    int n = 0, all = 0;
    for (const auto& p : h["per_pair"]["model"]) {
      const double c = covis.at(p["key"].get<std::string>());
      ++all;
      if (c >= lo && c < hi && p[figure].is_number()) sum += p[figure].get<double>(), ++n;
    }
    EXPECT_EQ(all, static_cast<int>(covis.size())) << "every held-out pair is measured";
    ASSERT_GT(n, 0) << "no held-out pair in the band";
    EXPECT_NEAR(row[column].get<double>(), sum / n, 1e-9 * std::max(1.0, sum / n)) << column;
  }
  int binned = 0;
  for (const auto& bin : row["ft_flow_by_covis"]) binned += bin["pairs"].get<int>();
  EXPECT_EQ(binned, static_cast<int>(flowStyle.size()));
}

// Flow fine-tunes on flow-style pairs of its own, of the training and held-out scenes; depth on
// the wide ones. With --finetune-flow-motion walk, flow shares depth's pairs and band.
void expectFlowStylePairsForFlow(const SweepConfig& c) {
  for (const char* part : {"flow-train", "flow-heldout"}) {
    const auto index = nlohmann::json::parse(readFile(c.out + "/ds/" + part + "/index.json"));
    EXPECT_EQ(index["motion"]["kind"], "near") << part;
    const auto covis = partCovis(c.out, part);
    EXPECT_EQ(covis.size(), std::string(part) == "flow-train" ? 16u : 24u) << part;
    for (const auto& [key, value] : covis) EXPECT_GE(value, 0.6 - 1e-9) << part << " " << key;
  }
  EXPECT_EQ(nlohmann::json::parse(readFile(c.out + "/ds/train/index.json"))["motion"]["kind"],
            "walk");
  const DownstreamData near = openDownstreamData(c);
  EXPECT_EQ(near.flowTrainShards, c.out + "/ds/flow-train/pairs-*.tar");
  EXPECT_EQ(near.flowTrainPairs, 16u);
  EXPECT_EQ(near.flowBandLo, 0.6);
  SweepConfig walkConfig = c;
  walkConfig.finetuneFlowMotion = "walk";
  const DownstreamData walk = openDownstreamData(walkConfig);
  EXPECT_EQ(walk.flowTrainShards, walk.trainShards);
  EXPECT_EQ(walk.flowHeldoutCovis, walk.heldoutCovis);
  EXPECT_EQ(walk.flowBandLo, kDownstreamBandLo);
  EXPECT_EQ(walk.flowBandHi, kDownstreamBandHi);
}

// The real command, started from `clean`'s pre-training alone and SIGKILLed at growing delays
// (so that kills land between and inside its fine-tunes, and in making their data), then run to
// the end, gives `clean`'s results.
void expectKilledFineTunesEndAsTheseDid(const std::string& clean) {
  const std::string killed = clean + "-killed";
  fs::remove_all(killed);  // a previous run's
  fs::copy(clean, killed, fs::copy_options::recursive);
  fs::remove_all(killed + "/ds");
  for (const auto& [path, time] : times(killed, true)) fs::remove_all(fs::path(path).parent_path());
  for (const char* f : {"results.csv", "results_runs.csv", "results.json", "summary.html",
                        "downstream_by_covis.csv"})
    fs::remove(killed + "/" + f);
  int kills = 0, midway = 0;
  for (int delayMs = 200; delayMs < 60000 && !fs::exists(killed + "/results.csv"); delayMs *= 2) {
    if (testing::runProcess(downstreamArgs(killed), delayMs) != -SIGKILL) continue;
    ++kills;
    int done = 0;
    for (const auto& [path, time] : times(killed, true))
      done += fs::exists(fs::path(path).parent_path() / "heldout.json");
    midway += done > 0 && done < 16;
  }
  EXPECT_GE(kills, 2);
  EXPECT_GE(midway, 1) << "no kill fell between two fine-tunes";
  ASSERT_EQ(testing::runProcess(downstreamArgs(killed)), 0);
  for (const char* f : {"results.csv", "results_runs.csv", "downstream_by_covis.csv"})
    EXPECT_EQ(readFile(killed + "/" + f), readFile(clean + "/" + f)) << f;
}

// ---- a study in parts: --first-seed and --merge ----

// Writes `text` to `dir`/results.json, as a part's folder holds it.
std::string writePart(const std::string& dir, const std::string& text) {
  fs::create_directories(dir);
  writeFileAtomic(dir + "/results.json", text);
  return dir;
}

std::string writePart(const std::string& dir, const nlohmann::json& results) {
  return writePart(dir, results.dump(1) + "\n");
}

// Parts that are not parts of one study, or not results at all, are refused naming the part.
void expectBadPartsRefused(const std::string& part0, const std::string& part1) {
  const std::string merged = testing::scratchDir("parts_bad_merged");
  const std::string text = readFile(part1 + "/results.json");
  const nlohmann::json r = nlohmann::json::parse(text);
  EXPECT_ERROR_CONTAINS(mergeSweepParts({part0, part0 + "/results.json"}, merged),
                        part0 + "/results.json: seed 0 is in " + part0 +
                            "/results.json too: merge each seed from one part");
  nlohmann::json other = r;
  other["config"]["steps"] = 5;
  const std::string steps = writePart(testing::scratchDir("parts_bad_steps"), other);
  EXPECT_ERROR_CONTAINS(mergeSweepParts({part0, steps}, merged),
                        steps + "/results.json: is not a part of the study of " + part0 +
                            "/results.json: its setting 'steps' is 5, not 4");
  other = r;
  other["finetune_baselines"]["ft_flow_aepe"] =
      r["finetune_baselines"]["ft_flow_aepe"].get<double>() * 1.01;
  const std::string data = writePart(testing::scratchDir("parts_bad_data"), other);
  EXPECT_ERROR_CONTAINS(mergeSweepParts({part0, data}, merged),
                        "its held-out data (zero flow's and constant depth's figures) is");
  EXPECT_ERROR_CONTAINS(mergeSweepParts({part0, data}, merged),
                        "(drawn on a CPU that draws other pairs? --other-draws merges parts whose "
                        "settings agree)");
  EXPECT_ERROR_CONTAINS(mergeSweepParts({part0, steps}, merged, true),
                        "its setting 'steps' is 5, not 4");  // a setting is never a draw
  other = r;
  other["config"]["eval_pairs"] = r["config"]["eval_pairs"].get<int>() - 1;  // a pair short
  const std::string shortDraw = writePart(testing::scratchDir("parts_short_draw"), other);
  EXPECT_ERROR_CONTAINS(mergeSweepParts({part0, shortDraw}, merged), "its held-out pair counts is");
  EXPECT_NO_THROW(
      mergeSweepParts({part0, shortDraw}, testing::scratchDir("parts_short_draw_merged"), true));
  other = r;
  other["config"]["scenes"] = nlohmann::json::array({"/elsewhere/apartment"});
  const std::string scenes = writePart(testing::scratchDir("parts_bad_scenes"), other);
  EXPECT_ERROR_CONTAINS(mergeSweepParts({part0, scenes}, merged),
                        "its scene files is [\"apartment\"], not [\"");
  const std::string truncated =
      writePart(testing::scratchDir("parts_truncated"), text.substr(0, text.size() / 2));
  EXPECT_ERROR_CONTAINS(mergeSweepParts({part0, truncated}, merged),
                        truncated + "/results.json: is not a JSON object (truncated?)");
  const std::string notResults =
      writePart(testing::scratchDir("parts_not_results"),
                {{"config", r["config"]}, {"runs", nlohmann::json::array()}});
  EXPECT_ERROR_CONTAINS(mergeSweepParts({notResults}, merged),
                        "has no runs in 'runs': not the results.json of a finished covis_sweep");
  EXPECT_ERROR_CONTAINS(mergeSweepParts({part0, merged + "/nowhere"}, merged),
                        merged + "/nowhere: no such file");
  EXPECT_FALSE(fs::exists(merged + "/results.json"));
  EXPECT_ERROR_CONTAINS(mergeSweepParts({part0, part1}, part1),
                        part1 + " holds the part " + part1 +
                            "/results.json, which the merge would overwrite: give another folder");
  EXPECT_EQ(readFile(part1 + "/results.json"), text);
  // The command: exit 1 for a bad part, 2 without --out.
  EXPECT_EQ(testing::runProcess({covisSweepTool(), "--merge", part0, truncated, "--out", merged}),
            1);
  EXPECT_EQ(testing::runProcess({covisSweepTool(), "--merge", part0}), 2);
  EXPECT_FALSE(fs::exists(merged + "/results.json"));
}

// Parts drawn apart (on CPUs that draw other pairs from one seed) merge with --other-draws: the
// runs as they are, the baselines the seed-weighted means of the parts', each set's mean covis
// its runs' mean, and each part's draw in the config. Here a two-seed part and a one-seed part
// (seed 1's runs as seed 2), its draw moved: zero flow 3 % higher, mean covis 0.01 higher, its
// first zero-flow covis bin empty (left out) and its second at 2 px more.
nlohmann::json movedDraw(const std::string& seed1, bool move) {
  nlohmann::json moved = nlohmann::json::parse(readFile(seed1 + "/results.json"));
  for (const char* key : {"runs", "random_runs"})
    for (auto& run : moved[key]) {
      run["seed_index"] = 2;
      if (move && run.contains("mean_covis"))
        run["mean_covis"] = run["mean_covis"].get<double>() + 0.01;
    }
  if (!move) return moved;
  for (auto& row : moved["rows"])
    if (row.contains("mean_covis")) row["mean_covis"] = row["mean_covis"].get<double>() + 0.01;
  nlohmann::json& zero = moved["finetune_baselines"];
  zero["ft_flow_aepe"] = zero["ft_flow_aepe"].get<double>() * 1.03;
  nlohmann::json& bins = zero["ft_flow_by_covis"];
  bins[1]["ft_flow_aepe"] = bins[1]["ft_flow_aepe"].get<double>() + 2;
  bins.erase(0);
  return moved;
}

void expectOtherDrawsMerged(const nlohmann::json& twoSeeds, const std::string& seed1) {
  const nlohmann::json& zero = twoSeeds["finetune_baselines"];
  ASSERT_GE(zero["ft_flow_by_covis"].size(), 2u);
  const nlohmann::json moved = movedDraw(seed1, true);
  const std::string a = writePart(testing::scratchDir("draws_a"), twoSeeds);
  const std::string b = writePart(testing::scratchDir("draws_b"), moved);
  const std::string merged = testing::scratchDir("draws_merged");
  EXPECT_ERROR_CONTAINS(mergeSweepParts({a, b}, merged), "its sets' mean covis is");
  const nlohmann::json m = mergeSweepParts({a, b}, merged, true);
  EXPECT_EQ(m["config"]["other_draws"], true);
  EXPECT_EQ(m["config"]["seeds"], 3);
  const nlohmann::json& z = m["finetune_baselines"];
  EXPECT_NEAR(z["ft_flow_aepe"].get<double>(), zero["ft_flow_aepe"].get<double>() * 3.03 / 3, 1e-9);
  EXPECT_EQ(m["constant_depth"], twoSeeds["constant_depth"]);  // equal in both: kept as it is
  // By covis: the first bin is part a's alone (its 2 seeds of 3 give 2/3 of its pairs); the
  // second pools a's pairs, 2 seeds, with b's, 1 seed, at 2 px more.
  const nlohmann::json& bin0 = zero["ft_flow_by_covis"][0];
  const nlohmann::json& bin1 = zero["ft_flow_by_covis"][1];
  ASSERT_EQ(z["ft_flow_by_covis"].size(), zero["ft_flow_by_covis"].size());
  EXPECT_EQ(z["ft_flow_by_covis"][0]["covis_lo"], bin0["covis_lo"]);
  EXPECT_NEAR(z["ft_flow_by_covis"][0]["ft_flow_aepe"].get<double>(),
              bin0["ft_flow_aepe"].get<double>(), 1e-9);
  EXPECT_EQ(z["ft_flow_by_covis"][0]["pairs"], std::lround(2 * bin0["pairs"].get<double>() / 3));
  const double n1 = bin1["pairs"].get<double>();
  EXPECT_NEAR(z["ft_flow_by_covis"][1]["ft_flow_aepe"].get<double>(),
              bin1["ft_flow_aepe"].get<double>() + 2 * n1 / (3 * n1), 1e-9);
  EXPECT_EQ(z["ft_flow_by_covis"][1]["pairs"], bin1["pairs"]);
  for (const auto& row : m["rows"]) {
    const auto before = std::find_if(twoSeeds["rows"].begin(), twoSeeds["rows"].end(),
                                     [&](const auto& r) { return r["set"] == row["set"]; });
    ASSERT_NE(before, twoSeeds["rows"].end()) << row["set"];
    EXPECT_NEAR(row["mean_covis"].get<double>(), (*before)["mean_covis"].get<double>() + 0.01 / 3,
                1e-12)
        << row["set"];
  }
  const nlohmann::json& draw = m["config"]["parts"][1]["draw"];
  EXPECT_EQ(draw["finetune_baselines"], moved["finetune_baselines"]);
  for (const auto& row : moved["rows"])
    EXPECT_EQ(draw["sets_mean_covis"][row["set"].get<std::string>()], row["mean_covis"]);
  // Parts of one draw merge alike with or without the flag, which then records nothing.
  const std::string same = writePart(testing::scratchDir("draws_same"), movedDraw(seed1, false));
  const nlohmann::json plain = mergeSweepParts({a, same}, merged);
  const nlohmann::json flagged = mergeSweepParts({a, same}, merged, true);
  EXPECT_FALSE(flagged["config"].contains("other_draws"));
  EXPECT_EQ(flagged.dump(), plain.dump());
  // The command: --other-draws merges, and is refused without --merge.
  const std::string cli = testing::scratchDir("draws_merged_cli");
  EXPECT_EQ(testing::runProcess({covisSweepTool(), "--merge", a, b, "--out", cli}), 1);
  EXPECT_EQ(testing::runProcess({covisSweepTool(), "--merge", a, b, "--other-draws", "--out", cli}),
            0);
  EXPECT_EQ(nlohmann::json::parse(readFile(cli + "/results.json"))["finetune_baselines"],
            m["finetune_baselines"]);
  EXPECT_EQ(testing::runProcess({covisSweepTool(), "--other-draws", "--out", cli}), 2);
}

// A study's seeds run as parts, each in its own folder (the later seed first: a part needs no
// other), and merged from their results.json files, give the report of one sweep over all the
// seeds: the same runs, intervals, verdicts and by-covis rows, to the byte.
TEST(CovisSweep, SeedsRunInPartsMergeToTheSweepOfAllTheSeeds) {
  const std::string whole = testing::scratchDir("parts_whole");
  SweepConfig c = downstreamSweep(whole);
  c.downstream = {"flow"};
  const nlohmann::json all = runCovisSweep(c);
  std::map<std::string, std::string> files;
  const std::vector<std::string> names = {"results.csv", "results_runs.csv", "probe_by_covis.csv",
                                          "downstream_by_covis.csv"};
  for (const std::string& f : names) files[f] = readFile(whole + "/" + f);

  SweepConfig part1 = c;
  part1.out = testing::scratchDir("parts_seed1");
  part1.firstSeed = 1;
  part1.seeds = 1;
  const nlohmann::json one = runCovisSweep(part1);
  EXPECT_FALSE(fs::exists(part1.out + "/runs/bin_0.45/seed-0"));
  EXPECT_EQ(one["runs"][0]["seed_index"], 1);
  EXPECT_EQ(one["config"]["first_seed"], 1);
  c.seeds = 1;  // the whole study's folder, now a part with seed 0: nothing trains again
  runCovisSweep(c);

  const std::string merged = testing::scratchDir("parts_merged");
  const nlohmann::json m = mergeSweepParts({part1.out, whole + "/results.json"}, merged);
  for (const std::string& f : names) EXPECT_EQ(readFile(merged + "/" + f), files[f]) << f;
  EXPECT_EQ(m["verdicts"], all["verdicts"]);
  EXPECT_EQ(m["rows"].dump(), all["rows"].dump());  // NaN (a column no run has) is never ==
  EXPECT_EQ(m["random_encoder"].dump(), all["random_encoder"].dump());
  EXPECT_EQ(m["config"]["seeds"], 2);
  ASSERT_EQ(m["config"]["parts"].size(), 2u);
  EXPECT_EQ(m["config"]["parts"][0]["seeds"], nlohmann::json::array({1}));
  EXPECT_EQ(m["config"]["parts"][1]["results"], whole + "/results.json");
  EXPECT_TRUE(fs::exists(merged + "/summary.html"));
  EXPECT_TRUE(fs::exists(merged + "/plot_downstream_by_covis.svg"));
  // The command merges the same.
  const std::string cli = testing::scratchDir("parts_merged_cli");
  ASSERT_EQ(testing::runProcess({covisSweepTool(), "--merge", whole, part1.out, "--out", cli}), 0);
  EXPECT_EQ(readFile(cli + "/results.csv"), files["results.csv"]);
  expectBadPartsRefused(whole, part1.out);
  expectOtherDrawsMerged(all, part1.out);
}

// Also: a killed sweep resumes fine-tune by fine-tune (expectKilledFineTunesEndAsTheseDid).
TEST(CovisSweep, DownstreamAddedToAFinishedSweepFineTunesOnlyWhatIsMissing) {
  const std::string out = testing::scratchDir("ds_added");
  SweepConfig c = downstreamSweep(out);
  runCovisSweep(c);
  const auto pretrained = times(out, false);
  ASSERT_EQ(pretrained.size(), 6u);
  EXPECT_FALSE(fs::exists(out + "/ds"));
  EXPECT_FALSE(fs::exists(out + "/downstream_by_covis.csv"));

  c.downstream = {"flow", "depth"};
  const nlohmann::json r = runCovisSweep(c);
  EXPECT_EQ(times(out, false), pretrained);  // no run trained again
  const auto tuned = times(out, true);
  ASSERT_EQ(tuned.size(), 16u);  // (6 runs + 2 random) x 2 tasks
  for (const auto& [path, time] : tuned) {
    const std::string dir = fs::path(path).parent_path().string();
    EXPECT_TRUE(fs::exists(dir + "/heldout.json")) << dir;
    EXPECT_EQ(nlohmann::json::parse(readFile(dir + "/summary.json"))["steps"], 4) << dir;
  }
  // The new columns, for every set, mae and random weights, with intervals over the 2 seeds.
  // Shares lie in [0, 1]; after 4 steps a model's flow errors are within 3 times zero flow's,
  // and its depth's relative error within 10 (a constant depth's is 0.6-0.9 here).
  const auto& floor = r["finetune_baselines"];
  const std::map<std::string, std::pair<double, double>> bounds = {
      {"ft_flow_aepe", {0, 3 * floor["ft_flow_aepe"].get<double>()}},
      {"ft_flow_aepe_covisible", {0, 3 * floor["ft_flow_aepe_covisible"].get<double>()}},
      {"ft_flow_aepe_all", {0, 3 * floor["ft_flow_aepe_all"].get<double>()}},
      {"ft_flow_px3", {0, 1}},
      {"ft_depth_delta1", {0, 1}},
      {"ft_depth_absrel", {0, 10}}};
  for (const auto& [m, range] : bounds) {
    expectSetsAggregateTheirRuns(r, out, m, range.first, range.second);
    for (const auto& row : r["rows"])
      EXPECT_TRUE(std::isfinite(numberOrNan(row, std::string(m) + "_ci95"))) << row["set"] << m;
    EXPECT_TRUE(std::isfinite(numberOrNan(r["random_encoder"], std::string(m) + "_mean"))) << m;
    EXPECT_TRUE(std::isfinite(numberOrNan(r["finetune_baselines"], m))) << m;
  }
  expectColumnsFromThePairs(r["runs"][4], out, runDir(out, "bin_0.75", 1));
  expectColumnsFromThePairs(r["random_runs"][0], out, out + "/runs/random/seed-0");
  expectFlowStylePairsForFlow(c);
  EXPECT_EQ(r["runs"][4]["set"], "bin_0.75");
  EXPECT_EQ(r["runs"][4]["seed_index"], 1);

  // The by-covis breakdown: bins of 0.1 per set, random weights and zero flow.
  const auto byCovis = readCsvRows(out + "/downstream_by_covis.csv");
  std::set<std::string> sets;
  for (const auto& row : byCovis) {
    sets.insert(row.at("set"));
    EXPECT_NEAR(std::stod(row.at("covis_hi")) - std::stod(row.at("covis_lo")), 0.1, 1e-9);
    EXPECT_EQ(row.at("seeds"), row.at("set") == "zero_flow" ? "1" : "2");
  }
  EXPECT_EQ(sets,
            (std::set<std::string>{"bin_0.45", "bin_0.75", "mae", "random_encoder", "zero_flow"}));
  const std::string csv = readFile(out + "/downstream_by_covis.csv");
  EXPECT_EQ(csv.substr(0, csv.find('\n')),
            "set,task,covis_lo,covis_hi,pairs,seeds,ft_flow_aepe_mean,ft_flow_aepe_ci95,"
            "ft_flow_aepe_covisible_mean,ft_flow_aepe_covisible_ci95");

  // The verdicts of both claims on each fine-tuned probe, and of the instrument, on the page.
  const std::string html = readFile(out + "/summary.html");
  for (const std::string line :
       {"Claim 1, covis near 0.5 beats high covis, on the fine-tuned flow AEPE (px): ",
        "Claim 1, covis near 0.5 beats high covis, on the fine-tuned depth delta1: ",
        "Claim 2, cross-view completion beats auto-completion (MAE), its encoder with a random "
        "decoder, on the fine-tuned flow AEPE (px): ",
        "Claim 2, cross-view completion beats auto-completion (MAE), its encoder with a random "
        "decoder, on the fine-tuned depth delta1: ",
        "Claim 2, cross-view pre-training beats random weights, on the fine-tuned flow AEPE "
        "(px): ",
        "Claim 2, cross-view pre-training beats random weights, on the fine-tuned depth "
        "AbsRel: ",
        "Instrument, fine-tuned flow AEPE (px): "})
    EXPECT_NE(html.find(plot::escape(line)), std::string::npos) << line;
  const std::regex ref("(src|href)='([^']+)'");
  for (auto it = std::sregex_iterator(html.begin(), html.end(), ref); it != std::sregex_iterator();
       ++it)
    EXPECT_TRUE(fs::exists(out + "/" + (*it)[2].str())) << (*it)[2].str();
  EXPECT_TRUE(fs::exists(out + "/plot_downstream_by_covis.svg"));

  // Run again: nothing is fine-tuned again. One fine-tune removed: only it runs, to the same
  // figures.
  const std::string results = readFile(out + "/results.csv");
  runCovisSweep(c);
  EXPECT_EQ(times(out, true), tuned);
  const std::string gone = runDir(out, "mae", 0) + "/finetune-flow";
  fs::remove_all(gone);
  runCovisSweep(c);
  expectOnlyRedone(times(out, true), tuned, gone + "/checkpoint-last.pth");
  EXPECT_EQ(readFile(out + "/results.csv"), results);
  expectKilledFineTunesEndAsTheseDid(out);

  // Another budget makes the fine-tunes it changes again, and only those.
  const auto before = times(out, true);
  c.downstream = {"depth"};
  c.finetuneSteps = 5;
  runCovisSweep(c);
  for (const auto& [path, time] : times(out, true)) {
    const bool depth = path.find("/finetune-depth/") != std::string::npos;
    EXPECT_EQ(time != before.at(path), depth) << path;
    EXPECT_EQ(
        nlohmann::json::parse(readFile(fs::path(path).parent_path() / "summary.json"))["steps"],
        depth ? 5 : 4)
        << path;
  }
}

// Only the parts a fine-tune reads are rendered: flow alone on flow-style pairs makes no wide
// pairs; adding depth makes them and keeps flow's; flow on wide pairs ("walk") needs them.
TEST(CovisSweep, FineTuningDataHoldsOnlyThePartsItsTasksRead) {
  SweepConfig c = downstreamSweep(testing::scratchDir("ds_parts"));
  const auto made = [&] {
    std::set<std::string> parts;
    for (const auto& e : fs::directory_iterator(c.out + "/ds"))
      if (fs::exists(e.path() / "summary.json")) parts.insert(e.path().filename().string());
    return parts;
  };
  const auto written = [&](const std::string& part) {  // each file of ds/<part>, with its time
    std::map<std::string, fs::file_time_type> files;
    for (const auto& e : fs::directory_iterator(c.out + "/ds/" + part))
      files[e.path().string()] = fs::last_write_time(e.path());
    return files;
  };
  c.downstream = {"flow"};
  EXPECT_FALSE(c.finetunesOnWidePairs());
  const DownstreamData flow = prepareDownstreamData(c, c.scenes, c.heldout);
  EXPECT_EQ(made(), (std::set<std::string>{"flow-heldout", "flow-train"}));
  EXPECT_EQ(flow.flowTrainPairs, 16u);
  EXPECT_EQ(flow.flowHeldoutCovis.size(), 24u);
  EXPECT_EQ(flow.trainShards, "");
  EXPECT_EQ(flow.trainPairs, 0u);
  EXPECT_TRUE(flow.heldoutCovis.empty());
  const auto flowFiles = written("flow-train");

  c.downstream = {"flow", "depth"};
  EXPECT_TRUE(c.finetunesOnWidePairs());
  const DownstreamData both = prepareDownstreamData(c, c.scenes, c.heldout);
  EXPECT_EQ(made(), (std::set<std::string>{"flow-heldout", "flow-train", "heldout", "train"}));
  EXPECT_EQ(both.trainPairs, 16u);
  EXPECT_EQ(both.heldoutCovis.size(), 24u);
  EXPECT_EQ(both.flowHeldoutCovis, flow.flowHeldoutCovis);  // flow's pairs were kept
  EXPECT_EQ(written("flow-train"), flowFiles);

  c.downstream = {"depth"};
  EXPECT_TRUE(c.finetunesOnWidePairs());
  c.downstream = {"flow"};
  c.finetuneFlowMotion = "walk";
  EXPECT_TRUE(c.finetunesOnWidePairs());
  EXPECT_EQ(openDownstreamData(c).flowTrainShards, c.out + "/ds/train/pairs-*.tar");
}

// The page names, for each task fine-tuned and only for those, the pairs it trains on and the
// held-out pairs its columns average over.
TEST(CovisSweep, DownstreamParagraphDescribesTheTasksThatRan) {
  SweepConfig c = downstreamSweep("unused");
  const std::string flowStyle =
                        "flow: flow-style pairs, generate_pairs --motion near, covis >= 0.6",
                    flowWide = "flow: wide pairs, covis >= 0.5",
                    depth = "depth: wide pairs, covis >= 0.5";
  const auto has = [](const std::string& text, const std::string& part) {
    return text.find(part) != std::string::npos;
  };
  c.downstream = {"flow"};
  std::string text = downstreamParagraph(c);
  EXPECT_TRUE(has(text,
                  "for flow with the linear heads, 4 steps of 8 on 16 pairs of the "
                  "training scenes (" +
                      flowStyle + "), "))
      << text;
  EXPECT_TRUE(has(text,
                  "Measured on held-out pairs of the same kinds: flow on every "
                  "flow-style pair; "))
      << text;
  EXPECT_FALSE(has(text, "depth:")) << text;

  c.downstream = {"flow", "depth"};
  text = downstreamParagraph(c);
  EXPECT_TRUE(has(text, "for flow and depth with")) << text;
  EXPECT_TRUE(has(text, "(" + flowStyle + "; " + depth + "), ")) << text;
  EXPECT_TRUE(has(text, ": flow on every flow-style pair, depth at covis 0.3-0.7; ")) << text;

  c.finetuneFlowMotion = "walk";
  text = downstreamParagraph(c);
  EXPECT_TRUE(has(text, "(" + flowWide + "; " + depth + "), ")) << text;
  EXPECT_TRUE(has(text,
                  ": flow at covis 0.3-0.7 (ft_flow_aepe_all: 0.1-1), depth at covis "
                  "0.3-0.7; "))
      << text;

  c.downstream = {"depth"};
  text = downstreamParagraph(c);
  EXPECT_TRUE(has(text, "(" + depth + "), ")) << text;
  EXPECT_FALSE(has(text, "flow:")) << text;
}

TEST(CovisSweep, FineTunesStartFromTheSeedsRandomWeightsAndMaeKeepsItsRandomDecoder) {
  SweepConfig c = downstreamSweep(testing::scratchDir("ds_init"));
  c.downstream = {"flow", "depth"};
  const std::vector<FinetuneJob> jobs = planFinetunes(c, planRuns(c, planSets(c)));
  ASSERT_EQ(jobs.size(), 16u);  // seed by seed: random weights, then each run; flow, then depth
  EXPECT_EQ(jobs[0].label, "random seed 0 flow");
  EXPECT_EQ(jobs[0].init, "random");
  EXPECT_EQ(jobs[1].label, "random seed 0 depth");
  EXPECT_EQ(jobs[1].dir, fs::path(c.out) / "runs/random/seed-0/finetune-depth");
  EXPECT_EQ(jobs[2].label, "bin_0.45 seed 0 flow");
  EXPECT_EQ(jobs[2].init, runDir(c.out, "bin_0.45", 0) + "/checkpoint-last.pth");
  const FinetuneJob& mae = jobs[14];
  EXPECT_EQ(mae.label, "mae seed 1 flow");
  for (size_t i = 0; i < jobs.size(); ++i)
    EXPECT_EQ(jobs[i].seed, runSeed(c, i < 8 ? 0 : 1)) << jobs[i].label;

  CroCoConfig mc = presetConfig(c.preset);
  mc.img_size = c.imgSize;
  mc.patch_size = c.patchSize;
  torch::manual_seed(1234);
  CroCoNet pretrained(mc);
  fs::create_directories(fs::path(mae.init).parent_path());
  saveCheckpoint(mae.init, pretrained, 0, {{"task", "mae"}});
  DownstreamData data;
  data.trainShards = "wide/*.tar", data.heldoutShards = "wide-heldout/*.tar";
  data.flowTrainShards = "near/*.tar", data.flowHeldoutShards = "near-heldout/*.tar";
  data.trainPairs = data.flowTrainPairs = 16;
  for (const FinetuneJob& job : {jobs[0], jobs[1]}) {  // flow, then depth
    const FinetuneConfig f = finetuneConfig(c, presetConfig(c.preset), data, job, 1);
    const bool flow = job.task == "flow";
    EXPECT_EQ(f.data, std::vector<std::string>{flow ? "near/*.tar" : "wide/*.tar"});
    EXPECT_EQ(f.evalData,
              std::vector<std::string>{flow ? "near-heldout/*.tar" : "wide-heldout/*.tar"});
  }
  torch::manual_seed(runSeed(c, 1));
  CroCoNet random(mc);
  const auto p = stateDict(pretrained), w = stateDict(random);
  const auto fromMae = initialNet(finetuneConfig(c, mc, data, mae, 1))->state();
  const auto fromScratch = initialNet(finetuneConfig(c, mc, data, jobs[8], 1))->state();
  int decoder = 0, encoder = 0;
  for (const auto& [name, tensor] : fromMae) {
    if (!w.count(name) || !w.at(name).sizes().equals(tensor.sizes())) continue;  // the head
    const bool dec = name.rfind("dec_", 0) == 0 || name.rfind("decoder_embed", 0) == 0;
    const bool enc = name.rfind("enc_", 0) == 0 || name.rfind("patch_embed", 0) == 0;
    if (dec) {
      ++decoder;
      EXPECT_TRUE(torch::equal(tensor, w.at(name))) << name;
    }
    if (enc) {
      ++encoder;
      EXPECT_TRUE(torch::equal(tensor, p.at(name))) << name;
    }
    EXPECT_TRUE(torch::equal(fromScratch.at(name), w.at(name))) << name;
  }
  EXPECT_GT(decoder, 10);
  EXPECT_GT(encoder, 10);
}

TEST(CovisSweep, BadDownstreamOptionsAreRefused) {
  SweepConfig c = downstreamSweep(testing::scratchDir("ds_bad"));
  c.downstream = {"pose"};
  EXPECT_ERROR_CONTAINS(runCovisSweep(c), "pose is not fine-tuned by the sweep");
  c.downstream = {"segmentation"};
  EXPECT_ERROR_CONTAINS(runCovisSweep(c),
                        "unknown downstream task 'segmentation' (use flow, depth or flow,depth)");
  c.downstream = {"flow", "flow"};
  EXPECT_ERROR_CONTAINS(runCovisSweep(c), "task 'flow' is given twice");
  c.downstream = {"flow"};
  c.finetuneFlowMotion = "jump";
  EXPECT_ERROR_CONTAINS(runCovisSweep(c), "flow's pairs are near or walk, not 'jump'");
  c.finetuneFlowMotion = "near";
  c.finetunePairs = 4;
  EXPECT_ERROR_CONTAINS(runCovisSweep(c), "fine-tuning pairs must be at least one batch (8)");
  for (const auto& [option, value] :
       {std::pair{"--downstream", "pose"}, std::pair{"--finetune-steps", "0"},
        std::pair{"--finetune-pairs", "x"}, std::pair{"--finetune-flow-motion", "jump"}})
    EXPECT_EQ(testing::runProcess(withOption(downstreamArgs(c.out), option, value)), 2) << option;
  EXPECT_FALSE(fs::exists(c.out + "/pool"));
}

}  // namespace
}  // namespace paircast
