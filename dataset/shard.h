// Writing tar shards (libarchive), and reading them whole through the shard codec
// (shard/shard_index.h). The format itself is defined in shard/shard_format.h.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "dataset/pair_generator.h"
#include "shard/shard_format.h"
#include "shard/shard_index.h"

struct archive;  // libarchive

namespace paircast {

// The record of a pair: the schema's fields of `s` (shard_format.h).
SampleRecord sampleRecordOf(const PairSample& s);
// Its JSON (the same content as CroCo's metadata entries plus ours).
nlohmann::json sampleRecord(const PairSample& s);

// Encoded files of one sample, shared by the shard and CroCo writers.
struct EncodedPair {
  std::string key;
  std::vector<Bytes> jpeg;      // [views]
  std::vector<Bytes> depthExr;  // [views], or empty without depth
  std::vector<Bytes> covisPng;  // [views], or empty without masks
  std::vector<Bytes> flowFlo;   // [views] .flo (into view flowTarget(k)), or empty without flow
  nlohmann::json record;
};
// Each view's optical flow (covis/flow.h) into view flowTarget(k), from its depth (kept).
std::vector<ImageF> viewFlows(const PairSample& s);

// withFlow: the views' flows (viewFlows), as .flo.
EncodedPair encodePair(const PairSample& s, bool withDepth, int jpegQuality, bool withFlow = false);

// Writes one shard to a temporary name and renames it into place on close(), so a shard
// under its final name is always whole. Throws paircast::Error naming the shard on failure
// (a full disk included) and removes the temporary file.
class ShardWriter {
 public:
  explicit ShardWriter(const std::string& path);
  ~ShardWriter();  // an unclosed writer discards its temporary file
  ShardWriter(const ShardWriter&) = delete;
  ShardWriter& operator=(const ShardWriter&) = delete;

  void add(const EncodedPair& pair);
  void close();
  size_t samples() const { return samples_; }
  uint64_t bytes() const { return bytes_; }

 private:
  void addFile(const std::string& name, const void* data, size_t size);
  std::string path_, tmp_;
  ::archive* archive_ = nullptr;
  size_t samples_ = 0;
  uint64_t bytes_ = 0;
};

// One sample read back from a shard.
struct ShardSample {
  std::string key;
  std::vector<Bytes> jpeg;      // [views]
  std::vector<Bytes> depthExr;  // [views] when the shard has depth, else empty
  std::vector<Bytes> covisPng;  // [views] when the shard has masks, else empty
  std::vector<Bytes> flowFlo;   // [views] when the shard has flow, else empty
  nlohmann::json record;
};

using ShardReadOptions = ShardIndexOptions;

// Reads samples in order, through ShardIndex. Calls `onSample` for each whole sample; a
// malformed sample (missing member, bad JSON, a record parseSampleRecord refuses, views that
// disagree with the members) is reported through `onError` with the shard and key, and skipped.
// A truncated or corrupt archive throws paircast::Error naming the shard, after the samples
// before the damage were delivered; so does a shard of another version, before any. Nothing is
// ever written or followed: entries that are not plain files (symbolic and hard links, folders,
// devices) or whose names hold '/', "..", or an absolute path are reported with the shard and
// entry and skipped, and an entry larger than maxEntryBytes is skipped before anything is
// allocated for it. Returns the number of samples delivered.
size_t readShard(const std::string& path, const std::function<void(ShardSample&&)>& onSample,
                 const std::function<void(const std::string&)>& onError = {},
                 const ShardReadOptions& options = {});

}  // namespace paircast
