#include "util/atomic_file.h"

#include <fcntl.h>
#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "util/error.h"

namespace paircast {
namespace fs = std::filesystem;

namespace {

std::string errnoText() {
  return std::strerror(errno);
}

void fsyncPath(const std::string& path, bool directory) {
  int fd = ::open(path.c_str(), directory ? O_RDONLY | O_DIRECTORY : O_RDONLY);
  if (fd < 0) return;  // Best effort: some file systems do not allow opening folders.
  ::fsync(fd);
  ::close(fd);
}

}  // namespace

void faultPointDuringWrite(const std::string& path, int fd, std::string_view data) {
  static const char* fault = std::getenv("PAIRCAST_FAULT_KILL_DURING_WRITE");
  if (!fault || !*fault || path.find(fault) == std::string::npos) return;
  size_t half = data.size() / 2, done = 0;
  while (done < half) {
    const ssize_t n = ::write(fd, data.data() + done, half - done);
    if (n <= 0) break;
    done += static_cast<size_t>(n);
  }
  ::fsync(fd);
  ::raise(SIGKILL);
}

int removeStaleTemporaries(const std::string& dir) {
  int removed = 0;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    const std::string name = e.path().filename().string();
    const size_t at = name.rfind(".tmp.");
    if (name.empty() || name[0] != '.' || at == std::string::npos) continue;
    const std::string pid = name.substr(at + 5);
    if (pid.empty() || pid.find_first_not_of("0123456789") != std::string::npos) continue;
    const long p = std::strtol(pid.c_str(), nullptr, 10);
    if (p == ::getpid() || (::kill(static_cast<pid_t>(p), 0) == 0 || errno != ESRCH)) continue;
    if (fs::remove(e.path(), ec)) ++removed;
  }
  return removed;
}

std::string tempPathFor(const std::string& path) {
  fs::path p(path);
  return (p.parent_path() / ("." + p.filename().string() + ".tmp." + std::to_string(::getpid())))
      .string();
}

void writeFileAtomic(const std::string& path, std::string_view data, Durability durability) {
  const std::string tmp = tempPathFor(path);
  int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw Error(path, "cannot create temporary file: " + errnoText());
  faultPointDuringWrite(path, fd, data);
  size_t done = 0;
  while (done < data.size()) {
    ssize_t n = ::write(fd, data.data() + done, data.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      std::string why = errnoText();
      ::close(fd);
      ::unlink(tmp.c_str());
      throw Error(path, "write failed: " + why);
    }
    done += static_cast<size_t>(n);
  }
  const bool sync = durability == Durability::Sync;
  if ((sync && ::fsync(fd) != 0) || ::close(fd) != 0) {
    std::string why = errnoText();
    ::unlink(tmp.c_str());
    throw Error(path, "write failed: " + why);
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    std::string why = errnoText();
    ::unlink(tmp.c_str());
    throw Error(path, "rename failed: " + why);
  }
  if (sync)
    fsyncPath(fs::path(path).parent_path().empty() ? "." : fs::path(path).parent_path().string(),
              true);
}

void commitFile(const std::string& from, const std::string& to) {
  fsyncPath(from, false);
  if (::rename(from.c_str(), to.c_str()) != 0) {
    std::string why = errnoText();
    ::unlink(from.c_str());
    throw Error(to, "rename failed: " + why);
  }
  auto parent = fs::path(to).parent_path();
  fsyncPath(parent.empty() ? "." : parent.string(), true);
}

std::string readFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(path, "cannot open file: " + errnoText());
  std::ostringstream os;
  os << in.rdbuf();
  if (in.bad()) throw Error(path, "read failed");
  return os.str();
}

void makeDirs(const std::string& path) {
  std::error_code ec;
  fs::create_directories(path, ec);
  if (ec) throw Error(path, "cannot create folder: " + ec.message());
}

}  // namespace paircast
