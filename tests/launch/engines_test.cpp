// The commands under the engines users run them with: a real one-node Slurm cluster (slurmctld and
// slurmd, started and stopped by each test through slurm_cluster.sh) and torchrun. Each checks
// that what the engine starts equals what the flags or variables given by hand make.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <thread>

#include "dataset/generate_job.h"
#include "test_checkpoints.h"
#include "test_files.h"
#include "test_pairs.h"
#include "test_paths.h"
#include "test_process.h"
#include "util/atomic_file.h"

namespace paircast {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double secondsSince(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

std::string shellQuoted(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

std::string joined(const std::vector<std::string>& args) {
  std::string line;
  for (const auto& a : args) line += (line.empty() ? "" : " ") + shellQuoted(a);
  return line;
}

struct Output {
  int status = -1;
  std::string text;  // stdout and stderr
};

// Runs `command` through sh; every command here carries its own `timeout`.
Output shell(const std::string& command) {
  Output out;
  FILE* p = popen((command + " 2>&1").c_str(), "r");
  if (!p) return out;
  char buf[4096];
  for (size_t n; (n = std::fread(buf, 1, sizeof buf, p)) > 0;) out.text.append(buf, n);
  const int status = pclose(p);
  out.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return out;
}

std::string binary(const std::string& tool) {
  return std::string(PAIRCAST_BINARY_DIR) + "/tools/" + tool;
}

// The text of `path`, or "" when there is none (for failure messages).
std::string textOf(const std::string& path) {
  std::error_code ec;
  return fs::exists(path, ec) ? readFile(path) : std::string();
}

// A one-node cluster for the life of the object (tests/launch/slurm_cluster.sh), in a short
// folder of its own under /tmp: slurmd's sockets go there, and their paths hold 108 bytes at
// most. The folder stays when the test failed, for its logs.
class SlurmCluster {
 public:
  SlurmCluster() : dir_(shortTempDir()), started_(Clock::now()) {
    if (dir_.empty()) {
      startLog_ = "mkdtemp in /tmp failed";
      return;
    }
    // Status 3 is the script's "Slurm can't run here", the one skip. Anything else (1: it died,
    // 2: a syntax error, 126: not executable, 127: missing) is a broken script: the test fails.
    const Output check = shell(script() + " check");
    if (check.status == 3) {
      skip_ = check.text.empty() ? "slurm_cluster.sh check: Slurm can't run here" : check.text;
      return;
    }
    if (check.status != 0) {
      startLog_ = "slurm_cluster.sh check exited " + std::to_string(check.status) +
                  " (3 would mean Slurm can't run here): " + check.text;
      return;
    }
    // Ports from the test's pid, below the ephemeral range: parallel test runs do not meet.
    const int port = 30000 + static_cast<int>(getpid() % 1300) * 2;
    starting_ = true;
    const Output start = shell("timeout 60 " + script() + " start " + shellQuoted(dir_) + " " +
                               std::to_string(port));
    up_ = start.status == 0;
    startLog_ = start.text;
    upSeconds_ = secondsSince(started_);
  }
  // Stops whatever the start got to, even if it was cut short by its timeout.
  ~SlurmCluster() {
    if (dir_.empty()) return;
    if (!starting_) {
      fs::remove_all(dir_);
      return;
    }
    const auto stopping = Clock::now();
    shell("timeout 60 " + script() + " stop " + shellQuoted(dir_));
    // Start to stop is about the whole test: the cluster is its first and last step.
    std::printf("[ slurm ] cluster up in %.1f s, down in %.1f s, start to stop %.1f s\n",
                upSeconds_, secondsSince(stopping), secondsSince(started_));
    if (::testing::Test::HasFailure())
      std::printf("[ slurm ] its configuration and logs: %s\n", dir_.c_str());
    else
      fs::remove_all(dir_);
  }
  const std::string& skipReason() const { return skip_; }
  bool up() const { return up_; }
  const std::string& startLog() const { return startLog_; }
  // A Slurm command line (sbatch ..., srun ..., with VAR=value before it for its environment)
  // against this cluster, within `seconds`.
  Output run(const std::string& command, int seconds) const {
    return shell("SLURM_CONF=" + shellQuoted(dir_ + "/slurm.conf") + " timeout -k 5 " +
                 std::to_string(seconds) + " env " + command);
  }
  // Waits until the queue holds nothing of `job` (all of it with "" ); false after `seconds`.
  bool waitForEmptyQueue(const std::string& job, int seconds) const {
    for (const auto end = Clock::now() + std::chrono::seconds(seconds); Clock::now() < end;
         std::this_thread::sleep_for(std::chrono::milliseconds(200))) {
      const Output q = run("squeue -h -o %i" + (job.empty() ? "" : " -j " + job), 10);
      if (q.status == 0 && q.text.find_first_not_of(" \n") == std::string::npos) return true;
    }
    return false;
  }

 private:
  static std::string shortTempDir() {
    char name[] = "/tmp/paircast-slurm.XXXXXX";
    return mkdtemp(name) ? name : "";
  }
  static std::string script() {
    return shellQuoted(testing::sourceDir() + "/tests/launch/slurm_cluster.sh");
  }
  std::string dir_, skip_, startLog_;
  Clock::time_point started_;
  double upSeconds_ = 0;
  bool starting_ = false, up_ = false;
};

#define START_SLURM(cluster)                                               \
  SlurmCluster cluster;                                                    \
  if (!cluster.skipReason().empty()) GTEST_SKIP() << cluster.skipReason(); \
  ASSERT_TRUE(cluster.up()) << cluster.startLog()

// ---- generation ----

// generate_pairs over `scenes` into `out` with `extra` arguments: tiny, fast pairs.
// generate_pairs' options besides --scenes and --out: tiny, fast pairs.
std::vector<std::string> pairArgs(int pairs) {
  return {"--pairs-per-scene",
          std::to_string(pairs),
          "--resolution",
          "32",
          "--shard-size",
          "5",
          "--format",
          "both",
          "--seed",
          "5"};
}

// The whole command line of generate_pairs over `scenes` into `out`.
std::vector<std::string> generateCommand(const std::string& scenes, const std::string& out,
                                         int pairs) {
  std::vector<std::string> args = {binary("generate_pairs"), "--scenes", scenes, "--out", out};
  for (const auto& a : pairArgs(pairs)) args.push_back(a);
  return args;
}

// The parts run by hand, one after the other, with --shard-index i --num-shards n.
void runPartsByHand(const std::string& scenes, const std::string& out, int pairs, int parts) {
  for (int i = 0; i < parts; ++i) {
    auto args = generateCommand(scenes, out, pairs);
    args.insert(args.end(), {"--jobs", "1", "--quiet", "--shard-index", std::to_string(i),
                             "--num-shards", std::to_string(parts)});
    ASSERT_EQ(testing::runProcess(args), 0) << "part " << i << " by hand";
  }
}

// `sbatch --wait` (or `--parsable`, not waiting) of the example array script over `scenes` into
// `out`, with `args` for generate_pairs; the tasks' output in dir/generate-<task>.out.
Output sbatchGenerate(const SlurmCluster& cluster, const std::string& dir,
                      const std::string& scenes, const std::string& out, const std::string& array,
                      const std::vector<std::string>& args, bool wait = true) {
  const std::string env = "PAIRCAST=" + shellQuoted(testing::sourceDir()) +
                          " PAIRCAST_BUILD=" + shellQuoted(PAIRCAST_BINARY_DIR) +
                          " SCENES=" + shellQuoted(scenes) + " OUT=" + shellQuoted(out);
  return cluster.run(env + " sbatch " + (wait ? "--wait" : "--parsable") + " --array=" + array +
                         " --cpus-per-task=1 --chdir=" + shellQuoted(dir) +
                         " --output=" + shellQuoted(dir + "/generate-%a.out") + " " +
                         shellQuoted(testing::sourceDir() + "/scripts/slurm/generate.sbatch") +
                         " " + joined(args),
                     240);
}

// `a` and `b` hold the same files, byte for byte (the summaries' timings aside), and the same
// journal records for each part.
void expectSameFolders(const std::string& a, const std::string& b, int parts) {
  for (int i = 0; i < parts; ++i) {
    const std::string journal = "/.paircast/journal-" + std::to_string(i) + ".jsonl";
    EXPECT_EQ(testing::journalRecords(a + journal), testing::journalRecords(b + journal))
        << journal;
  }
  const auto x = testing::fileTree(a), y = testing::fileTree(b);
  EXPECT_GT(x.size(), 10u);
  EXPECT_EQ(x.size(), y.size());
  for (const auto& [name, bytes] : x) {
    ASSERT_TRUE(y.count(name)) << name << " missing";
    EXPECT_TRUE(bytes == y.at(name)) << name << " differs";
  }
}

// The members of our ustar shards (name -> bytes) in `dir`.
std::map<std::string, std::string> shardMembers(const std::string& dir) {
  std::map<std::string, std::string> members;
  for (const auto& e : fs::directory_iterator(dir)) {
    if (e.path().extension() != ".tar") continue;
    const std::string tar = readFile(e.path().string());
    for (size_t at = 0; at + 512 <= tar.size() && tar[at] != '\0';) {
      const std::string name(tar.c_str() + at);
      const size_t size = std::stoul(tar.substr(at + 124, 12), nullptr, 8);
      members[name] = tar.substr(at + 512, size);
      at += 512 + (size + 511) / 512 * 512;
    }
  }
  return members;
}

std::multiset<std::string> lines(const std::string& text) {
  std::multiset<std::string> out;
  std::istringstream in(text);
  for (std::string l; std::getline(in, l);) out.insert(l);
  return out;
}

// The parts in `split` together hold what one machine's run in `whole` made: the same samples
// in the shards, the same CroCo files, the same lines of pairs.txt.
void expectUnionIsOneMachine(const std::string& split, const std::string& whole, int parts) {
  EXPECT_EQ(shardMembers(split), shardMembers(whole));
  std::string pairs;
  for (int i = 0; i < parts; ++i) pairs += readFile(split + "/pairs-" + std::to_string(i) + ".txt");
  EXPECT_EQ(lines(pairs), lines(readFile(whole + "/pairs.txt")));
  const auto a = testing::fileTree(split), b = testing::fileTree(whole);
  size_t sceneFiles = 0;
  for (const auto& [name, bytes] : b) {
    if (name.find('/') == std::string::npos) continue;  // shards, indexes, pairs.txt: above
    ++sceneFiles;
    ASSERT_TRUE(a.count(name)) << name << " missing from the parts";
    EXPECT_TRUE(bytes == a.at(name)) << name << " differs";
  }
  EXPECT_GT(sceneFiles, 3u * 2);
}

std::string scenesDir() {
  return testing::sourceDir() + "/scenes";
}

TEST(Slurm, ArrayOfGeneratePairsWritesTheUnionOfOneMachine) {
  const std::string dir = testing::scratchDir("array");
  START_SLURM(cluster);
  // --array=1-3: an array need not start at 0; task 1 is part 0.
  const Output sbatch =
      sbatchGenerate(cluster, dir, scenesDir(), dir + "/slurm", "1-3", pairArgs(12));
  ASSERT_EQ(sbatch.status, 0) << sbatch.text << textOf(dir + "/generate-1.out");
  for (int task = 1; task <= 3; ++task) {
    const std::string log = textOf(dir + "/generate-" + std::to_string(task) + ".out");
    EXPECT_EQ(log.rfind("generate_pairs: part " + std::to_string(task - 1) +
                            " of 3, from the Slurm array (SLURM_ARRAY_TASK_ID=" +
                            std::to_string(task) + " - SLURM_ARRAY_TASK_MIN=1",
                        0),
              0u)
        << "the first line says where the part came from: " << log;
  }
  // The same bytes as the parts run by hand with the flags, and as one machine's run.
  runPartsByHand(scenesDir(), dir + "/flags", 12, 3);
  expectSameFolders(dir + "/flags", dir + "/slurm", 3);
  auto whole = generateCommand(scenesDir(), dir + "/whole", 12);
  whole.insert(whole.end(), {"--jobs", "2", "--quiet"});
  ASSERT_EQ(testing::runProcess(whole), 0);
  expectUnionIsOneMachine(dir + "/slurm", dir + "/whole", 3);
}

TEST(Slurm, ArrayTasksWithoutASceneFailWithOneLineAndSbatchWaitFails) {
  const std::string dir = testing::scratchDir("empty");
  START_SLURM(cluster);
  // One scene, two tasks: task 1 has nothing to do.
  auto args = pairArgs(2);
  args.push_back("--quiet");
  const Output sbatch =
      sbatchGenerate(cluster, dir, scenesDir() + "/room", dir + "/out", "0-1", args);
  EXPECT_NE(sbatch.status, 0) << "sbatch --wait succeeded although a task failed: " << sbatch.text;
  EXPECT_EQ(textOf(dir + "/generate-1.out"),
            "generate_pairs: error: part 1 of 2 has no scene: the scene list has 1 scene(s) for 2 "
            "parts (use at most 1 parts)\n");
  EXPECT_TRUE(fs::exists(dir + "/out/index-0.json")) << "task 0 did its part";
}

TEST(Slurm, ACancelledArrayTaskSubmittedAgainEndsWithTheSameBytes) {
  const std::string dir = testing::scratchDir("cancel");
  START_SLURM(cluster);
  const std::string out = dir + "/slurm";
  const auto args = pairArgs(60);
  const Output submitted = sbatchGenerate(cluster, dir, scenesDir(), out, "0-2", args, false);
  ASSERT_EQ(submitted.status, 0) << submitted.text;
  const std::string job = submitted.text.substr(0, submitted.text.find_first_of(";\n"));
  // Cancel task 1 (the room) while it writes a shard.
  bool writing = false;
  for (const auto end = Clock::now() + std::chrono::seconds(120); !writing && Clock::now() < end;
       std::this_thread::sleep_for(std::chrono::milliseconds(2)))
    writing = testing::hasTemporary(out, "pairs-1-");
  const Output cancel = cluster.run("scancel " + job + "_1", 20);
  EXPECT_EQ(cancel.status, 0) << cancel.text;
  ASSERT_TRUE(cluster.waitForEmptyQueue(job, 180)) << "the array did not end";
  EXPECT_TRUE(writing) << "task 1 was not seen writing a shard: the test did not test cancelling";
  EXPECT_FALSE(fs::exists(out + "/index-1.json")) << "task 1 finished before it was cancelled";
  // Task 1 alone again: with --num-shards, the task id is the part index.
  auto again = args;
  again.insert(again.end(), {"--num-shards", "3"});
  const Output rerun = sbatchGenerate(cluster, dir, scenesDir(), out, "1", again);
  ASSERT_EQ(rerun.status, 0) << rerun.text << textOf(dir + "/generate-1.out");
  runPartsByHand(scenesDir(), dir + "/flags", 60, 3);
  expectSameFolders(dir + "/flags", out, 3);
  for (const auto& e : fs::recursive_directory_iterator(out))
    EXPECT_EQ(e.path().filename().string().find(".tmp."), std::string::npos)
        << "temporary left: " << e.path();
}

// ---- training ----

const std::string& trainingPairs() {
  return testing::roomPairs();
}

// pretrain's arguments after --data and --out: 3 steps of the tiny model at 32x32 (as
// Pretrain.TwoGlooProcessesEqualOneWithTheDoubledBatch).
std::vector<std::string> trainArgs(int batch) {
  // No --workers: pretrain.sbatch gives it from --cpus-per-task (and batches do not depend on it).
  return {"--img-size",  "32", "--batch-size", std::to_string(batch),
          "--max-steps", "3",  "--epochs",     "4",
          "--seed",      "4",  "--amp",        "none"};  // bf16 rounds each rank's half apart
}

// One process with the doubled batch, into `out`.
void trainAlone(const std::string& out) {
  std::vector<std::string> args = {
      binary("pretrain"), "--data", trainingPairs() + "/pairs-*.tar", "--out", out, "--quiet"};
  for (const auto& a : trainArgs(4)) args.push_back(a);
  ASSERT_EQ(testing::runProcess(args), 0);
}

void expectTwoRanksEqualOne(const std::string& one, const std::string& two) {
  EXPECT_LT(testing::weightDifference(one + "/checkpoint-last.pth", two + "/checkpoint-last.pth"),
            1e-5);
  const auto s = nlohmann::json::parse(readFile(two + "/summary.json"));
  EXPECT_EQ(s["world_size"], 2);
}

TEST(Slurm, PretrainSbatchWithTwoSrunTasksEqualsOneProcessWithTheDoubledBatch) {
  const std::string dir = testing::scratchDir("pretrain");
  START_SLURM(cluster);
  trainAlone(dir + "/one");
  // The example script as it is: srun starts one pretrain per task.
  const std::string env = "PAIRCAST=" + shellQuoted(testing::sourceDir()) +
                          " PAIRCAST_BUILD=" + shellQuoted(PAIRCAST_BINARY_DIR) +
                          " DATA=" + shellQuoted(trainingPairs() + "/pairs-*.tar") +
                          " OUT=" + shellQuoted(dir + "/two");
  const Output sbatch =
      cluster.run(env + " sbatch --wait --ntasks=2 --cpus-per-task=1 --chdir=" + shellQuoted(dir) +
                      " --output=" + shellQuoted(dir + "/pretrain.out") + " " +
                      shellQuoted(testing::sourceDir() + "/scripts/slurm/pretrain.sbatch") + " " +
                      joined(trainArgs(2)),
                  300);
  const std::string log = textOf(dir + "/pretrain.out");
  ASSERT_EQ(sbatch.status, 0) << sbatch.text << log;
  for (int r = 0; r < 2; ++r)
    EXPECT_NE(log.find("pretrain: rank " + std::to_string(r) + " of 2 (local rank " +
                       std::to_string(r) + ") from srun"),
              std::string::npos)
        << log;
  expectTwoRanksEqualOne(dir + "/one", dir + "/two");
}

TEST(Torchrun, TwoPretrainProcessesEqualOneWithTheDoubledBatch) {
  const auto began = Clock::now();
  const std::string torchrun = "/usr/bin/torchrun";
  if (!fs::exists(torchrun)) GTEST_SKIP() << torchrun << " is not installed (python3-torch)";
  // Debian 13's torch 2.6 has no libuv, and torchrun's rendezvous asks its TCPStore for libuv
  // whatever USE_LIBUV says: that torchrun starts no job at all.
  const Output store = shell(
      "/usr/bin/python3 -c 'import datetime, torch.distributed as d; "
      "d.TCPStore(\"127.0.0.1\", 0, 1, True, timeout=datetime.timedelta(seconds=10))' 2>&1");
  if (store.text.find("use_libuv was requested") != std::string::npos)
    GTEST_SKIP() << "this torchrun cannot start its rendezvous store (python3-torch built "
                    "without libuv; docs/scale.md, \"torchrun\")";
  ASSERT_EQ(store.status, 0) << store.text;
  const std::string dir = testing::scratchDir("torchrun");
  trainAlone(dir + "/one");
  const std::string port = std::to_string(20000 + (getpid() + 11) % 10000);
  // torch 1.13 on Python 3.11: --redirects and --tee must be maps, or torchrun fails in to_map;
  // --log_dir keeps its logs out of /tmp.
  std::vector<std::string> args = {torchrun,
                                   "--nnodes",
                                   "1",
                                   "--nproc_per_node",
                                   "2",
                                   "--master_addr",
                                   "127.0.0.1",
                                   "--master_port",
                                   port,
                                   "--monitor_interval",
                                   "1",
                                   "--redirects",
                                   "9:1",
                                   "--tee",
                                   "9:1",
                                   "--log_dir",
                                   dir + "/torchrun",
                                   "--no_python",
                                   binary("pretrain"),
                                   "--data",
                                   trainingPairs() + "/pairs-*.tar",
                                   "--out",
                                   dir + "/two"};
  for (const auto& a : trainArgs(2)) args.push_back(a);
  const Output run = shell("timeout -k 5 300 " + joined(args));
  ASSERT_EQ(run.status, 0) << run.text;
  EXPECT_NE(run.text.find("from torchrun"), std::string::npos) << run.text;
  expectTwoRanksEqualOne(dir + "/one", dir + "/two");
  std::printf("[ torchrun ] test wall time %.1f s\n", secondsSince(began));
}

// covis_sweep's smallest sweep: one bin set, one seed.
std::vector<std::string> sweepArgs(const std::string& out) {
  const std::string s = testing::sourceDir();
  return {binary("covis_sweep"),
          "--scenes",
          s + "/scenes/room",
          s + "/scenes/apartment",
          "--heldout",
          s + "/scenes/studio",
          "--out",
          out,
          "--mode",
          "bin",
          "--centers",
          "0.45",
          "--pairs-per-set",
          "16",
          "--batch-size",
          "4",
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
          "--blr",
          "1.5e-4",
          "--jobs",
          "1",
          "--no-reports"};
}

TEST(Slurm, CovisSweepUnderSrunEqualsTheRanksStartedByHand) {
  const std::string dir = testing::scratchDir("sweep");
  START_SLURM(cluster);
  // By hand: the variables, two processes over loopback.
  const std::string port = "MASTER_PORT=" + std::to_string(20000 + (getpid() + 5) % 10000);
  std::vector<pid_t> ranks;
  for (int r = 1; r >= 0; --r)
    ranks.push_back(testing::spawnProcess(
        sweepArgs(dir + "/hand"),
        {"WORLD_SIZE=2", "RANK=" + std::to_string(r), "LOCAL_RANK=" + std::to_string(r),
         "MASTER_ADDR=127.0.0.1", port, "PAIRCAST_SWEEP_WAIT=300"}));
  for (pid_t p : ranks) ASSERT_EQ(testing::waitProcess(p), 0);
  // Under srun, nothing set by hand (--overcommit: never wait for CPUs).
  const Output srun =
      cluster.run("PAIRCAST_SWEEP_WAIT=300 srun -n 2 --overcommit --chdir=" + shellQuoted(dir) +
                      " " + joined(sweepArgs(dir + "/srun")),
                  300);
  ASSERT_EQ(srun.status, 0) << srun.text;
  EXPECT_NE(srun.text.find("covis_sweep: rank 1 of 2 (local rank 1) from srun"), std::string::npos)
      << srun.text;
  const auto hand = nlohmann::json::parse(readFile(dir + "/hand/results.json"));
  const auto slurm = nlohmann::json::parse(readFile(dir + "/srun/results.json"));
  ASSERT_GE(hand["runs"].size(), 1u);
  ASSERT_EQ(hand["runs"].size(), slurm["runs"].size());
  for (size_t i = 0; i < hand["runs"].size(); ++i) {
    const std::string run = hand["runs"][i]["set"].get<std::string>() + "/seed-" +
                            std::to_string(hand["runs"][i]["seed_index"].get<int>());
    EXPECT_LT(testing::weightDifference(dir + "/hand/runs/" + run + "/checkpoint-last.pth",
                                        dir + "/srun/runs/" + run + "/checkpoint-last.pth"),
              1e-5)
        << run;
    EXPECT_NEAR(hand["runs"][i]["xv_loss"].get<double>(), slurm["runs"][i]["xv_loss"].get<double>(),
                1e-4)
        << run;
  }
}

}  // namespace
}  // namespace paircast
