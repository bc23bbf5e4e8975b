#include "shard/shard_batches.h"

#include <zlib.h>

#include <algorithm>
#include <cmath>

#include "util/error.h"
#include "util/numpy_random.h"

namespace paircast {

PairPlan drawPair(const ShardSet& set, size_t sample, uint64_t seed, uint64_t epoch, int height,
                  int width, bool flow) {
  const IndexedSample& s = set[sample];
  const std::string& scene = s.record.scene;
  const uLong crc =
      crc32(0L, reinterpret_cast<const Bytef*>(scene.data()), static_cast<uInt>(scene.size()));
  NumpyGenerator rng(
      {seed, epoch, static_cast<uint64_t>(crc), static_cast<uint64_t>(s.record.index)});
  PairPlan p;
  p.sample = sample;
  const int views = s.record.views;
  if (views < 2) {
    p.view = 0;
    return p;
  }
  p.view = views == 2 || flow ? 1 : static_cast<int>(rng.integers(1, views));
  const int imageHeight = s.record.camera[0].height, imageWidth = s.record.camera[0].width;
  if (height > imageHeight || width > imageWidth)
    throw Error(s.key, "crop (" + std::to_string(height) + ", " + std::to_string(width) +
                           ") is larger than the images (" + std::to_string(imageHeight) + " x " +
                           std::to_string(imageWidth) + ")");
  for (CropBox* box : {&p.first, &p.second}) {
    box->top = static_cast<int>(rng.integers(0, imageHeight - height + 1));
    box->left = static_cast<int>(rng.integers(0, imageWidth - width + 1));
    box->height = height;
    box->width = width;
  }
  return p;
}

void cropFlow(const ImageF& flow, const CropBox& from, const CropBox& to, float* out,
              uint8_t* valid) {
  const size_t plane = static_cast<size_t>(from.height) * from.width;
  const float shift[2] = {static_cast<float>(from.left - to.left),
                          static_cast<float>(from.top - to.top)};
  for (int y = 0; y < from.height; ++y)
    for (int x = 0; x < from.width; ++x) {
      const float* f =
          &flow.data[(static_cast<size_t>(from.top + y) * flow.width + from.left + x) * 2];
      const size_t i = static_cast<size_t>(y) * from.width + x;
      out[i] = f[0] + shift[0];
      out[plane + i] = f[1] + shift[1];
      valid[i] = std::isfinite(out[i]) && std::isfinite(out[plane + i]);
    }
}

void relativePose(const Camera& camera1, const Camera& camera2, double* out) {
  const Eigen::Matrix3d R = camera1.R_cam2world.transpose() * camera2.R_cam2world;
  const Eigen::Vector3d t =
      camera1.R_cam2world.transpose() * (camera2.t_cam2world - camera1.t_cam2world);
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c)
      out[r * 4 + c] = r == 3 ? (c == 3 ? 1.0 : 0.0) : c == 3 ? t(r) : R(r, c);
}

ShardBatches::ShardBatches(const ShardSet& set, std::vector<size_t> order, const Options& o,
                           std::vector<std::array<void*, 2>> buffers,
                           std::vector<TruthBuffers> truth)
    : set_(set),
      order_(std::move(order)),
      o_(o),
      buffers_(std::move(buffers)),
      truth_(std::move(truth)) {
  if (o.batchSize < 1 || o.height < 1 || o.width < 1 || o.threads < 1 || o.prefetch < 1 ||
      o.keep < 0)
    throw Error("ShardBatches: batch size, crop, threads and prefetch must be positive");
  if (o.layout != PixelLayout::kUint8CHW && o.layout != PixelLayout::kNormalizedFloatCHW)
    throw Error("ShardBatches: the layout must be uint8 or normalised float32, [3, H, W]");
  if (static_cast<int>(buffers_.size()) != depthOf(o))
    throw Error("ShardBatches: " + std::to_string(depthOf(o)) + " buffers needed, " +
                std::to_string(buffers_.size()) + " given");
  if (o.flow && static_cast<int>(truth_.size()) != depthOf(o))
    throw Error("ShardBatches: " + std::to_string(depthOf(o)) + " ground-truth buffers needed, " +
                std::to_string(truth_.size()) + " given");
  for (size_t i : order_)
    if (i >= set_.size())
      throw Error("ShardBatches: sample " + std::to_string(i) + " of " +
                  std::to_string(set_.size()));
  BatchRing::Options r;
  r.threads = o.threads;
  r.batchSize = o.batchSize;
  r.prefetch = o.prefetch;
  r.keep = o.keep;
  r.items = static_cast<int64_t>(order_.size());
  r.dropLast = o.dropLast;
  ring_ = std::make_unique<BatchRing>(
      r, [this](int64_t item, int64_t, int slot, int buffer) { return fill(item, slot, buffer); });
}

ShardBatches::~ShardBatches() {
  ring_.reset();  // the workers stop before the order goes
}

bool ShardBatches::fill(int64_t item, int slot, int buffer) {
  const size_t sample = order_[static_cast<size_t>(item)];
  // A crop larger than the images is the caller's error: it stops the loader.
  const PairPlan p = drawPair(set_, sample, o_.seed, o_.epoch, o_.height, o_.width, o_.flow);
  if (p.view == 0) return drop(item, set_[sample].key + ": one view, no pair");
  // Shards without flow are the caller's error too.
  if (o_.flow && set_[sample].flow.empty())
    throw Error(set_.shard(sample),
                "sample " + set_[sample].key + " has no flow (generate_pairs --save-flow)");
  const size_t element = o_.layout == PixelLayout::kUint8CHW ? 1 : sizeof(float);
  const size_t offset = size_t{3} * o_.height * o_.width * element * slot;
  try {
    set_.decodeView(sample, 0, p.first, o_.layout,
                    static_cast<char*>(buffers_[buffer][0]) + offset);
    set_.decodeView(sample, p.view, p.second, o_.layout,
                    static_cast<char*>(buffers_[buffer][1]) + offset);
    if (o_.flow) {
      const TruthBuffers& t = truth_[buffer];
      const size_t plane = static_cast<size_t>(o_.height) * o_.width;
      cropFlow(set_.decodeFlow(sample, 0), p.first, p.second, t.flow + 2 * plane * slot,
               t.valid + plane * slot);
      relativePose(set_[sample].record.camera[0], set_[sample].record.camera[1],
                   t.pose + 16 * slot);
    }
    return true;
  } catch (const Error& e) {
    return drop(item, e.what());
  }
}

bool ShardBatches::drop(int64_t item, const std::string& why) {
  std::lock_guard<std::mutex> lock(errorsMu_);
  errors_[item] = why;
  return false;
}

std::optional<ShardBatches::Batch> ShardBatches::next() {
  Batch out;
  while (true) {
    auto r = ring_->next();
    if (!r) return std::nullopt;
    if (r->failed.empty()) {
      out.buffer = r->buffer;
      out.size = r->size;
      return out;
    }
    // Drop the failed pairs and redo this batch and the ones after it.
    ring_->redo([&] {
      const int64_t first = r->batch * o_.batchSize;
      std::lock_guard<std::mutex> lock(errorsMu_);
      for (int slot : r->failed) out.skipped.push_back(errors_[first + slot]);
      for (auto it = r->failed.rbegin(); it != r->failed.rend(); ++it)
        order_.erase(order_.begin() + first + *it);
      errors_.clear();
      return static_cast<int64_t>(order_.size());
    });
  }
}

}  // namespace paircast
