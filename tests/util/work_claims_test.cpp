#include "util/work_claims.h"

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "test_errors.h"
#include "test_paths.h"
#include "util/atomic_file.h"

namespace paircast {
namespace {

namespace fs = std::filesystem;

// A child process that takes the claim, tells us through a pipe, then waits for SIGKILL.
pid_t holdInChild(const std::string& path) {
  int ready[2];
  EXPECT_EQ(pipe(ready), 0);
  const pid_t pid = fork();
  if (pid == 0) {
    auto claim = WorkClaim::tryTake(path);
    const char c = claim ? 'y' : 'n';
    (void)!write(ready[1], &c, 1);
    while (true) pause();
  }
  close(ready[1]);
  char c = 0;
  EXPECT_EQ(read(ready[0], &c, 1), 1);
  close(ready[0]);
  EXPECT_EQ(c, 'y');
  return pid;
}

TEST(WorkClaim, IsExclusiveUntilItsHolderLetsGo) {
  const std::string path = testing::scratchDir("claims") + "/sub/run-seed-0.lock";
  {
    auto first = WorkClaim::tryTake(path);  // makes the folder
    ASSERT_TRUE(first.has_value());
    EXPECT_FALSE(WorkClaim::tryTake(path).has_value()) << "a second open must not take it";
    const WorkClaim moved = std::move(*first);
    first.reset();  // the moved-from claim holds nothing: releasing it changes nothing
    EXPECT_FALSE(WorkClaim::tryTake(path).has_value());
  }
  EXPECT_TRUE(WorkClaim::tryTake(path).has_value());
}

TEST(WorkClaim, AKilledHolderLeavesItFree) {
  const std::string path = testing::scratchDir("claims") + "/a.lock";
  const pid_t child = holdInChild(path);
  EXPECT_FALSE(WorkClaim::tryTake(path).has_value());
  kill(child, SIGKILL);
  waitpid(child, nullptr, 0);
  EXPECT_TRUE(WorkClaim::tryTake(path).has_value());
}

TEST(WorkClaim, TakeWaitsForTheHolder) {
  const std::string dir = testing::scratchDir("claims");
  const std::string path = dir + "/a.lock", released = dir + "/released";
  const pid_t pid = fork();
  if (pid == 0) {
    const WorkClaim claim = WorkClaim::take(path);
    usleep(300 * 1000);
    std::ofstream(released) << "1";  // written while it still holds the claim
    _exit(0);
  }
  // Until the child holds it, take() could win; wait for that first.
  for (int i = 0; i < 10000 && WorkClaim::tryTake(path).has_value(); ++i) usleep(1000);
  ASSERT_FALSE(WorkClaim::tryTake(path).has_value()) << "the child never took the claim";
  const WorkClaim claim = WorkClaim::take(path);
  EXPECT_TRUE(fs::exists(released)) << "take() returned while the child held the claim";
  int status = 0;
  waitpid(pid, &status, 0);
  EXPECT_EQ(WEXITSTATUS(status), 0);
}

TEST(WorkClaim, AnUnwritableFolderIsNamed) {
  const std::string dir = testing::scratchDir("claims");
  writeFileAtomic(dir + "/file", "x");
  EXPECT_ERROR_CONTAINS(WorkClaim::tryTake(dir + "/file/a.lock"),
                        dir + "/file/a.lock: cannot open the claim file");
}

TEST(WorkerProcesses, EachGetsItsIndexItsThreadsAndOurPid) {
  const std::string dir = testing::scratchDir("workers");
  // $0 is argv[0] ("sh"); the flag and the worker's index follow.
  const std::string script =
      "echo \"$1 $2 $OMP_NUM_THREADS $OPENBLAS_NUM_THREADS "
      "$PAIRCAST_WORKER_PARENT\" > " +
      dir + "/worker-$2";
  setenv("OPENBLAS_NUM_THREADS", "7", 1);  // ours is replaced, not added to
  runWorkerProcesses("/bin/sh", {"sh", "-c", script, "sh"}, "--worker", 3, 2);
  unsetenv("OPENBLAS_NUM_THREADS");
  for (int k = 1; k <= 3; ++k) {
    std::ifstream in(dir + "/worker-" + std::to_string(k));
    std::string flag, parent;
    int index = 0, threads = 0, blasThreads = 0;
    in >> flag >> index >> threads >> blasThreads >> parent;
    EXPECT_EQ(flag, "--worker");
    EXPECT_EQ(index, k);
    EXPECT_EQ(threads, 2);
    EXPECT_EQ(blasThreads, 2);
    EXPECT_EQ(parent, std::to_string(getpid()));
  }
}

// A worker script that notes the signals `traps` in DIR/<mark>-$2 and exits 0, once it has
// touched DIR/up-$2; it gives up after 20 s.
std::string waitForSignals(const std::string& dir, const std::string& traps,
                           const std::string& mark) {
  return "trap 'echo > " + dir + "/" + mark + "-$2; exit 0' " + traps + "; touch " + dir +
         "/up-$2; i=0; while [ $i -lt 400 ]; do sleep 0.05; i=$((i+1)); done; exit 9";
}

// The bits of SIGINT and SIGTERM in a /proc/<pid>/status mask ("SigBlk:\t0000000000004002").
uint64_t stopBits(const std::string& line) {
  const uint64_t mask = std::stoull(line.substr(line.find(':') + 1), nullptr, 16);
  return mask & ((uint64_t{1} << (SIGINT - 1)) | (uint64_t{1} << (SIGTERM - 1)));
}

TEST(WorkerProcesses, TheyHearSigintAndSigtermThoughWeBlockOrIgnoreThem) {
  const std::string dir = testing::scratchDir("workers");
  // As a shell's background job ignores SIGINT; and SIGTERM blocked, as while spawning.
  struct sigaction ignore {};
  struct sigaction oldInt {};
  ignore.sa_handler = SIG_IGN;
  sigaction(SIGINT, &ignore, &oldInt);
  sigset_t term, oldMask;
  sigemptyset(&term);
  sigaddset(&term, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &term, &oldMask);
  // Python, not a shell: a shell may unblock signals itself, and so hide what it was given.
  const std::string copyStatus =
      "import sys; open('" + dir +
      "/sig-' + sys.argv[2], 'w').write(open('/proc/self/status').read())";
  runWorkerProcesses("/usr/bin/python3", {"python3", "-c", copyStatus}, "--worker", 2, 1);
  pthread_sigmask(SIG_SETMASK, &oldMask, nullptr);
  sigaction(SIGINT, &oldInt, nullptr);
  for (int k = 1; k <= 2; ++k) {
    std::ifstream in(dir + "/sig-" + std::to_string(k));
    std::string line;
    int masks = 0;
    while (std::getline(in, line)) {
      if (line.rfind("SigBlk:", 0) != 0 && line.rfind("SigIgn:", 0) != 0) continue;
      ++masks;
      EXPECT_EQ(stopBits(line), 0u) << "worker " << k << ": " << line;
    }
    EXPECT_EQ(masks, 2) << "worker " << k;
  }
}

TEST(WorkerProcesses, TheFirstFailureIsNamedAndStopsTheOthers) {
  const std::string dir = testing::scratchDir("workers");
  const std::string script = "if [ $2 = 2 ]; then while [ ! -e " + dir +
                             "/up-1 ]; do sleep 0.01; done; exit 4; fi; " +
                             waitForSignals(dir, "TERM", "term");
  EXPECT_ERROR_CONTAINS(runWorkerProcesses("/bin/sh", {"sh", "-c", script, "sh"}, "--w", 2, 1),
                        "worker 2 of 2 (pid ", ") exited with status 4");
  EXPECT_TRUE(fs::exists(dir + "/term-1")) << "worker 1 was not stopped";
  EXPECT_ERROR_CONTAINS(
      runWorkerProcesses("/bin/sh", {"sh", "-c", "[ $2 = 2 ] && kill -9 $$; exit 0", "sh"}, "-w", 2,
                         1),
      "worker 2 of 2", "was killed by Killed");
  EXPECT_ERROR_CONTAINS(
      runWorkerProcesses("/nonexistent/covis_sweep", {"covis_sweep"}, "--worker", 1, 1),
      "/nonexistent/covis_sweep: cannot start a worker of covis_sweep: No such file");
}

TEST(WorkerProcesses, SignalsToUsReachThemAndEndTheWait) {
  const std::string dir = testing::scratchDir("workers");
  for (int sig : {SIGINT, SIGTERM}) {
    // Each worker notes the signal and exits 0; the wait still ends in an error.
    const std::string script = waitForSignals(dir, "INT TERM", "sig");
    const pid_t self = getpid();
    const pid_t sender = fork();
    if (sender == 0) {
      for (int i = 0; i < 2000 && !(fs::exists(dir + "/up-1") && fs::exists(dir + "/up-2")); ++i)
        usleep(10 * 1000);
      kill(self, sig);
      _exit(0);
    }
    EXPECT_ERROR_CONTAINS(
        runWorkerProcesses("/bin/sh", {"sh", "-c", script, "sh"}, "--worker", 2, 1),
        std::string("stopped by ") + strsignal(sig));
    waitpid(sender, nullptr, 0);
    for (const char* f : {"/sig-1", "/sig-2", "/up-1", "/up-2"}) {
      EXPECT_TRUE(fs::exists(dir + f)) << f << " " << sig;
      fs::remove(dir + f);
    }
    // Our own handling is back as it was (gtest's default: none).
    struct sigaction now {};
    sigaction(sig, nullptr, &now);
    EXPECT_EQ(now.sa_handler, SIG_DFL);
  }
}

TEST(WorkerProcesses, AWorkerHearsItsStopAndItsParentsEnd) {
  const std::string dir = testing::scratchDir("workers");
  // A worker of this process: SIGTERM is a request it reads, not its end.
  const pid_t worker = fork();
  if (worker == 0) {
    setenv("PAIRCAST_WORKER_PARENT", std::to_string(getppid()).c_str(), 1);
    stopWithParent();
    const bool before = workerShouldStop();
    raise(SIGTERM);
    _exit(!before && workerShouldStop() ? 0 : 1);
  }
  int status = 0;
  waitpid(worker, &status, 0);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
  // A worker whose parent ends: it hears it.
  const pid_t parent = fork();
  if (parent == 0) {
    const pid_t child = fork();
    if (child == 0) {
      setenv("PAIRCAST_WORKER_PARENT", std::to_string(getppid()).c_str(), 1);
      stopWithParent();
      std::ofstream(dir + "/started") << "1";
      for (int i = 0; i < 1000 && !workerShouldStop(); ++i) usleep(10 * 1000);
      if (workerShouldStop()) std::ofstream(dir + "/heard") << "1";
      _exit(0);
    }
    for (int i = 0; i < 1000 && !fs::exists(dir + "/started"); ++i) usleep(10 * 1000);
    _exit(0);
  }
  waitpid(parent, nullptr, 0);
  for (int i = 0; i < 1000 && !fs::exists(dir + "/heard"); ++i) usleep(10 * 1000);
  EXPECT_TRUE(fs::exists(dir + "/heard"));
}

TEST(WorkerProcesses, AWorkerStartedByHandIsRefused) {
  unsetenv("PAIRCAST_WORKER_PARENT");
  EXPECT_ERROR_CONTAINS(stopWithParent(), "PAIRCAST_WORKER_PARENT is not set");
  setenv("PAIRCAST_WORKER_PARENT", "1", 1);  // not our parent: it is gone, as far as we know
  EXPECT_ERROR_CONTAINS(stopWithParent(), "the process that started this worker (pid 1) is gone");
  unsetenv("PAIRCAST_WORKER_PARENT");
  prctl(PR_SET_PDEATHSIG, 0);  // stopWithParent set it on the test process
}

}  // namespace
}  // namespace paircast
