// Training samples on disk, by index: members of tar shards (located once through the shard
// codec, shard/shard_index.h, then read with pread) or CroCo's folder layout (pairs.txt). A
// sample is view 1 and one or more other views (N - 1 of them when it was rendered with CroCo's
// views_count N); a pair pairs view 1 with one of the others, drawn by the caller.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "util/image.h"
#include "util/image_io.h"

namespace paircast {

// The files that shard paths and glob patterns name, in order (each pattern's matches sorted).
// Throws paircast::Error naming a pattern that matches nothing.
std::vector<std::string> expandShardPatterns(const std::vector<std::string>& patterns);

class PairDataset {
 public:
  // Shards: files or glob patterns, read through ShardIndex. A sample the index refuses (a
  // missing member, a record that names other views than its members) or that has one view
  // is skipped with a warning; a truncated shard keeps its whole samples (with a warning).
  // Throws paircast::Error naming the shard when it is of another paircast_shard_version.
  static PairDataset fromShards(const std::vector<std::string>& patterns);
  // CroCo layout: DIR/pairs.txt with "im1 im2" lines relative to DIR. The lines that share
  // im1 make one sample: im1 is view 1, their im2s the other views, in the order listed.
  static PairDataset fromCrocoDir(const std::string& dir);

  // Keeps only the samples whose key is listed (one key per line in `keysFile`), in their order
  // in the shards. Throws paircast::Error naming the file when a listed key is missing.
  void restrictTo(const std::string& keysFile);

  size_t size() const { return samples_.size(); }
  const std::string& key(size_t i) const { return samples_.at(i).key; }
  // Views of sample i, view 1 included (2 for a pair).
  size_t views(size_t i) const { return 1 + samples_.at(i).others.size(); }
  // The encoded images of view 1 of sample i and of the other view `draw` picks (draw modulo
  // the number of other views, so draw 0 is view 2 and a pair ignores it): a caller that passes
  // a draw from its seeded stream stays reproducible. Names are "<shard>:<member>" or the file.
  std::pair<EncodedImage, EncodedImage> encoded(size_t i, uint64_t draw = 0) const;
  // The same, decoded. Throws paircast::Error naming the file and member on corruption.
  std::pair<Image8, Image8> load(size_t i, uint64_t draw = 0) const;
  std::string describe(size_t i) const;

 private:
  struct Member {
    std::string file;
    uint64_t offset = 0, length = 0;  // length 0: the whole file
    std::string name;                 // the shard member, for messages ("" in CroCo folders)
  };
  struct Sample {
    std::string key;
    Member first;
    std::vector<Member> others;  // at least one
  };
  std::vector<Sample> samples_;
};

}  // namespace paircast
