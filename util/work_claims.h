// Independent processes that share one list of work: each unit is claimed with an advisory lock
// (flock) on a file of its own, held while the unit runs and released when its holder exits or
// dies, so a killed process never leaves a unit claimed. And the processes themselves: the
// command run again as N workers, each on cores / N threads, waited for as one.
#pragma once

#include <sys/types.h>

#include <optional>
#include <string>
#include <vector>

namespace paircast {

class WorkClaim {
 public:
  // The claim on `path` (created, with its folder), or nothing when another process holds it.
  static std::optional<WorkClaim> tryTake(const std::string& path);
  // Waits for whoever holds `path` to let it go, then holds it.
  static WorkClaim take(const std::string& path);

  WorkClaim(WorkClaim&& other) noexcept;
  WorkClaim& operator=(WorkClaim&&) = delete;
  WorkClaim(const WorkClaim&) = delete;
  ~WorkClaim();

 private:
  explicit WorkClaim(int fd) : fd_(fd) {}
  int fd_ = -1;
};

// Runs `command` (argv[0] a path) as `count` processes at once, the k-th (1-based) with
// `workerFlag` k appended, OMP_NUM_THREADS set to `threads` and PAIRCAST_WORKER_PARENT to our
// pid, their output going where ours does. SIGINT and SIGTERM sent to this process meanwhile are
// passed on to them (they save and stop). Returns once all have exited; throws an Error naming the
// first that failed, or that was stopped by a signal.
void runWorkerProcesses(const std::vector<std::string>& command, const std::string& workerFlag,
                        int count, int threads);

// For a worker that runWorkerProcesses started: it is sent SIGTERM when that process dies.
// Throws when it is already gone, or when this process was not started so.
void stopWithParent();

// The path of the running executable (/proc/self/exe).
std::string selfExecutable();

}  // namespace paircast
