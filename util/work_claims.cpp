#include "util/work_claims.h"

#include <fcntl.h>
#include <pthread.h>
#include <signal.h>
#include <spawn.h>
#include <sys/file.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>

#include "util/error.h"

extern char** environ;

namespace paircast {
namespace fs = std::filesystem;

namespace {

constexpr const char* kParentName = "PAIRCAST_WORKER_PARENT";
const std::string kParentVariable = std::string(kParentName) + "=";

// SIGINT and SIGTERM, the signals that stop a worker.
sigset_t stopSignals() {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  return set;
}

// `handler` for SIGINT and SIGTERM (system calls restarted), the old actions into `old`.
void handleStopSignals(void (*handler)(int), struct sigaction* oldInt, struct sigaction* oldTerm) {
  struct sigaction sa {};
  sa.sa_handler = handler;
  sa.sa_flags = SA_RESTART;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, oldInt);
  sigaction(SIGTERM, &sa, oldTerm);
}

int openClaimFile(const std::string& path) {
  std::error_code ec;
  fs::create_directories(fs::path(path).parent_path(), ec);
  const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0) throw Error(path, std::string("cannot open the claim file: ") + std::strerror(errno));
  return fd;
}

// The workers of the one runWorkerProcesses in flight, for the signal handler: a reaped one's
// pid is set to 0. And the last signal it passed on.
constexpr int kMaxWorkers = 256;
volatile sig_atomic_t gWorkerCount = 0;
volatile pid_t gWorkers[kMaxWorkers];
volatile sig_atomic_t gPassedOn = 0;

void passSignalOn(int sig) {
  const int saved = errno;
  gPassedOn = sig;
  for (sig_atomic_t i = 0; i < gWorkerCount; ++i)
    if (gWorkers[i] > 0) ::kill(gWorkers[i], sig);
  errno = saved;
}

// Passes SIGINT and SIGTERM on to the workers while they run; restores the old handlers after.
class PassSignalsOn {
 public:
  PassSignalsOn() {
    gWorkerCount = 0;
    gPassedOn = 0;
    handleStopSignals(passSignalOn, &oldInt_, &oldTerm_);
  }
  ~PassSignalsOn() {
    sigaction(SIGINT, &oldInt_, nullptr);
    sigaction(SIGTERM, &oldTerm_, nullptr);
    gWorkerCount = 0;
  }

 private:
  struct sigaction oldInt_ {
  }, oldTerm_{};
};

// SIGINT and SIGTERM held back while workers are started and entered for the handler: none is
// lost between two spawns.
class HoldStopSignals {
 public:
  HoldStopSignals() {
    const sigset_t stop = stopSignals();
    pthread_sigmask(SIG_BLOCK, &stop, &old_);
  }
  ~HoldStopSignals() { pthread_sigmask(SIG_SETMASK, &old_, nullptr); }

 private:
  sigset_t old_;
};

// Our environment, with the thread counts and the parent variable set.
std::vector<std::string> workerEnvironment(int threads) {
  std::vector<std::string> env;
  auto replaced = [](const char* e) {
    for (const char* name : {"OMP_NUM_THREADS=", "OPENBLAS_NUM_THREADS=", kParentVariable.c_str()})
      if (std::strncmp(e, name, std::strlen(name)) == 0) return true;
    return false;
  };
  for (char** e = environ; *e; ++e)
    if (!replaced(*e)) env.emplace_back(*e);
  env.push_back("OMP_NUM_THREADS=" + std::to_string(threads));
  env.push_back("OPENBLAS_NUM_THREADS=" + std::to_string(threads));
  env.push_back(kParentVariable + std::to_string(::getpid()));
  return env;
}

std::vector<char*> pointers(std::vector<std::string>& strings) {
  std::vector<char*> p;
  for (auto& s : strings) p.push_back(s.data());
  p.push_back(nullptr);
  return p;
}

// Workers start with SIGINT and SIGTERM unblocked and at their default action, whatever ours
// are: a spawned process inherits the signal mask (HoldStopSignals blocks both while spawning)
// and the signals we ignore (a shell's background job ignores SIGINT).
class CleanSignals {
 public:
  CleanSignals() {
    posix_spawnattr_init(&attr_);
    sigset_t none;
    sigemptyset(&none);
    const sigset_t stop = stopSignals();
    posix_spawnattr_setsigmask(&attr_, &none);
    posix_spawnattr_setsigdefault(&attr_, &stop);
    posix_spawnattr_setflags(&attr_, POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF);
  }
  ~CleanSignals() { posix_spawnattr_destroy(&attr_); }
  const posix_spawnattr_t* get() const { return &attr_; }

 private:
  posix_spawnattr_t attr_;
};

pid_t spawnWorker(const std::string& executable, std::vector<std::string> args,
                  std::vector<std::string> env) {
  std::vector<char*> argv = pointers(args), envp = pointers(env);
  pid_t pid = 0;
  const CleanSignals attr;
  const int rc =
      posix_spawn(&pid, executable.c_str(), nullptr, attr.get(), argv.data(), envp.data());
  if (rc != 0)
    throw Error(executable, "cannot start a worker of " + args[0] + ": " + std::strerror(rc));
  return pid;
}

