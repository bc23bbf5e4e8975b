// Pairs on disk, by index, for training: members of tar shards (located once by scanning the
// ustar headers, then read with pread) or CroCo's folder layout (pairs.txt).
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "util/image.h"

namespace paircast {

class PairDataset {
 public:
  // Shards: files or glob patterns. Truncated shards keep their whole samples (with a warning).
  static PairDataset fromShards(const std::vector<std::string>& patterns);
  // CroCo layout: DIR/pairs.txt with "im1 im2" lines relative to DIR.
  static PairDataset fromCrocoDir(const std::string& dir);

  // Keeps only the pairs whose key is listed (one key per line in `keysFile`), in their order
  // in the shards. Throws paircast::Error naming the file when a listed key is missing.
  void restrictTo(const std::string& keysFile);

  size_t size() const { return pairs_.size(); }
  const std::string& key(size_t i) const { return pairs_.at(i).key; }
  // Decodes pair i. Throws paircast::Error naming the file and member on corruption.
  std::pair<Image8, Image8> load(size_t i) const;
  std::string describe(size_t i) const;

 private:
  struct Member {
    std::string file;
    uint64_t offset = 0, length = 0;  // length 0: the whole file
  };
  struct Pair {
    Member a, b;
    std::string key;
  };
  std::vector<Pair> pairs_;
};

}  // namespace paircast
