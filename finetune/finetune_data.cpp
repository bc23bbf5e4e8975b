#include "finetune/finetune_data.h"

#include "model/croco_net.h"
#include "trainer/augment.h"
#include "trainer/pair_dataset.h"
#include "util/error.h"
#include "util/flo_io.h"
#include "util/image_io.h"
#include "util/random.h"

namespace paircast {
namespace {

void warn(const std::string& message) {
  std::fprintf(stderr, "finetune: warning: %s\n", message.c_str());
}

// Views 1 and 2 with depth and view 1's flow, or the reason the sample cannot be used.
std::string missingTruth(const IndexedSample& s) {
  if (s.record.views < 2) return "has one view";
  if (s.flow.empty()) return "has no flow (generate_pairs --save-flow)";
  if (s.depth.empty()) return "has no depth (generate_pairs --save-depth)";
  return "";
}

torch::Tensor cropPlanes(const torch::Tensor& t, int top, int left, int size) {
  return t.narrow(2, top, size).narrow(3, left, size);
}

}  // namespace

TruthPairs TruthPairs::fromShards(const std::vector<std::string>& patterns) {
  TruthPairs out;
  for (const std::string& file : expandShardPatterns(patterns)) {
    ShardIndex index = ShardIndex::open(file, warn);
    index.warnOfDamage(warn);
    for (size_t i = 0; i < index.size(); ++i) {
      const std::string why = missingTruth(index[i]);
      if (!why.empty()) throw Error(file, "sample " + index[i].key + " " + why);
      const Camera& c = index[i].record.camera[0];
      if (c.width != c.height) throw Error(file, "sample " + index[i].key + " is not square");
      if (out.side_ == 0) out.side_ = c.width;
      if (c.width != out.side_)
        throw Error(file, "sample " + index[i].key + " is " + std::to_string(c.width) +
                              " pixels wide, the others " + std::to_string(out.side_));
      out.items_.push_back({out.indexes_.size(), i});
    }
    out.indexes_.push_back(std::move(index));
  }
  if (out.items_.empty()) throw Error(patterns.empty() ? "--data" : patterns[0], "no pairs");
  return out;
}

const std::string& TruthPairs::key(size_t i) const {
  const Item& it = items_.at(i);
  return indexes_[it.index][it.sample].key;
}

TruthPair TruthPairs::load(size_t i) const {
  const Item& it = items_.at(i);
  const ShardIndex& index = indexes_[it.index];
  const IndexedSample& s = index[it.sample];
  auto bytes = [&](const Extent& e) { return index.read(e); };
  auto name = [&](MemberKind kind, int view) { return index.describe(it.sample, kind, view); };
  TruthPair p;
  p.key = s.key;
  const Bytes j1 = bytes(s.image[0]), j2 = bytes(s.image[1]);
  p.rgb1 = decodeImage8(j1.data(), j1.size(), name(MemberKind::kImage, 1));
  p.rgb2 = decodeImage8(j2.data(), j2.size(), name(MemberKind::kImage, 2));
  const Bytes f = bytes(s.flow[0]);
  p.flow = decodeFlo(f.data(), f.size(), name(MemberKind::kFlow, 1));
  const Bytes d1 = bytes(s.depth[0]), d2 = bytes(s.depth[1]);
  p.depth1 = decodeImageF(d1.data(), d1.size(), name(MemberKind::kDepth, 1));
  p.depth2 = decodeImageF(d2.data(), d2.size(), name(MemberKind::kDepth, 2));
  p.camera1 = s.record.camera[0];
  p.camera2 = s.record.camera[1];
  const int w = p.camera1.width, h = p.camera1.height;
  for (const auto* img : {&p.flow, &p.depth1, &p.depth2})
    if (img->width != w || img->height != h)
      throw Error(name(MemberKind::kFlow, 1), "sample's maps differ in size from its camera");
  if (p.depth1.channels != 1 || p.depth2.channels != 1)
    throw Error(name(MemberKind::kDepth, 1), "sample's depth maps are not single-channel");
  if (p.rgb1.width != w || p.rgb1.height != h || p.rgb2.width != w || p.rgb2.height != h)
    throw Error(name(MemberKind::kImage, 1), "sample's images differ in size from its camera");
  return p;
}

TruthBatch TruthBatch::to(const torch::Device& device) const {
  return {img1.to(device), img2.to(device), flow.to(device), depth.to(device), pose.to(device)};
}

torch::Tensor poseVector(const Camera& a, const Camera& b) {
  const Eigen::Matrix3d R = a.R_cam2world.transpose() * b.R_cam2world;
  const Eigen::Vector3d t = a.R_cam2world.transpose() * (b.t_cam2world - a.t_cam2world);
  auto out = torch::empty({12}, torch::kFloat32);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) out[r * 3 + c] = static_cast<float>(R(r, c));
  for (int k = 0; k < 3; ++k) out[9 + k] = static_cast<float>(t(k));
  return out;
}

