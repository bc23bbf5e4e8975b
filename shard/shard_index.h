// A shard's index: where each sample's members lie in the file, found by reading the ustar
// headers alone (no libarchive, so the trainer-only build has it too), with each sample's
// record parsed and checked against its members. Members are then read with pread, so any
// number of threads can read one index.
//
// Legend: V views.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "shard/shard_format.h"

namespace paircast {

using Bytes = std::vector<unsigned char>;

// A member's bytes in the shard file.
struct Extent {
  uint64_t offset = 0, size = 0;
};

struct IndexedSample {
  std::string key;
  SampleRecord record;
  nlohmann::json json;            // the record as stored (with keys the schema does not name)
  std::vector<Extent> image;      // [V] K.k.jpg
  std::vector<Extent> depth;      // [V] K.k.depth.exr, or empty
  std::vector<Extent> covisMask;  // [V] K.k.covis.png, or empty
  std::vector<Extent> flow;       // [V] K.k.flow.flo, or empty (flowTarget says into which view)
};

struct ShardIndexOptions {
  uint64_t maxEntryBytes = 64ull << 20;  // refuse larger members before reading them
};

class ShardIndex {
 public:
  using Warn = std::function<void(const std::string&)>;

  // Indexes the shard at `path`. A sample that cannot be used (a missing or empty member, a
  // record that does not parse or names other views than its members, a member that is a link,
  // not a plain file, escapes a folder, or exceeds maxEntryBytes) is reported through `warn`
  // with the shard and the key, and left out. A truncated or corrupt archive keeps the samples
  // before the damage and says what it is in damage(): each reader decides whether that is an
  // error. Throws paircast::Error naming the shard when it cannot be read or is of another
  // paircast_shard_version.
  static ShardIndex open(const std::string& path, const Warn& warn = {},
                         const ShardIndexOptions& options = {});
  // The keys of the samples of the shard at `path` that have a record and images, in order, from
  // the headers alone: no record is read or checked. For a shard known to be whole (one that
  // generate_pairs renamed into place), where open() would parse every record. Throws
  // paircast::Error naming the shard when it cannot be read or is truncated or corrupt.
  static std::vector<std::string> keys(const std::string& path);

  const std::string& path() const { return path_; }
  size_t size() const { return samples_.size(); }
  const IndexedSample& operator[](size_t i) const { return samples_[i]; }
  const std::vector<IndexedSample>& samples() const { return samples_; }
  bool damaged() const { return !damage_.empty(); }
  // "shard is truncated or corrupt: <where>", or "" when the archive ends cleanly.
  const std::string& damage() const { return damage_; }
  // For readers that keep a damaged shard's whole samples: "<shard>: <damage>; its whole samples
  // are used" through `warn`, when damaged.
  void warnOfDamage(const Warn& warn) const;

  // The bytes of a member. Throws paircast::Error naming the shard when the file is shorter than
  // the index says (it changed since).
  Bytes read(const Extent& e) const;
  // "<shard>: <member name>", for messages.
  std::string describe(size_t i, MemberKind kind, int view) const;

 private:
  std::string path_;
  std::vector<IndexedSample> samples_;
  std::string damage_;
};

// The bytes of [offset, offset + size) of `path`. Throws paircast::Error naming it on a short
// read.
Bytes readFileRange(const std::string& path, uint64_t offset, uint64_t size);

}  // namespace paircast
