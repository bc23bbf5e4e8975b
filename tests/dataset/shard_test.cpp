#include "dataset/shard.h"

#include <archive.h>
#include <archive_entry.h>
#include <gtest/gtest.h>

#include <filesystem>

#include "fake_sample.h"
#include "test_errors.h"
#include "test_paths.h"
#include "util/atomic_file.h"
#include "util/error.h"

namespace paircast {
namespace {

namespace fs = std::filesystem;

PairSample fakePair(uint64_t index, bool depth) {
  return testing::fakeSample("my.scene", index, 2, depth);
}

std::string writeShard(const std::string& dir, int n, bool depth) {
  const std::string path = dir + "/pairs-000000.tar";
  ShardWriter w(path);
  for (int i = 0; i < n; ++i) w.add(encodePair(fakePair(i, depth), depth, 90));
  w.close();
  return path;
}

TEST(Shard, RoundTrip) {
  const std::string path = writeShard(testing::scratchDir("rt"), 3, true);
  std::vector<ShardSample> got;
  const size_t n = readShard(path, [&](ShardSample&& s) { got.push_back(std::move(s)); });
  ASSERT_EQ(n, 3u);
  EXPECT_EQ(got[2].key, "my_scene-00000002");  // dots are not allowed in keys
  EXPECT_EQ(got[2].record["index"], 2);
  EXPECT_EQ(got[2].record["scene"], "my.scene");
  EXPECT_DOUBLE_EQ(got[1].record["v_ji"].get<double>(), 0.7);
  const Camera c = cameraFromJson(got[1].record["camera2"], "rec");
  EXPECT_DOUBLE_EQ(c.t_cam2world.z(), 1.0);
  EXPECT_FALSE(got[0].depthExr[1].empty());
  EXPECT_EQ(
      ShardIndex::keys(path),
      (std::vector<std::string>{"my_scene-00000000", "my_scene-00000001", "my_scene-00000002"}));
}

// generate_pairs learns a complete shard's pairs from its headers alone; a cut one throws.
TEST(Shard, KeysFromTheHeadersAloneMatchTheCheckedOnes) {
  const std::string dir = testing::scratchDir("keys");
  const std::string path = writeShard(dir, 4, true);
  const ShardIndex index = ShardIndex::open(path);
  std::vector<std::string> checked;  // the keys of the samples the full index accepts
  for (const IndexedSample& sample : index.samples()) checked.push_back(sample.key);
  EXPECT_EQ(ShardIndex::keys(path), checked);
  const std::string bytes = readFile(path);
  writeFileAtomic(dir + "/cut.tar", bytes.substr(0, bytes.size() * 6 / 10));
  EXPECT_ERROR_CONTAINS(ShardIndex::keys(dir + "/cut.tar"),
                        dir + "/cut.tar: shard is truncated or corrupt");
}

TEST(Shard, UnclosedWriterLeavesNothing) {
  const std::string dir = testing::scratchDir("unclosed");
  {
    ShardWriter w(dir + "/pairs-000000.tar");
    w.add(encodePair(fakePair(0, false), false, 90));
  }
  EXPECT_TRUE(fs::is_empty(dir));
}

TEST(Shard, TruncatedShardDeliversWhatPrecedesTheDamageThenFails) {
  const std::string dir = testing::scratchDir("trunc");
  const std::string path = writeShard(dir, 4, true);
  const std::string bytes = readFile(path);
  writeFileAtomic(path, bytes.substr(0, bytes.size() * 6 / 10));
  size_t delivered = 0;
  try {
    readShard(path, [&](ShardSample&&) { ++delivered; });
    FAIL() << "truncation not detected";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("pairs-000000.tar"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("truncated"), std::string::npos) << e.what();
  }
  EXPECT_GE(delivered, 1u);
  EXPECT_LT(delivered, 4u);
  EXPECT_ERROR_CONTAINS(readShard(dir + "/none.tar", [](ShardSample&&) {}),
                        dir + "/none.tar: no such shard");
}

// Writes a tar with hand-made entries, for the malformed cases.
void writeRawTar(const std::string& path,
                 const std::vector<std::pair<std::string, std::string>>& files,
                 const std::string& symlink = "") {
  archive* a = archive_write_new();
  archive_write_set_format_ustar(a);
  archive_write_open_filename(a, path.c_str());
  for (const auto& [name, data] : files) {
    archive_entry* e = archive_entry_new();
    archive_entry_set_pathname(e, name.c_str());
    archive_entry_set_size(e, data.size());
    archive_entry_set_filetype(e, AE_IFREG);
    archive_entry_set_perm(e, 0644);
    archive_write_header(a, e);
    archive_write_data(a, data.data(), data.size());
    archive_entry_free(e);
  }
  if (!symlink.empty()) {
    archive_entry* e = archive_entry_new();
    archive_entry_set_pathname(e, symlink.c_str());
    archive_entry_set_filetype(e, AE_IFLNK);
    archive_entry_set_symlink(e, "/etc/passwd");
    archive_write_header(a, e);
    archive_entry_free(e);
  }
  archive_write_close(a);
  archive_write_free(a);
}

TEST(Shard, MalformedSamplesAndUnsafeEntriesAreSkippedAndReported) {
  const std::string dir = testing::scratchDir("bad");
  const std::string good = encodePair(fakePair(0, false), false, 90).record.dump();
  writeRawTar(dir + "/bad.tar",
              {{"a-1.1.jpg", "x"},
               {"a-1.2.jpg", "y"},
               {"a-1.json", "{not json"},  // bad JSON
               {"b-1.1.jpg", "x"},
               {"b-1.json", good},  // missing member
               {"../evil.1.jpg", "x"},
               {"/abs.2.jpg", "x"},  // unsafe paths
               {"d-1.1.jpg", "x"},
               {"d-1.2.jpg", "y"},
               {"d-1.json", good}},
              "e-1.1.jpg");
  std::vector<std::string> keys, errors;
  readShard(
      dir + "/bad.tar", [&](ShardSample&& s) { keys.push_back(s.key); },
      [&](const std::string& e) { errors.push_back(e); });
  EXPECT_EQ(keys, std::vector<std::string>{"d-1"});
  std::string all;
  for (const auto& e : errors) all += e + "\n";
  EXPECT_NE(all.find("'a-1' is incomplete"), std::string::npos) << all;
  EXPECT_NE(all.find("'b-1' is incomplete"), std::string::npos) << all;
  EXPECT_NE(all.find("../evil.1.jpg"), std::string::npos) << all;
  EXPECT_NE(all.find("/abs.2.jpg"), std::string::npos) << all;
  EXPECT_NE(all.find("e-1.1.jpg"), std::string::npos) << all;
  EXPECT_FALSE(fs::exists(dir + "/../evil.1.jpg"));
}

TEST(Shard, AnotherVersionIsRefusedWholeNamingTheShardAndBothVersions) {
  const std::string dir = testing::scratchDir("version");
  nlohmann::json future = encodePair(fakePair(1, false), false, 90).record;
  future["paircast_shard_version"] = kShardVersion + 1;
  const std::string good = encodePair(fakePair(0, false), false, 90).record.dump();
  writeRawTar(dir + "/future.tar", {{"a-0.1.jpg", "x"},
                                    {"a-0.2.jpg", "y"},
                                    {"a-0.json", good},
                                    {"b-1.1.jpg", "x"},
                                    {"b-1.2.jpg", "y"},
                                    {"b-1.json", future.dump()}});
  size_t delivered = 0;
  const std::string why = testing::refusalOf(dir + "/future.tar", [&] {
    readShard(dir + "/future.tar", [&](ShardSample&&) { ++delivered; });
  });
  EXPECT_EQ(delivered, 0u);  // refused whole, not sample by sample
  EXPECT_NE(why.find("paircast_shard_version " + std::to_string(kShardVersion + 1)),
            std::string::npos)
      << why;
  EXPECT_NE(why.find("reads version " + std::to_string(kShardVersion)), std::string::npos) << why;
  EXPECT_NE(why.find("regenerate"), std::string::npos) << why;
}

TEST(Shard, OversizedEntriesAreRefusedBeforeAllocation) {
  const std::string path = writeShard(testing::scratchDir("big"), 1, false);
  ShardReadOptions small;
  small.maxEntryBytes = 100;  // the JPEGs are larger
  std::vector<std::string> errors;
  const size_t n = readShard(
      path, [](ShardSample&&) {}, [&](const std::string& e) { errors.push_back(e); }, small);
  EXPECT_EQ(n, 0u);
  EXPECT_FALSE(errors.empty());
}

}  // namespace
}  // namespace paircast
