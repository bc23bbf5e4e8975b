// Comparing output folders in tests.
#pragma once

#include <filesystem>
#include <map>
#include <string>

#include "util/atomic_file.h"

namespace paircast::testing {

// Every regular file under `dir` (relative path -> bytes), except the run summaries
// ("summary*" at the top), whose timings differ between runs, and generate_pairs' journal
// (".paircast/"), which a resumed run appends to: compare its records with journalRecords().
inline std::map<std::string, std::string> fileTree(const std::string& dir) {
  namespace fs = std::filesystem;
  std::map<std::string, std::string> files;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (!e.is_regular_file()) continue;
    const std::string rel = fs::relative(e.path(), dir).string();
    if (rel.rfind("summary", 0) == 0 || rel.rfind(".paircast/", 0) == 0) continue;
    files[rel] = readFile(e.path().string());
  }
  return files;
}

}  // namespace paircast::testing