torch::Tensor planes(const ImageF& image) {
  return torch::from_blob(const_cast<float*>(image.data.data()),
                          {image.height, image.width, image.channels}, torch::kFloat32)
      .permute({2, 0, 1})
      .unsqueeze(0)
      .clone();
}

namespace {

torch::Tensor unitImage(const Image8& rgb) {
  return torch::from_blob(const_cast<uint8_t*>(rgb.data.data()), {rgb.height, rgb.width, 3},
                          torch::kUInt8)
             .permute({2, 0, 1})
             .to(torch::kFloat32) /
         255.0;
}

// The inverse of a [12] pose: R^T, -R^T t.
torch::Tensor invertPose(const torch::Tensor& pose) {
  auto R = pose.narrow(0, 0, 9).view({3, 3}), t = pose.narrow(0, 9, 3);
  auto Rt = R.t().contiguous();
  return torch::cat({Rt.reshape({9}), -torch::mv(Rt, t)});
}

}  // namespace

torch::Tensor normalizedImage(const Image8& rgb) {
  return imagenetNormalize(unitImage(rgb).unsqueeze(0));
}

TruthBatch makeTruthBatch(const TruthPairs& data, const std::vector<size_t>& pairs,
                          const TruthAugment& a, uint64_t seed, int64_t step, size_t firstSlot) {
  const int S = a.size, side = data.side();
  if (S > side)
    throw Error("the training size " + std::to_string(S) + " is larger than the pairs' " +
                std::to_string(side) + " pixels");
  AugmentOptions jitter;  // CroCo's factors in [0.6, 1.4]
  jitter.size = S;
  jitter.colorJitter = a.colorJitter;
  std::vector<torch::Tensor> i1, i2, fl, dp, ps;
  for (size_t slot = 0; slot < pairs.size(); ++slot) {
    Rng rng(
        mixSeed(seed, "finetune-batch", static_cast<uint64_t>(step) * 65536 + firstSlot + slot));
    const TruthPair p = data.load(pairs[slot]);
    const int top = static_cast<int>(rng.below(side - S + 1));
    const int left = static_cast<int>(rng.below(side - S + 1));
    auto crop = [&](const torch::Tensor& t) {
      return cropPlanes(t.unsqueeze(0), top, left, S).squeeze(0);
    };
    // One crop box for both views: the flow keeps its values.
    torch::Tensor x1 = jitterAndNormalize(crop(unitImage(p.rgb1)), jitter, rng);
    torch::Tensor x2 = jitterAndNormalize(crop(unitImage(p.rgb2)), jitter, rng);
    torch::Tensor pose = poseVector(p.camera1, p.camera2);
    if (a.swap && rng.uniform() < 0.5) {
      std::swap(x1, x2);
      pose = invertPose(pose);
    }
    i1.push_back(x1);
    i2.push_back(x2);
    fl.push_back(cropPlanes(planes(p.flow), top, left, S).squeeze(0));
    dp.push_back(cropPlanes(planes(p.depth1), top, left, S).squeeze(0));
    ps.push_back(pose);
  }
  return {torch::stack(i1), torch::stack(i2), torch::stack(fl), torch::stack(dp), torch::stack(ps)};
}

}  // namespace paircast
