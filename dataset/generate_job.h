// generate_pairs as a library call: samples pairs (or N-view samples) in every scene, in parallel,
// and writes them as tar shards and/or CroCo's folder layout. Resumable: a killed run, started
// again with the same arguments, finishes the job with no duplicate, missing or corrupt file, and
// with the same bytes as an uninterrupted run, whatever --jobs is. Its bookkeeping is one
// append-only journal, <out>/.paircast/journal.jsonl (docs/dataset.md).
#pragma once

#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "dataset/pair_generator.h"
#include "render/scene_loader.h"

namespace paircast {

struct GenerateConfig {
  // Checks what a user sets (the pair options too); throws OptionError naming the field.
  void validate() const;

  std::vector<std::string> scenes;  // files, folders (searched recursively) or .txt lists
  std::string out;
  int pairsPerScene = 100;
  uint64_t seed = 0;
  int jobs = 0;            // worker threads; 0 = all cores
  bool shards = true;      // pairs-NNNNNN.tar + index.json
  bool croco = false;      // <scene>/<idx>_1.jpeg ... + metadata.json + pairs.txt
  bool saveDepth = false;  // also z-depth EXR (and camera JSON in the CroCo layout)
  int shardSize = 1000;    // pairs per shard
  uint64_t shardMaxBytes = 1ull << 30;
  int jpegQuality = 90;
  int shardIndex = 0;    // this machine's part of the scene list ...
  int numShards = 1;     // ... of numShards parts
  bool progress = true;  // progress line on stderr
  LoadOptions load;
  PairOptions pair;  // views, covis band, screening, covis masks, ...
};

// The regular files under `dir` (recursively) that `keep` accepts, sorted by path.
std::vector<std::string> sortedFilesUnder(
    const std::string& dir, const std::function<bool(const std::filesystem::path&)>& keep);

// Expands the --scenes arguments into scene files, sorted within each folder, in argument order.
// Throws paircast::Error naming an argument that does not exist.
std::vector<std::string> expandSceneList(const std::vector<std::string>& args);

// The name of each scene file in outputs and keys: its sanitised stem, or "<folder>_<stem>" when
// several files share the stem (Replica's mesh.ply), with _2, _3, ... added to later files whose
// name is taken.
std::vector<std::string> uniqueSceneNames(const std::vector<std::string>& files);

// Runs the job and returns the summary (also written to <out>/summary.json). Scenes that fail
// to load or have no walkable floor or valid views are skipped with a warning and listed in
// "skipped_scenes"; the caller decides what that means for its exit status.
nlohmann::json runGenerate(const GenerateConfig& config);

}  // namespace paircast
