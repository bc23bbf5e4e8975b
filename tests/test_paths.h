// Paths shared by the tests: the repository, the optional ../shared/scenes, and scratch folders.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <vector>

namespace paircast::testing {

inline std::string sourceDir() {
  return PAIRCAST_SOURCE_DIR;
}

// ../shared/scenes beside the checkout, or "" when it is absent (tests then skip).
inline std::string sharedScenesDir() {
  const auto dir = std::filesystem::path(PAIRCAST_SOURCE_DIR).parent_path() / "shared" / "scenes";
  return std::filesystem::is_directory(dir) ? dir.string() : std::string();
}

// A fresh, empty folder for this test.
inline std::string scratchDir(const std::string& name) {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  auto dir = std::filesystem::path(::testing::TempDir()) / "paircast" /
             (std::string(info->test_suite_name()) + "." + info->name() + "." + name);
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir.string();
}

// Inputs a fuzz target's regression test replays: the seeds (fuzz/corpus/<target>/) when
// `seeds`, else the findings kept after their fix (tests/regressions/<target>/). Sorted.
inline std::vector<std::string> fuzzInputs(const std::string& target, bool seeds) {
  const auto dir = std::filesystem::path(PAIRCAST_SOURCE_DIR) /
                   (seeds ? "fuzz/corpus" : "tests/regressions") / target;
  std::vector<std::string> files;
  if (std::filesystem::is_directory(dir))
    for (const auto& e : std::filesystem::directory_iterator(dir))
      if (e.is_regular_file()) files.push_back(e.path().string());
  std::sort(files.begin(), files.end());
  return files;
}

// Replays a fuzz target's inputs through `run`, the target's entry point (fuzz/*_inputs.h: true
// when the bytes were accepted, false when refused with paircast::Error, anything else thrown is
// a failure): every seed must be accepted, every kept finding accepted or refused.
inline void replayFuzzInputs(const std::string& target,
                             const std::function<bool(const std::string&)>& run) {
  auto bytesOf = [](const std::string& file) {
    std::ifstream in(file, std::ios::binary);
    std::ostringstream os;
    os << in.rdbuf();
    return os.str();
  };
  const auto seeds = fuzzInputs(target, true);
  EXPECT_FALSE(seeds.empty()) << "no seeds for " << target;
  for (const auto& file : seeds) EXPECT_TRUE(run(bytesOf(file))) << file << " was refused";
  for (const auto& file : fuzzInputs(target, false)) {
    SCOPED_TRACE(file);
    EXPECT_NO_THROW(run(bytesOf(file)));
  }
}

}  // namespace paircast::testing