struct Ended {
  int index;
  pid_t pid;
  int status;  // waitpid's, or -1 when it could not wait
};

// The first of `pids` to end (its slot then set to 0), polled every 50 ms.
Ended waitForAny(std::vector<pid_t>& pids) {
  while (true) {
    for (size_t k = 0; k < pids.size(); ++k) {
      if (pids[k] <= 0) continue;
      int status = 0;
      const pid_t r = ::waitpid(pids[k], &status, WNOHANG);
      if (r == pids[k] || (r < 0 && errno != EINTR)) {
        const Ended ended{static_cast<int>(k), pids[k], r < 0 ? -1 : status};
        gWorkers[k] = 0;  // never signalled again: its pid may be reused
        pids[k] = 0;
        return ended;
      }
    }
    ::usleep(50 * 1000);
  }
}

std::string describeExit(int status) {
  if (status != -1 && WIFEXITED(status))
    return "exited with status " + std::to_string(WEXITSTATUS(status));
  if (status != -1 && WIFSIGNALED(status))
    return std::string("was killed by ") + strsignal(WTERMSIG(status));
  return "could not be waited for";
}

// Starts the workers, with SIGINT and SIGTERM held until each is known to the handler. Those
// already started are stopped and waited for when one cannot start.
std::vector<pid_t> startWorkers(const std::string& executable,
                                const std::vector<std::string>& command,
                                const std::string& workerFlag, int count, int threads) {
  const std::vector<std::string> env = workerEnvironment(threads);
  HoldStopSignals hold;
  std::vector<pid_t> pids;
  for (int k = 1; k <= count; ++k) {
    std::vector<std::string> args = command;
    args.insert(args.end(), {workerFlag, std::to_string(k)});
    try {
      pids.push_back(spawnWorker(executable, args, env));
    } catch (const Error&) {
      for (pid_t p : pids) ::kill(p, SIGTERM);  // they save and stop
      for (pid_t p : pids) ::waitpid(p, nullptr, 0);
      throw;  // PassSignalsOn forgets them
    }
    gWorkers[k - 1] = pids.back();
    gWorkerCount = k;
  }
  return pids;
}

}  // namespace

std::optional<WorkClaim> WorkClaim::tryTake(const std::string& path) {
  const int fd = openClaimFile(path);
  if (::flock(fd, LOCK_EX | LOCK_NB) == 0) return WorkClaim(fd);
  const int err = errno;
  ::close(fd);
  if (err == EWOULDBLOCK) return std::nullopt;
  throw Error(path, std::string("cannot lock the claim file: ") + std::strerror(err));
}

WorkClaim WorkClaim::take(const std::string& path) {
  const int fd = openClaimFile(path);
  while (::flock(fd, LOCK_EX) != 0)
    if (errno != EINTR) {
      const int err = errno;
      ::close(fd);
      throw Error(path, std::string("cannot lock the claim file: ") + std::strerror(err));
    }
  return WorkClaim(fd);
}

WorkClaim::WorkClaim(WorkClaim&& other) noexcept : fd_(other.fd_) {
  other.fd_ = -1;
}

WorkClaim::~WorkClaim() {
  if (fd_ >= 0) ::close(fd_);  // closing the only descriptor releases the lock
}

void runWorkerProcesses(const std::string& executable, const std::vector<std::string>& command,
                        const std::string& workerFlag, int count, int threads) {
  PAIRCAST_CHECK(!command.empty() && count >= 1 && count <= kMaxWorkers && threads >= 1);
  PassSignalsOn pass;
  std::vector<pid_t> pids = startWorkers(executable, command, workerFlag, count, threads);
  std::string failed;
  for (int left = count; left > 0; --left) {
    const Ended e = waitForAny(pids);
    if (!failed.empty() || (WIFEXITED(e.status) && WEXITSTATUS(e.status) == 0)) continue;
    failed = "worker " + std::to_string(e.index + 1) + " of " + std::to_string(count) + " (pid " +
             std::to_string(e.pid) + ") " + describeExit(e.status);
    for (pid_t p : pids)
      if (p > 0) ::kill(p, SIGTERM);  // the others save and stop
  }
  if (!failed.empty()) throw Error(failed);
  if (gPassedOn) throw Error(std::string("stopped by ") + strsignal(gPassedOn));
}

namespace {
volatile sig_atomic_t gStopAsked = 0;
pid_t gParent = 0;
void askToStop(int) {
  gStopAsked = 1;
}
}  // namespace

void stopWithParent() {
  const char* parent = std::getenv(kParentName);
  if (!parent || !*parent)
    throw Error(std::string(kParentName) +
                " is not set: workers are started by the command itself, not by hand");
  gParent = static_cast<pid_t>(std::atoll(parent));
  handleStopSignals(askToStop, nullptr, nullptr);
  ::prctl(PR_SET_PDEATHSIG, SIGTERM);
  // The parent may have died before the line above: then we were re-parented.
  if (::getppid() != gParent)
    throw Error("the process that started this worker (pid " + std::string(parent) + ") is gone");
}

bool workerShouldStop() {
  return gStopAsked || ::getppid() != gParent;
}

}  // namespace paircast
