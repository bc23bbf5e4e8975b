// WebDataset-style tar shards. A sample with key K of N views is the consecutive entries K.1.jpg
// ... K.N.jpg, optional K.k.depth.exr and K.k.covis.png for each view, and K.json: scene, seed,
// index, "views", "cameras" (N), camera1 and camera2, covis, v_ij and v_ji of views 1 and 2,
// CroCo's covisibility_ratios and pairwise_visibility_ratios, and "paircast_shard_version". Entries
// are plain ustar files with fixed owner, mode and time, so a shard's bytes depend only on its
// samples.
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
  int views = 2;
  std::vector<Camera> camera;            // [views]
  double covis = 0, v_ij = 0, v_ji = 0;  // views 1 and 2, in [0, 1] (0 with one view)
};
// Throws paircast::Error naming `source` when the version differs (the message says how to
// regenerate the shard) or a field is missing, of the wrong type or out of range.
SampleRecord parseSampleRecord(const nlohmann::json& record, const std::string& source);

using Bytes = std::vector<unsigned char>;

// Encoded files of one sample, shared by the shard and CroCo writers.
struct EncodedPair {
  std::string key;
  std::vector<Bytes> jpeg;      // [views]
  std::vector<Bytes> depthExr;  // [views], or empty without depth
  std::vector<Bytes> covisPng;  // [views], or empty without masks
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
  std::vector<Bytes> jpeg;      // [views]
  std::vector<Bytes> depthExr;  // [views] when the shard has depth, else empty
  std::vector<Bytes> covisPng;  // [views] when the shard has masks, else empty
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
