// The samples of several shards as one list, and views decoded straight into the layout a
// consumer takes: only a crop's rows and columns, written in one pass (util/jpeg_decoder.h).
// What paircast.torch.ShardPairs reads through.
//
// Legend: H, W pixels of a crop.
#pragma once

#include <string>
#include <vector>

#include "shard/shard_index.h"
#include "util/image.h"
#include "util/jpeg_decoder.h"

namespace paircast {

class ShardSet {
 public:
  // Indexes `files` in order (ShardIndex::open, warnings through `warn`; a damaged shard keeps
  // its whole samples, with a warning). Throws paircast::Error naming a shard that cannot be
  // read or is of another version, or the first file when no shard holds any sample.
  static ShardSet open(const std::vector<std::string>& files, const ShardIndex::Warn& warn = {});

  size_t size() const { return where_.size(); }
  const IndexedSample& operator[](size_t i) const;
  const std::string& shard(size_t i) const;
  // The shards in order, each with its first sample and its count of samples.
  struct Range {
    std::string path;
    size_t first = 0, count = 0;
  };
  std::vector<Range> ranges() const;

  // Decodes `box` of view `view` (from 0) of sample i into `out` (H W 3 elements of `layout`).
  // Throws paircast::Error naming the shard and member when the JPEG does not decode, its size
  // differs from its camera's, or the box is outside it.
  void decodeView(size_t i, int view, const CropBox& box, PixelLayout layout, void* out) const;
  // View `view`'s flow of sample i ([H, W, 2] pixels, +inf where unknown; into view
  // flowTarget(view)). Throws paircast::Error naming the shard and sample when it has none
  // (generate_pairs --save-flow), and naming the member when it does not decode.
  ImageF decodeFlow(size_t i, int view) const;

 private:
  struct Where {
    size_t shard, sample;
  };
  std::vector<ShardIndex> shards_;
  std::vector<Where> where_;
};

}  // namespace paircast
