// Paths shared by the tests: the repository, the optional ../shared/scenes, and scratch folders.
#pragma once

#include <gtest/gtest.h>

#include <filesystem>
#include <string>

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

}  // namespace paircast::testing
