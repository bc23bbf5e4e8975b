// Comparing output folders in tests.
#pragma once

#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
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

// The last record of each key in a generate_pairs journal.
inline std::map<std::string, nlohmann::json> journalRecords(const std::string& path) {
  std::map<std::string, nlohmann::json> last;
  std::ifstream in(path);
  for (std::string line; std::getline(in, line);) {
    const auto r = nlohmann::json::parse(line);
    last[r["scene"].get<std::string>() + std::to_string(r["index"].get<int>())] = r;
  }
  return last;
}

// Whether `out` holds a temporary (".NAME.tmp.*", util/atomic_file.h) of a file whose name
// starts with `prefix` ("pairs-0-").
inline bool hasTemporary(const std::string& out, const std::string& prefix) {
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(out, ec)) {
    const std::string name = e.path().filename().string();
    if (name.rfind("." + prefix, 0) == 0 && name.find(".tmp.") != std::string::npos) return true;
  }
  return false;
}

}  // namespace paircast::testing
