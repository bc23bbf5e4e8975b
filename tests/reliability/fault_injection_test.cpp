// Fault injection: generate_pairs and pretrain killed at random points and during writes, and a
// full disk. Whatever happens, nothing already written is lost or left half-written, and a
// resumed run ends with the bytes of an uninterrupted one.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <map>
#include <random>
#include <set>

#include "dataset/shard.h"
#include "model/checkpoint.h"
#include "test_files.h"
#include "test_paths.h"
#include "test_process.h"
#include "util/atomic_file.h"
#include "util/error.h"

namespace paircast {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

std::string tool(const char* name) {
  return std::string(PAIRCAST_BINARY_DIR) + "/tools/" + name;
}

// Shards under their final names are always whole, and hold each key once.
void expectWholeShards(const std::string& dir) {
  if (!fs::exists(dir)) return;  // killed before it made its folder
  std::set<std::string> keys;
  for (const auto& e : fs::directory_iterator(dir)) {
    if (e.path().extension() != ".tar" || e.path().filename().string()[0] == '.') continue;
    size_t errors = 0;
    EXPECT_NO_THROW(readShard(
        e.path().string(),
        [&](ShardSample&& s) { EXPECT_TRUE(keys.insert(s.key).second) << s.key << " twice"; },
        [&](const std::string&) { ++errors; }))
        << e.path();
    EXPECT_EQ(errors, 0u) << e.path();
  }
}

std::vector<std::string> generateArgs(const std::string& out) {
  const std::string s = testing::sourceDir() + "/scenes/";
  return {tool("generate_pairs"),
          "--scenes",
          s + "room",
          s + "studio",
          "--out",
          out,
          "--pairs-per-scene",
          "24",
          "--resolution",
          "64",
          "--shard-size",
          "5",
          "--format",
          "both",
          "--seed",
          "11",
          "--jobs",
          "2",
          "--quiet"};
}

TEST(FaultInjection, GeneratePairsSurvivesTwentyRandomKills) {
  const std::string dir = testing::scratchDir("gen");
  const auto t0 = Clock::now();
  ASSERT_EQ(testing::runProcess(generateArgs(dir + "/clean")), 0);
  const int cleanMs = static_cast<int>(
      std::chrono::duration_cast<std::chrono::milliseconds>(Clock::now() - t0).count());
  const auto clean = testing::fileTree(dir + "/clean");
  std::mt19937 rng(20261122);
  // Random kill times over the whole run; when a run completes, start a new output, so that
  // every one of the 20 kills lands somewhere in a run.
  int kills = 0, outputs = 0;
  std::string out = dir + "/killed0";
  while (kills < 20) {
    const int delay = std::uniform_int_distribution<int>(10, std::max(20, cleanMs))(rng);
    const int rc = testing::runProcess(generateArgs(out), delay);
    if (rc == -SIGKILL) {
      ++kills;
      expectWholeShards(out);
      continue;
    }
    ASSERT_EQ(rc, 0) << "generate_pairs failed after a kill";
    EXPECT_EQ(testing::fileTree(out), clean) << out << " differs from the clean run";
    out = dir + "/killed" + std::to_string(++outputs);
  }
  ASSERT_EQ(testing::runProcess(generateArgs(out)), 0);
  const auto last = testing::fileTree(out);
  EXPECT_EQ(last.size(), clean.size());
  EXPECT_TRUE(last == clean) << "the output after the last kill differs from the clean run";
  for (const auto& [name, bytes] : last)
    EXPECT_EQ(name.find(".tmp."), std::string::npos) << "temporary file left: " << name;
  RecordProperty("kills", kills);
}

std::vector<std::string> pretrainArgs(const std::string& data, const std::string& out, int steps) {
  return {tool("pretrain"),
          "--data",
          data + "/pairs-*.tar",
          "--preset",
          "tiny",
          "--img-size",
          "32",
          "--batch-size",
          "4",
          "--epochs",
          "3",
          "--max-steps",
          std::to_string(steps),
          "--save-every",
          "2",
          "--workers",
          "1",
          "--out",
          out,
          "--resume",
          "--quiet"};
}

TEST(FaultInjection, PretrainKilledDuringACheckpointWriteKeepsThePreviousOne) {
  const std::string dir = testing::scratchDir("ckpt");
  ASSERT_EQ(testing::runProcess(generateArgs(dir + "/pairs")), 0);
  // Reference: 8 steps in one go.
  ASSERT_EQ(testing::runProcess(pretrainArgs(dir + "/pairs", dir + "/whole", 8)), 0);
  // 4 steps, then a run that dies half-way through writing its checkpoint at step 6.
  const std::string out = dir + "/killed";
  ASSERT_EQ(testing::runProcess(pretrainArgs(dir + "/pairs", out, 4)), 0);
  const std::string before = readFile(out + "/checkpoint-last.pth");
  const int rc = testing::runProcess(pretrainArgs(dir + "/pairs", out, 8), -1,
                                     {"PAIRCAST_FAULT_KILL_DURING_WRITE=checkpoint-last.pth"});
  ASSERT_EQ(rc, -SIGKILL) << "the fault point did not fire";
  // The previous checkpoint is intact; the half-written one is a temporary beside it.
  EXPECT_EQ(readFile(out + "/checkpoint-last.pth"), before);
  EXPECT_EQ(loadCheckpoint(out + "/checkpoint-last.pth").extra["step"], 4);
  bool temporary = false;
  for (const auto& e : fs::directory_iterator(out))
    temporary |= e.path().filename().string().find(".tmp.") != std::string::npos;
  EXPECT_TRUE(temporary) << "the fault point should leave a half-written temporary";
  // Resuming removes it and ends with the weights of the uninterrupted run, bit for bit.
  ASSERT_EQ(testing::runProcess(pretrainArgs(dir + "/pairs", out, 8)), 0);
  for (const auto& e : fs::directory_iterator(out))
    EXPECT_EQ(e.path().filename().string().find(".tmp."), std::string::npos) << e.path();
  const Checkpoint a = loadCheckpoint(dir + "/whole/checkpoint-last.pth");
  const Checkpoint b = loadCheckpoint(out + "/checkpoint-last.pth");
  for (const auto& [k, t] : a.model) EXPECT_TRUE(torch::equal(t, b.model.at(k))) << k;
}

// Runs a tool with a file-size limit, which makes writes fail as on a full disk (EFBIG).
int runWithFileLimit(const std::vector<std::string>& args, rlim_t bytes, std::string* stderrText) {
  int pipefd[2];
  if (pipe(pipefd) != 0) return -1000;
  const pid_t pid = fork();
  if (pid == 0) {
    signal(SIGXFSZ, SIG_IGN);  // inherited through exec: write() returns EFBIG instead
    rlimit lim{bytes, bytes};
    setrlimit(RLIMIT_FSIZE, &lim);
    dup2(pipefd[1], 2);
    close(pipefd[0]);
    std::vector<char*> argv;
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    execv(argv[0], argv.data());
    _exit(127);
  }
  close(pipefd[1]);
  char buf[4096];
  ssize_t n;
  while ((n = read(pipefd[0], buf, sizeof buf)) > 0) stderrText->append(buf, n);
  close(pipefd[0]);
  return testing::waitProcess(pid);
}

TEST(FaultInjection, FullDiskIsACleanErrorWithNoHalfWrittenShard) {
  const std::string dir = testing::scratchDir("full");
  std::vector<std::string> args = generateArgs(dir + "/out");
  args[std::find(args.begin(), args.end(), "--shard-size") - args.begin() + 1] = "100";
  std::string err;
  const int rc = runWithFileLimit(args, 20000, &err);
  EXPECT_EQ(rc, 1) << err;
  // One line, naming the file that could not be written.
  ASSERT_FALSE(err.empty());
  const std::string lastLine = err.substr(err.rfind('\n', err.size() - 2) + 1);
  EXPECT_NE(lastLine.find("generate_pairs: error: "), std::string::npos) << err;
  EXPECT_NE(lastLine.find(dir + "/out"), std::string::npos) << err;
  expectWholeShards(dir + "/out");
  for (const auto& e : fs::recursive_directory_iterator(dir + "/out"))
    EXPECT_EQ(e.path().filename().string().find(".tmp."), std::string::npos)
        << "temporary left behind: " << e.path();
  // With room again, the same command finishes the job.
  EXPECT_EQ(testing::runProcess(args), 0);
  expectWholeShards(dir + "/out");
}

}  // namespace
}  // namespace paircast
