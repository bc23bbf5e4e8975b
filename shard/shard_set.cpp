#include "shard/shard_set.h"

#include "util/error.h"
#include "util/flo_io.h"

namespace paircast {

ShardSet ShardSet::open(const std::vector<std::string>& files, const ShardIndex::Warn& warn) {
  ShardSet set;
  for (const std::string& file : files) {
    ShardIndex index = ShardIndex::open(file, warn);
    index.warnOfDamage(warn);
    for (size_t k = 0; k < index.size(); ++k) set.where_.push_back({set.shards_.size(), k});
    set.shards_.push_back(std::move(index));
  }
  if (set.where_.empty() && !files.empty()) throw Error(files[0], "no usable sample in the shards");
  return set;
}

const IndexedSample& ShardSet::operator[](size_t i) const {
  const Where& w = where_.at(i);
  return shards_[w.shard][w.sample];
}

const std::string& ShardSet::shard(size_t i) const {
  return shards_[where_.at(i).shard].path();
}

std::vector<ShardSet::Range> ShardSet::ranges() const {
  std::vector<Range> out;
  size_t first = 0;
  for (const ShardIndex& index : shards_) {
    out.push_back({index.path(), first, index.size()});
    first += index.size();
  }
  return out;
}

void ShardSet::decodeView(size_t i, int view, const CropBox& box, PixelLayout layout,
                          void* out) const {
  const Where& w = where_.at(i);
  const ShardIndex& index = shards_[w.shard];
  const IndexedSample& s = index[w.sample];
  PAIRCAST_CHECK(view >= 0 && view < static_cast<int>(s.image.size()));
  const std::string name = index.describe(w.sample, MemberKind::kImage, view + 1);
  const Bytes bytes = index.read(s.image[view]);
  const JpegSize size = jpegSize(bytes.data(), bytes.size(), name);
  const Camera& camera = s.record.camera[view];
  if (size.width != camera.width || size.height != camera.height)
    throw Error(name, "is " + std::to_string(size.width) + "x" + std::to_string(size.height) +
                          " but its camera is " + std::to_string(camera.width) + "x" +
                          std::to_string(camera.height));
  decodeJpegCrop(bytes.data(), bytes.size(), name, box, layout, out);
}

ImageF ShardSet::decodeFlow(size_t i, int view) const {
  const Where& w = where_.at(i);
  const ShardIndex& index = shards_[w.shard];
  const IndexedSample& s = index[w.sample];
  if (view < 0 || view >= static_cast<int>(s.flow.size()))
    throw Error(index.path(), "sample " + s.key + " has no flow (generate_pairs --save-flow)");
  const std::string name = index.describe(w.sample, MemberKind::kFlow, view + 1);
  const Bytes bytes = index.read(s.flow[view]);
  ImageF flow = decodeFlo(bytes.data(), bytes.size(), name);
  const Camera& camera = s.record.camera[view];
  if (flow.width != camera.width || flow.height != camera.height)
    throw Error(name, "is " + std::to_string(flow.width) + "x" + std::to_string(flow.height) +
                          " but its camera is " + std::to_string(camera.width) + "x" +
                          std::to_string(camera.height));
  return flow;
}

}  // namespace paircast
