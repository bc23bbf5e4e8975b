#include "util/atomic_file.h"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cctype>
#include <filesystem>
#include <fstream>
#include <set>

#include "test_paths.h"

namespace paircast {
namespace {

namespace fs = std::filesystem;

std::string thisHost() {
  char name[256] = {};
  std::string host = gethostname(name, sizeof name - 1) == 0 && name[0] ? name : "localhost";
  for (char& c : host)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_') c = '_';
  return host;
}

// The pid of a process that has ended.
pid_t endedPid() {
  const pid_t pid = fork();
  if (pid == 0) _exit(0);
  waitpid(pid, nullptr, 0);
  return pid;
}

std::set<std::string> namesIn(const std::string& dir) {
  std::set<std::string> names;
  for (const auto& e : fs::directory_iterator(dir)) names.insert(e.path().filename().string());
  return names;
}

TEST(AtomicFile, ATemporaryNamesTheHostAndThePid) {
  const std::string host = thisHost();
  EXPECT_EQ(host.find('.'), std::string::npos);
  EXPECT_EQ(tempPathFor("/data/out/pairs-1-000042.tar"),
            "/data/out/.pairs-1-000042.tar.tmp." + host + "." + std::to_string(getpid()));
  EXPECT_EQ(tempPathFor("index.json"), ".index.json.tmp." + host + "." + std::to_string(getpid()));
}

TEST(AtomicFile, StaleTemporariesAreThoseOfEndedProcessesHereAndAnyOnOtherHosts) {
  const std::string dir = testing::scratchDir("stale");
  const std::string host = thisHost(), other = host + "-other", ended = std::to_string(endedPid());
  const std::string self = std::to_string(getpid()), parent = std::to_string(getppid());
  const std::vector<std::string> files = {
      ".a.json.tmp." + host + "." + ended,    // killed here: removed
      ".b.json.tmp." + host + "." + self,     // this process: kept
      ".c.json.tmp." + host + "." + parent,   // a process that runs here: kept
      ".d.json.tmp." + other + "." + parent,  // another host, whose pid means nothing here: removed
      ".e.json.tmp." + ended,                 // the older form, this host's: removed
      ".f.json.tmp." + parent,                // the older form, running: kept
      "g.json",                               // not temporaries
      ".g.json.tmp.",
      ".tmp." + host + "." + ended,
  };
  for (const auto& f : files) std::ofstream(dir + "/" + f) << "x";
  EXPECT_EQ(removeStaleTemporaries(dir), 3);
  std::set<std::string> left(files.begin(), files.end());
  for (const auto& f : {files[0], files[3], files[4]}) left.erase(f);
  EXPECT_EQ(namesIn(dir), left);
}

TEST(AtomicFile, OnlyTheTemporariesOfOwnedFilesAreRemoved) {
  // Two parts of a job write into one folder: part 1 removes its own leftovers, from any host,
  // and leaves those of part 0 whoever wrote them.
  const std::string dir = testing::scratchDir("owned");
  const std::string host = thisHost(), other = host + "-other", ended = std::to_string(endedPid());
  const std::vector<std::string> files = {
      ".pairs-1-000003.tar.tmp." + other + ".12", ".index-1.json.tmp." + host + "." + ended,
      ".pairs-0-000003.tar.tmp." + other + ".12", ".index-0.json.tmp." + host + "." + ended};
  for (const auto& f : files) std::ofstream(dir + "/" + f) << "x";
  auto part1 = [](const std::string& name) { return name.find("-1") != std::string::npos; };
  EXPECT_EQ(removeStaleTemporaries(dir, part1), 2);
  EXPECT_EQ(namesIn(dir), (std::set<std::string>{files[2], files[3]}));
}

}  // namespace
}  // namespace paircast
