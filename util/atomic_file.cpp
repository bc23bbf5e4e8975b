#include "util/atomic_file.h"

#include <fcntl.h>
#include <signal.h>
#include <unistd.h>

#include <cctype>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
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

// This machine's host name as it appears in temporary names: no '.', so that names parse back.
const std::string& hostTag() {
  static const std::string tag = [] {
    char name[256] = {};
    std::string host = ::gethostname(name, sizeof name - 1) == 0 && name[0] ? name : "localhost";
    for (char& c : host)
      if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_') c = '_';
    return host;
  }();
  return tag;
}

bool allDigits(const std::string& s) {
  return !s.empty() && s.find_first_not_of("0123456789") == std::string::npos;
}

struct Temporary {
  std::string target, host;  // the file it stands for, and the host that wrote it
  long pid = 0;
};

// Parses ".<target>.tmp.<host>.<pid>", or the older ".<target>.tmp.<pid>" (this host's).
std::optional<Temporary> parseTemporary(const std::string& name) {
  const size_t dot = name.rfind('.');
  if (name.size() < 2 || name[0] != '.' || dot == std::string::npos) return {};
  const std::string pid = name.substr(dot + 1);
  if (!allDigits(pid) || pid.size() > 9) return {};
  const std::string marker = ".tmp";
  // The target of "<rest>" when it is ".<target>.tmp", else "".
  auto targetOf = [&](const std::string& rest) {
    if (rest.size() <= marker.size() + 1 ||
        rest.compare(rest.size() - marker.size(), marker.size(), marker) != 0)
      return std::string();
    return rest.substr(1, rest.size() - 1 - marker.size());
  };
  Temporary t;
  t.pid = std::strtol(pid.c_str(), nullptr, 10);
  const std::string rest = name.substr(0, dot);
  const size_t hostDot = rest.rfind('.');
  if (hostDot != std::string::npos && hostDot + 1 < rest.size()) {
    t.target = targetOf(rest.substr(0, hostDot));
    t.host = rest.substr(hostDot + 1);
  }
  if (t.target.empty()) {
    t.target = targetOf(rest);
    t.host = hostTag();
  }
  if (t.target.empty()) return {};
  return t;
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

int removeStaleTemporaries(const std::string& dir,
                           const std::function<bool(const std::string&)>& owned) {
  int removed = 0;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    const std::optional<Temporary> t = parseTemporary(e.path().filename().string());
    if (!t || (owned && !owned(t->target))) continue;
    if (t->host == hostTag() &&
        (t->pid == ::getpid() || ::kill(static_cast<pid_t>(t->pid), 0) == 0 || errno != ESRCH))
      continue;  // a process of this host that still runs
    if (fs::remove(e.path(), ec)) ++removed;
  }
  return removed;
}

std::string tempPathFor(const std::string& path) {
  fs::path p(path);
  return (p.parent_path() /
          ("." + p.filename().string() + ".tmp." + hostTag() + "." + std::to_string(::getpid())))
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
