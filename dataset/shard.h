// WebDataset-style tar shards. A sample with key K is the consecutive entries K.1.jpg, K.2.jpg,
// optional K.1.depth.exr and K.2.depth.exr, and K.json (both cameras, covis, v_ij, v_ji, scene,
// seed, index, and "paircast_shard_version"). Entries are plain ustar files with fixed owner,
// mode and time, so a shard's bytes depend only on its samples.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "dataset/pair_generator.h"

struct archive;  // libarchive

namespace paircast {

constexpr int kShardVersion = 1;

// The key of a sample: "<scene>-<index:08>", with the scene name reduced to [A-Za-z0-9_-].
std::string sampleKey(const std::string& scene, uint64_t index);
std::string sanitizeName(const std::string& name);

// The JSON record of a pair (the same content as CroCo's metadata entries plus ours).
nlohmann::json sampleRecord(const PairSample& s);

// The checked content of a sample's JSON record, as sampleRecord() writes it: what readers of
// shards rely on. Other keys (seed, valid fractions, candidates) are optional.
struct SampleRecord {
  std::string scene;
  uint64_t index = 0;
  Camera camera[2];
  double covis = 0, v_ij = 0, v_ji = 0;  // in [0, 1]
};
// Throws paircast::Error naming `source` when the version differs (the message says how to
// regenerate the shard) or a field is missing, of the wrong type or out of range.
SampleRecord parseSampleRecord(const nlohmann::json& record, const std::string& source);

// Encoded files of one pair, shared by the shard and CroCo writers.
struct EncodedPair {
  std::string key;
  std::vector<unsigned char> jpeg[2];
  std::vector<unsigned char> depthExr[2];  // empty without depth
  nlohmann::json record;
};
EncodedPair encodePair(const PairSample& s, bool withDepth, int jpegQuality);

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
  std::vector<unsigned char> jpeg[2];
  std::vector<unsigned char> depthExr[2];
  nlohmann::json record;
};

struct ShardReadOptions {
  uint64_t maxEntryBytes = 64ull << 20;  // refuse larger entries before allocating them
};

// Reads samples in order. Calls `onSample` for each whole sample; a malformed sample (missing
// member, bad JSON, a record parseSampleRecord refuses) is reported through `onError` with the
// shard and key, and skipped. A truncated or corrupt archive throws paircast::Error naming the
// shard, after the samples before the damage were delivered. Nothing is ever written or
// followed: entries that are not plain files (symbolic and hard links, folders, devices) or whose
// names hold '/', "..", or an absolute path are reported with the shard and entry and skipped,
// and an entry larger than maxEntryBytes is skipped before anything is allocated for it.
// Returns the number of samples delivered.
size_t readShard(const std::string& path, const std::function<void(ShardSample&&)>& onSample,
                 const std::function<void(const std::string&)>& onError = {},
                 const ShardReadOptions& options = {});

// The keys of a shard's samples, in order (reads headers and skips data).
std::vector<std::string> shardKeys(const std::string& path);

}  // namespace paircast
