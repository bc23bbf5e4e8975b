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
#include "dataset/scene_list.h"
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
  // Also each view's optical flow (.flo, pixels) into view flowTarget(k): view 1's into view 2,
  // every other view's into view 1 (shard/shard_format.h).
  bool saveFlow = false;
  int shardSize = 1000;    // pairs per shard
  uint64_t shardMaxBytes = 1ull << 30;
  int jpegQuality = 90;
  int shardIndex = 0;    // this machine's part of the scene list ...
  int numShards = 1;     // ... of numShards parts
  bool progress = true;  // progress line on stderr
  LoadOptions load;
  PairOptions pair;  // views, covis band, screening, covis masks, ...
};

// Runs the job and returns the summary (also written to <out>/summary.json). Scenes that fail
// to load or have no walkable floor or valid views are skipped with a warning and listed in
// "skipped_scenes"; the caller decides what that means for its exit status.
nlohmann::json runGenerate(const GenerateConfig& config);

}  // namespace paircast
