// Running the real command-line tools from tests: fork, exec with extra environment, output
// discarded, optionally killed after a delay.
#pragma once

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <string>
#include <thread>
#include <vector>

namespace paircast::testing {

inline pid_t spawnProcess(const std::vector<std::string>& args,
                          const std::vector<std::string>& env = {}) {
  const pid_t pid = fork();
  if (pid == 0) {
    for (const auto& e : env) putenv(const_cast<char*>(e.c_str()));
    std::vector<char*> argv;
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    const int devnull = open("/dev/null", O_WRONLY);
    dup2(devnull, 1);
    dup2(devnull, 2);
    execv(argv[0], argv.data());
    _exit(127);
  }
  return pid;
}

// The exit code, or minus the signal that ended the process.
inline int waitProcess(pid_t pid) {
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -WTERMSIG(status);
}

// Runs a command to its end, or SIGKILLs it after `killAfterMs` (never when < 0).
inline int runProcess(const std::vector<std::string>& args, int killAfterMs = -1,
                      const std::vector<std::string>& env = {}) {
  const pid_t pid = spawnProcess(args, env);
  if (killAfterMs >= 0) {
    std::this_thread::sleep_for(std::chrono::milliseconds(killAfterMs));
    kill(pid, SIGKILL);
  }
  return waitProcess(pid);
}

}  // namespace paircast::testing
