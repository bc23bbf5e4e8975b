// One shard through every consumer of the shard codec: readShard (generate_pairs, dataset_report),
// the trainer's PairDataset and its crop-decoding loader, and ShardSet (paircast.torch) agree
// sample for sample, pixel for pixel.
#include <gtest/gtest.h>

#include <cmath>

#include "dataset/fake_sample.h"
#include "dataset/shard.h"
#include "shard/shard_set.h"
#include "test_paths.h"
#include "trainer/augment.h"
#include "trainer/pair_dataset.h"
#include "util/image_io.h"
#include "util/random.h"

namespace paircast {
namespace {

// Samples of 3 views with textured 40 x 40 images, so that crops and JPEG edges matter.
PairSample texturedSample(uint64_t index) {
  PairSample s = testing::fakeSample("room", index, 3);
  for (int k = 0; k < 3; ++k) {
    s.camera[k] = Camera::fromHfov(40, 40, 60);
    s.camera[k].t_cam2world.x() = k;
    Image8 img(40, 40, 3);
    for (int y = 0; y < 40; ++y)
      for (int x = 0; x < 40; ++x)
        for (int c = 0; c < 3; ++c)
          img.pixel(x, y)[c] =
              static_cast<uint8_t>(127 + 120 * std::sin(0.3 * x + 0.2 * y * (c + 1) + k + index));
    s.rgb[k] = img;
  }
  return s;
}

TEST(ShardConsumers, AgreeSampleForSample) {
  const std::string path = testing::scratchDir("consumers") + "/pairs-000000.tar";
  {
    ShardWriter w(path);
    for (uint64_t i = 0; i < 5; ++i) w.add(encodePair(texturedSample(i), false, 90));
    w.close();
  }
  std::vector<ShardSample> whole;
  readShard(path, [&](ShardSample&& s) { whole.push_back(std::move(s)); });
  const PairDataset ds = PairDataset::fromShards({path});
  const ShardSet set = ShardSet::open({path});
  ASSERT_EQ(whole.size(), 5u);
  ASSERT_EQ(ds.size(), 5u);
  ASSERT_EQ(set.size(), 5u);
  for (size_t i = 0; i < 5; ++i) {
    ASSERT_EQ(ds.key(i), whole[i].key);
    ASSERT_EQ(set[i].key, whole[i].key);
    EXPECT_EQ(set[i].record.index, i);
    for (uint64_t draw = 0; draw < 2; ++draw) {
      const auto [first, other] = ds.load(i, draw);
      const int view = 1 + static_cast<int>(draw % 2);
      const Bytes& jpeg = whole[i].jpeg[view];
      const Image8 expected = decodeImage8(jpeg.data(), jpeg.size(), "x.jpg");
      EXPECT_EQ(other.data, expected.data) << whole[i].key << " view " << view;
      Image8 fromSet(40, 40, 3);
      set.decodeView(i, view, CropBox{0, 0, 40, 40}, PixelLayout::kUint8HWC, fromSet.data.data());
      EXPECT_EQ(fromSet.data, expected.data) << whole[i].key << " view " << view;
      // The trainer's crop path draws and decodes only the crops: the same tensors as
      // cropping the decoded images.
      AugmentOptions o;
      o.size = 24;
      Rng r1(100 + i), r2(100 + i);
      const auto [ea, eb] = ds.encoded(i, draw);
      const auto fromCrops = augmentEncodedPair(ea, eb, o, r1);
      const auto fromImages = augmentPair(first, other, o, r2);
      EXPECT_TRUE(torch::allclose(fromCrops.first, fromImages.first, 0, 1e-6));
      EXPECT_TRUE(torch::allclose(fromCrops.second, fromImages.second, 0, 1e-6));
      EXPECT_EQ(r1.next(), r2.next());  // the same draws were taken
    }
  }
}

}  // namespace
}  // namespace paircast
