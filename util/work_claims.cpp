#include "util/work_claims.h"

#include <fcntl.h>
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

constexpr const char* kParentVariable = "PAIRCAST_WORKER_PARENT";

int openClaimFile(const std::string& path) {
  std::error_code ec;
  fs::create_directories(fs::path(path).parent_path(), ec);
  const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0) throw Error(path, std::string("cannot open the claim file: ") + std::strerror(errno));
  return fd;
}

// The workers of the one runWorkerProcesses in flight, for the signal handler.
constexpr int kMaxWorkers = 256;
volatile sig_atomic_t gWorkerCount = 0;
pid_t gWorkers[kMaxWorkers];

void passSignalOn(int sig) {
  for (sig_atomic_t i = 0; i < gWorkerCount; ++i) ::kill(gWorkers[i], sig);
}

// Holds SIGINT and SIGTERM for the workers while they run; restores the old handlers after.
class PassSignalsOn {
 public:
  PassSignalsOn() {
    struct sigaction sa {};
    sa.sa_handler = passSignalOn;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, &oldInt_);
    sigaction(SIGTERM, &sa, &oldTerm_);
  }
  ~PassSignalsOn() {
    gWorkerCount = 0;
    sigaction(SIGINT, &oldInt_, nullptr);
    sigaction(SIGTERM, &oldTerm_, nullptr);
  }

 private:
  struct sigaction oldInt_ {
  }, oldTerm_{};
};

// Our environment, with OMP_NUM_THREADS and the parent variable set.
std::vector<std::string> workerEnvironment(int threads) {
  std::vector<std::string> env;
  for (char** e = environ; *e; ++e)
    if (std::strncmp(*e, "OMP_NUM_THREADS=", 16) && std::strncmp(*e, kParentVariable, 22))
      env.emplace_back(*e);
  env.push_back("OMP_NUM_THREADS=" + std::to_string(threads));
  env.push_back(std::string(kParentVariable) + "=" + std::to_string(::getpid()));
  return env;
}

std::vector<char*> pointers(std::vector<std::string>& strings) {
  std::vector<char*> p;
  for (auto& s : strings) p.push_back(s.data());
  p.push_back(nullptr);
  return p;
}

pid_t spawnWorker(std::vector<std::string> args, std::vector<std::string> env) {
  std::vector<char*> argv = pointers(args), envp = pointers(env);
  pid_t pid = 0;
  const int rc = posix_spawn(&pid, argv[0], nullptr, nullptr, argv.data(), envp.data());
  if (rc != 0) throw Error(args[0], std::string("cannot start a worker: ") + std::strerror(rc));
  return pid;
}

// Waits for one worker; a signal handled meanwhile does not end the wait.
int waitFor(pid_t pid) {
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0)
    if (errno != EINTR) return -1;
  return status;
}

std::string describeExit(int status) {
  if (WIFEXITED(status)) return "exited with status " + std::to_string(WEXITSTATUS(status));
  if (WIFSIGNALED(status)) return std::string("was killed by ") + strsignal(WTERMSIG(status));
  return "could not be waited for";
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

void runWorkerProcesses(const std::vector<std::string>& command, const std::string& workerFlag,
                        int count, int threads) {
  PAIRCAST_CHECK(!command.empty() && count >= 1 && count <= kMaxWorkers && threads >= 1);
  const std::vector<std::string> env = workerEnvironment(threads);
  PassSignalsOn pass;
  std::vector<pid_t> pids;
  for (int k = 1; k <= count; ++k) {
    std::vector<std::string> args = command;
    args.insert(args.end(), {workerFlag, std::to_string(k)});
    try {
      pids.push_back(spawnWorker(args, env));
    } catch (const Error&) {
      passSignalOn(SIGTERM);  // those already started save and stop
      for (pid_t p : pids) waitFor(p);
      throw;
    }
    gWorkers[k - 1] = pids.back();
    gWorkerCount = k;
  }
  std::string failed;
  for (int k = 1; k <= count; ++k) {
    const int status = waitFor(pids[k - 1]);
    if (failed.empty() && !(WIFEXITED(status) && WEXITSTATUS(status) == 0))
      failed = "worker " + std::to_string(k) + " of " + std::to_string(count) + " (pid " +
               std::to_string(pids[k - 1]) + ") " + describeExit(status);
  }
  if (!failed.empty()) throw Error(command[0], failed);
}

void stopWithParent() {
  const char* parent = std::getenv(kParentVariable);
  if (!parent || !*parent)
    throw Error(std::string(kParentVariable) +
                " is not set: workers are started by the command "
                "itself, not by hand");
  ::prctl(PR_SET_PDEATHSIG, SIGTERM);
  // The parent may have died before the line above: then we were re-parented.
  if (std::to_string(::getppid()) != parent)
    throw Error("the process that started this worker (pid " + std::string(parent) + ") is gone");
}

std::string selfExecutable() {
  std::error_code ec;
  const fs::path p = fs::read_symlink("/proc/self/exe", ec);
  if (ec) throw Error("/proc/self/exe", "cannot find the running executable: " + ec.message());
  return p.string();
}

}  // namespace paircast
