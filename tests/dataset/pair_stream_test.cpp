#include "dataset/pair_stream.h"

#include <gtest/gtest.h>

#include <set>

#include "dataset/test_scenes.h"
#include "test_errors.h"
#include "test_paths.h"
#include "util/error.h"

namespace paircast {
namespace {

PairStreamOptions streamOptions(const std::string& dir) {
  testing::writeBoxesObj(dir + "/room.obj", testing::roomBoxes());
  PairStreamOptions o;
  o.scenes = {dir + "/room.obj"};
  o.pair.resolution = 40;
  o.threads = 2;
  o.queueCapacity = 4;
  return o;
}

TEST(PairStream, DeliversPairsInTheBandFromWorkerThreads) {
  PairStream stream(streamOptions(testing::scratchDir("s")));
  std::set<uint64_t> seen;
  for (int i = 0; i < 8; ++i) {
    auto p = stream.next();
    ASSERT_TRUE(p.has_value());
    EXPECT_GE(p->covis[1].covis, 0.5);
    EXPECT_EQ(p->rgb[0].width, 40);
    EXPECT_TRUE(seen.insert(p->index).second) << "pair " << p->index << " delivered twice";
  }
  EXPECT_EQ(stream.position(), 8u);
  stream.stop();
  // After stop(), next() drains what was queued and then returns nullopt instead of blocking.
  int drained = 0;
  while (stream.next().has_value()) ASSERT_LE(++drained, 4);
}

TEST(PairStream, PartsAreDisjoint) {
  const std::string dir = testing::scratchDir("parts");
  PairStreamOptions a = streamOptions(dir), b = a;
  a.partCount = b.partCount = 2;
  b.partIndex = 1;
  a.threads = b.threads = 1;
  std::set<uint64_t> ia, ib;
  {
    PairStream sa(a), sb(b);
    for (int i = 0; i < 4; ++i) {
      ia.insert(sa.next()->index);
      ib.insert(sb.next()->index);
    }
  }
  for (uint64_t i : ia) EXPECT_EQ(ib.count(i), 0u);
}

TEST(PairStream, NoUsableSceneIsAnError) {
  const std::string dir = testing::scratchDir("none");
  testing::writeBoxesObj(dir + "/wall.obj", {{{0, 0, 0}, {0.1f, 3, 4}}});
  PairStreamOptions o;
  o.scenes = {dir + "/wall.obj"};
  EXPECT_ERROR_CONTAINS(PairStream stream(o), "no usable scene for the live pair stream");
}

}  // namespace
}  // namespace paircast
