// Samples of N views (CroCo's views_count) in the trainer's datasets: view 1 with another view
// drawn by the caller, from hand-made 3-view shards and CroCo folders; 2-view data ignore the
// draw.
#include "trainer/pair_dataset.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>

#include "model/checkpoint.h"
#include "test_errors.h"
#include "test_paths.h"
#include "test_tar.h"
#include "trainer/trainer.h"
#include "util/error.h"
#include "util/random.h"

namespace paircast {
namespace {

namespace fs = std::filesystem;
using testing::jpegBytes;
using testing::TarMember;
using testing::ustar;

// View k of sample s as a flat grey that survives JPEG: 30 + 40 k + 7 s.
int greyOf(int sample, int view) {
  return 30 + 40 * view + 7 * sample;
}
// Which view an image decoded from greyOf(sample, ·) shows (0 when none).
int viewOf(const Image8& img, int sample) {
  for (int k = 1; k <= 4; ++k)
    if (std::abs(img.data[img.data.size() / 2] - greyOf(sample, k)) <= 4) return k;
  return 0;
}

std::string writeFile(const std::string& path, const std::string& bytes) {
  fs::create_directories(fs::path(path).parent_path());
  std::ofstream(path, std::ios::binary) << bytes;
  return path;
}

// The members of sample `key` with the given views, as generate_pairs --views N writes them:
// K.k.jpg for each view, optional depth and covis members, then K.json.
std::vector<TarMember> sampleMembers(const std::string& key, int sample,
                                     const std::vector<int>& views) {
  std::vector<TarMember> m;
  for (int k : views) {
    m.push_back({key + "." + std::to_string(k) + ".jpg", jpegBytes(greyOf(sample, k))});
    m.push_back({key + "." + std::to_string(k) + ".depth.exr", "not read by the trainer"});
  }
  m.push_back(testing::recordMember(key, static_cast<int>(views.size())));
  return m;
}

std::vector<TarMember> concat(std::vector<std::vector<TarMember>> parts) {
  std::vector<TarMember> all;
  for (auto& p : parts) all.insert(all.end(), p.begin(), p.end());
  return all;
}

TEST(PairDatasetViews, ThreeViewShardsPairViewOneWithTheDrawnView) {
  const std::string dir = testing::scratchDir("shards");
  const std::string path =
      writeFile(dir + "/pairs-000000.tar", ustar(concat({sampleMembers("s-00000000", 0, {1, 2, 3}),
                                                         sampleMembers("s-00000001", 1, {1, 2})})));
  const PairDataset ds = PairDataset::fromShards({dir + "/pairs-*.tar"});
  ASSERT_EQ(ds.size(), 2u);
  EXPECT_EQ(ds.key(0), "s-00000000");
  EXPECT_EQ(ds.views(0), 3u);
  EXPECT_EQ(ds.views(1), 2u);
  std::set<int> seen;
  Rng rng(3);
  for (int t = 0; t < 20; ++t) {
    const uint64_t draw = rng.next();
    const auto [x, y] = ds.load(0, draw);
    EXPECT_EQ(viewOf(x, 0), 1);
    const int other = viewOf(y, 0);
    EXPECT_EQ(other, 2 + static_cast<int>(draw % 2)) << draw;
    seen.insert(other);
    // The same draw, the same view.
    EXPECT_EQ(viewOf(ds.load(0, draw).second, 0), other);
    // A pair ignores the draw: always view 2.
    const auto [a, b] = ds.load(1, draw);
    EXPECT_EQ(viewOf(a, 1), 1);
    EXPECT_EQ(viewOf(b, 1), 2);
  }
  EXPECT_EQ(seen, (std::set<int>{2, 3}));
  EXPECT_EQ(viewOf(ds.load(0).second, 0), 2);  // no draw: view 2
}

TEST(PairDatasetViews, ShardSamplesMissingViewOneOrWithOneViewAreSkipped) {
  const std::string dir = testing::scratchDir("incomplete");
  auto members = concat({
      sampleMembers("a-00000000", 0, {2, 3}),     // no view 1
      sampleMembers("b-00000000", 1, {1}),        // view 1 alone
      sampleMembers("c-00000000", 2, {3, 1}),     // views 1 and 3 of a 2-view record
      sampleMembers("d-00000000", 3, {1, 2, 3}),  // whole
      {{"e-00000000.1.jpg", jpegBytes(greyOf(4, 1))},
       {"e-00000000.2.jpg", ""},  // empty: missing
       {"f-00000000.1.jpg", jpegBytes(greyOf(5, 1))},
       {"f-00000000.01.jpg", jpegBytes(greyOf(5, 2))},  // not a view number
       {"f-00000000.0.jpg", jpegBytes(greyOf(5, 2))},
       {"f-00000000.2.png", jpegBytes(greyOf(5, 2))}},
  });
  const std::string path = writeFile(dir + "/mixed.tar", ustar(members));
  const PairDataset ds = PairDataset::fromShards({path});
  // The shard format wants views 1..V for a record of V views: c's view 2 is missing.
  ASSERT_EQ(ds.size(), 1u);
  EXPECT_EQ(ds.key(0), "d-00000000");
  EXPECT_EQ(ds.views(0), 3u);
  EXPECT_EQ(viewOf(ds.load(0, 0).first, 3), 1);
  EXPECT_EQ(viewOf(ds.load(0, 0).second, 3), 2);
  // Nothing complete at all is an error naming the shard.
  const std::string none = writeFile(
      dir + "/none.tar",
      ustar(concat({sampleMembers("a-00000000", 0, {2, 3}), sampleMembers("b-00000000", 1, {1})})));
  testing::refusalOf(none, [&] { PairDataset::fromShards({none}); });
}

// A CroCo folder: <scene>/<idx:08>_<k>.jpeg, and pairs.txt with the (1, k) lines.
std::string crocoFolder(const std::string& dir, const std::vector<int>& viewsPerSample,
                        bool writeViewOne = true) {
  std::string list;
  for (size_t s = 0; s < viewsPerSample.size(); ++s) {
    char base[32];
    std::snprintf(base, sizeof base, "scene/%08zu_", s);
    for (int k = 1; k <= viewsPerSample[s]; ++k) {
      if (k > 1 || writeViewOne)
        writeFile(dir + "/" + base + std::to_string(k) + ".jpeg",
                  jpegBytes(greyOf(static_cast<int>(s), k)));
      if (k > 1) list += std::string(base) + "1.jpeg " + base + std::to_string(k) + ".jpeg\n";
    }
  }
  writeFile(dir + "/pairs.txt", list);
  return dir;
}

TEST(PairDatasetViews, CrocoFoldersGroupTheLinesOfOneFirstImage) {
  // Mixed N: 3 views, 2 views, 4 views.
  const std::string dir = crocoFolder(testing::scratchDir("croco"), {3, 2, 4});
  // A repeated line does not weigh its view twice.
  std::ofstream(dir + "/pairs.txt", std::ios::app)
      << "scene/00000000_1.jpeg scene/00000000_2.jpeg\n";
  const PairDataset ds = PairDataset::fromCrocoDir(dir);
  ASSERT_EQ(ds.size(), 3u);
  EXPECT_EQ(ds.key(0), "scene/00000000_1.jpeg");
  EXPECT_EQ(ds.views(0), 3u);
  EXPECT_EQ(ds.views(1), 2u);
  EXPECT_EQ(ds.views(2), 4u);
  for (uint64_t draw = 0; draw < 12; ++draw) {
    for (int s = 0; s < 3; ++s) {
      const auto [x, y] = ds.load(s, draw);
      EXPECT_EQ(viewOf(x, s), 1);
      EXPECT_EQ(viewOf(y, s), 2 + static_cast<int>(draw % (ds.views(s) - 1))) << s << " " << draw;
    }
  }
}

TEST(PairDatasetViews, ACrocoSampleMissingViewOneNamesTheFile) {
  const std::string dir = crocoFolder(testing::scratchDir("nofirst"), {3}, false);
  const PairDataset ds = PairDataset::fromCrocoDir(dir);
  ASSERT_EQ(ds.size(), 1u);
  testing::refusalOf(dir + "/scene/00000000_1.jpeg", [&] { ds.load(0, 1); });
}

// Pre-training on 3-view shards: the other view is drawn from the run's seeded streams, so a
// run that stops and resumes ends with the same weights as one that does not.
TEST(PairDatasetViews, TrainingOnThreeViewsResumesExactly) {
  const std::string dir = testing::scratchDir("train");
  std::vector<TarMember> members;
  Rng rng(5);
  for (int s = 0; s < 8; ++s) {
    const std::string key = "s-0000000" + std::to_string(s);
    for (int k = 1; k <= 3; ++k) {
      Image8 img(40, 40, 3);
      for (auto& v : img.data) v = static_cast<uint8_t>(rng.below(256));
      const auto bytes = encodeImage(img, "jpg", 90);
      members.push_back(
          {key + "." + std::to_string(k) + ".jpg", std::string(bytes.begin(), bytes.end())});
    }
    members.push_back(testing::recordMember(key, 3, 40, 40));
  }
  writeFile(dir + "/pairs-000000.tar", ustar(members));
  auto run = [&](const std::string& out, int64_t steps, bool resume) {
    TrainConfig c;
    c.shards = {dir + "/pairs-*.tar"};
    c.model = presetConfig("tiny");
    c.model.img_size = 32;
    c.model.patch_size = 8;
    c.batchSize = 4;
    c.epochs = 4;
    c.out = out;
    c.workers = 1;
    c.saveEvery = 1;
    c.progress = false;
    c.maxSteps = steps;
    c.resume = resume;
    return runPretrain(c);
  };
  EXPECT_EQ(run(dir + "/whole", 4, false)["steps"], 4);
  run(dir + "/split", 2, false);
  EXPECT_EQ(run(dir + "/split", 4, true)["steps_this_run"], 2);
  const Checkpoint a = loadCheckpoint(dir + "/whole/checkpoint-last.pth");
  const Checkpoint b = loadCheckpoint(dir + "/split/checkpoint-last.pth");
  for (const auto& [k, t] : a.model)
    EXPECT_TRUE(torch::equal(t, b.model.at(k))) << k << " differs after resume";
}

}  // namespace
}  // namespace paircast
