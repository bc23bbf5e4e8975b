// Independent processes that share one list of work: each unit is claimed with an advisory lock
// (flock) on a file of its own, held while the unit runs and released when its holder exits or
// dies, so a killed process never leaves a unit claimed. And the processes themselves: the
// command run again as N workers, each on its share of the threads, waited for as one.
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

// Runs `executable` as `count` processes at once, with the arguments `command` (argv[0]
// included), the k-th (1-based) with `workerFlag` k appended. Each has OMP_NUM_THREADS and
// OPENBLAS_NUM_THREADS set to `threads` and PAIRCAST_WORKER_PARENT to our pid; their output
// goes where ours does. SIGINT and SIGTERM sent to this process meanwhile are passed on to them
// (they save and stop), and then end the wait with an Error. When one fails, the others are sent
// SIGTERM. Returns once all have exited; throws an Error naming the first that failed, or that
// was stopped by a signal.
void runWorkerProcesses(const std::string& executable, const std::vector<std::string>& command,
                        const std::string& workerFlag, int count, int threads);

// For a worker that runWorkerProcesses started: it is sent SIGTERM when that process dies, and
// SIGINT and SIGTERM set a flag that workerShouldStop reads (while a trainer holds the signals,
// it passes them on). Throws when the parent is already gone, or when this process was not
// started so.
void stopWithParent();
// Whether a worker should stop before its next unit of work: it was sent SIGINT or SIGTERM, or
// the process that started it is gone.
bool workerShouldStop();

// The running executable, for runWorkerProcesses: /proc/self/exe, which stays this very file
// when the path it was started from is rebuilt or removed meanwhile.
inline constexpr const char* kSelfExecutable = "/proc/self/exe";

}  // namespace paircast
