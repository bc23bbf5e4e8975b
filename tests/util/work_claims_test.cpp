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
    auto claim = WorkClaim::tryTake(path);
    if (!claim) _exit(3);
    usleep(300 * 1000);
    std::ofstream(released) << "1";  // written while it still holds the claim
    _exit(0);
  }
  // Until the child holds it, take() could win; wait for that first.
  while (WorkClaim::tryTake(path).has_value()) usleep(1000);
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
  // $0 is the flag, $1 the worker's index.
  const std::string script =
      "echo \"$0 $1 $OMP_NUM_THREADS $PAIRCAST_WORKER_PARENT\" > " + dir + "/worker-$1";
  runWorkerProcesses({"/bin/sh", "-c", script}, "--worker", 3, 2);
  for (int k = 1; k <= 3; ++k) {
    std::ifstream in(dir + "/worker-" + std::to_string(k));
    std::string flag, parent;
    int index = 0, threads = 0;
    in >> flag >> index >> threads >> parent;
    EXPECT_EQ(flag, "--worker");
    EXPECT_EQ(index, k);
    EXPECT_EQ(threads, 2);
    EXPECT_EQ(parent, std::to_string(getpid()));
  }
}

TEST(WorkerProcesses, TheFirstFailureIsNamedAfterAllHaveEnded) {
  const std::string dir = testing::scratchDir("workers");
  // Worker 1 fails at once; worker 2 runs on, and must have ended when the error comes.
  const std::string script =
      "if [ $1 = 1 ]; then exit 4; fi; sleep 0.3; echo done > " + dir + "/second";
  EXPECT_ERROR_CONTAINS(runWorkerProcesses({"/bin/sh", "-c", script}, "--worker", 2, 1),
                        "worker 1 of 2 (pid ", ") exited with status 4");
  EXPECT_TRUE(fs::exists(dir + "/second"));
  EXPECT_ERROR_CONTAINS(
      runWorkerProcesses({"/bin/sh", "-c", "[ $1 = 2 ] && kill -9 $$; exit 0"}, "-w", 2, 1),
      "worker 2 of 2", "was killed by Killed");
  EXPECT_ERROR_CONTAINS(runWorkerProcesses({"/nonexistent/covis_sweep"}, "--worker", 1, 1),
                        "/nonexistent/covis_sweep: cannot start a worker: No such file");
}

TEST(WorkerProcesses, SigintToUsReachesThemAndTheyStop) {
  const std::string dir = testing::scratchDir("workers");
  // Each worker waits for SIGINT, notes it, and exits 0; we send ours to this process.
  const std::string script = "trap 'echo int > " + dir + "/int-$1; exit 0' INT; touch " + dir +
                             "/up-$1; while true; do sleep 0.05; done";
  const pid_t self = getpid();
  const pid_t sender = fork();
  if (sender == 0) {
    for (int i = 0; i < 2000 && !(fs::exists(dir + "/up-1") && fs::exists(dir + "/up-2")); ++i)
      usleep(10 * 1000);
    kill(self, SIGINT);
    _exit(0);
  }
  runWorkerProcesses({"/bin/sh", "-c", script}, "--worker", 2, 1);
  waitpid(sender, nullptr, 0);
  EXPECT_TRUE(fs::exists(dir + "/int-1"));
  EXPECT_TRUE(fs::exists(dir + "/int-2"));
  // Our own SIGINT handling is back as it was (gtest's default: none).
  struct sigaction now {};
  sigaction(SIGINT, nullptr, &now);
  EXPECT_EQ(now.sa_handler, SIG_DFL);
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
