// The shard codec's index: samples grouped from the ustar headers alone, records checked against
// their members, another version refused whole, damage kept apart from the samples before it.
#include "shard/shard_index.h"

#include <gtest/gtest.h>

#include <fstream>

#include "shard/shard_set.h"
#include "test_errors.h"
#include "test_paths.h"
#include "test_tar.h"
#include "util/error.h"

namespace paircast {
namespace {

using testing::recordMember;
using testing::TarMember;
using testing::ustar;

std::string write(const std::string& name, const std::string& bytes) {
  const std::string path = testing::scratchDir("shard_index") + "/" + name;
  std::ofstream(path, std::ios::binary) << bytes;
  return path;
}

// The members of a sample of `views` views, K.k.jpg (and K.k.depth.exr) then K.json.
std::vector<TarMember> sample(const std::string& key, int views, bool depth = false) {
  std::vector<TarMember> m;
  for (int k = 1; k <= views; ++k) {
    m.push_back({memberName(key, MemberKind::kImage, k), testing::jpegBytes(10 * k)});
    if (depth) m.push_back({memberName(key, MemberKind::kDepth, k), "exr bytes"});
  }
  m.push_back(recordMember(key, views));
  return m;
}

std::vector<TarMember> concat(std::vector<std::vector<TarMember>> parts) {
  std::vector<TarMember> all;
  for (auto& p : parts) all.insert(all.end(), p.begin(), p.end());
  return all;
}

struct Indexed {
  std::vector<std::string> keys;
  std::string warnings;
  std::string damage;
};

Indexed indexOf(const std::string& path) {
  Indexed r;
  const ShardIndex index =
      ShardIndex::open(path, [&](const std::string& w) { r.warnings += w + "\n"; });
  for (const IndexedSample& s : index.samples()) r.keys.push_back(s.key);
  r.damage = index.damage();
  return r;
}

TEST(ShardIndex, MemberNamesRoundTripAndOthersAreNotOurs) {
  for (MemberKind kind : {MemberKind::kImage, MemberKind::kDepth, MemberKind::kCovisMask}) {
    for (int view : {1, 2, 9, 10, kMaxViews}) {
      const auto m = parseMemberName(memberName("room-00000003", kind, view));
      ASSERT_TRUE(m);
      EXPECT_EQ(m->key, "room-00000003");
      EXPECT_EQ(m->kind, kind);
      EXPECT_EQ(m->view, view);
    }
  }
  EXPECT_EQ(parseMemberName("k.json")->kind, MemberKind::kRecord);
  for (const char* other :
       {"k.01.jpg", "k.0.jpg", "k.100.jpg", "k.2.png", "k.1.jpeg", "k", ".json"})
    EXPECT_FALSE(parseMemberName(other)) << other;
}

TEST(ShardIndex, GroupsSamplesWithTheirRecordsAndMembers) {
  const std::string path =
      write("good.tar", ustar(concat({sample("a-00000000", 2, true), sample("b-00000001", 3)})));
  const ShardIndex index = ShardIndex::open(path);
  ASSERT_EQ(index.size(), 2u);
  EXPECT_FALSE(index.damaged());
  EXPECT_EQ(index[0].record.scene, "a");
  EXPECT_EQ(index[0].depth.size(), 2u);
  EXPECT_EQ(index[1].record.index, 1u);
  EXPECT_EQ(index[1].record.views, 3);
  EXPECT_EQ(index[1].image.size(), 3u);
  EXPECT_TRUE(index[1].depth.empty());
  const Bytes jpeg = index.read(index[1].image[2]);
  EXPECT_EQ(std::string(jpeg.begin(), jpeg.end()), testing::jpegBytes(30));
  EXPECT_EQ(index.describe(1, MemberKind::kImage, 3), path + ": b-00000001.3.jpg");
}

TEST(ShardIndex, SamplesWhoseViewsDisagreeWithTheirRecordAreSkippedAndNamed) {
  auto extra = sample("b-00000001", 2);
  extra.insert(extra.begin() + 2, {memberName("b-00000001", MemberKind::kImage, 3), "x"});
  auto halfDepth = sample("c-00000002", 2);
  halfDepth.insert(halfDepth.begin() + 1, {memberName("c-00000002", MemberKind::kDepth, 1), "d"});
  auto missing = sample("d-00000003", 3);
  missing.erase(missing.begin() + 1);  // view 2
  const std::string path = write(
      "views.tar",
      ustar(concat({sample("a-00000000", 2), extra, halfDepth, missing, sample("e-00000004", 1)})));
  const Indexed r = indexOf(path);
  EXPECT_EQ(r.keys, (std::vector<std::string>{"a-00000000", "e-00000004"}));
  for (const char* fragment :
       {": sample 'b-00000001' has members of 3 views but its record names 2, skipped",
        ": sample 'c-00000002' is incomplete, skipped",
        ": sample 'd-00000003' is incomplete, skipped"})
    EXPECT_NE(r.warnings.find(path + fragment), std::string::npos) << fragment << " in\n"
                                                                   << r.warnings;
}

TEST(ShardIndex, AnotherVersionIsRefusedWholeWithBothVersions) {
  nlohmann::json future = nlohmann::json::parse(recordMember("b-00000001", 2).data);
  future["paircast_shard_version"] = kShardVersion + 7;
  auto b = sample("b-00000001", 2);
  b.back().data = future.dump();
  const std::string path = write("future.tar", ustar(concat({sample("a-00000000", 2), b})));
  const std::string why = testing::refusalOf(path, [&] { ShardIndex::open(path); });
  EXPECT_NE(why.find("paircast_shard_version " + std::to_string(kShardVersion + 7) +
                     ", this build reads version " + std::to_string(kShardVersion)),
            std::string::npos)
      << why;
  // Every reader on top of it refuses it the same way.
  testing::refusalOf(path, [&] { ShardSet::open({path}); });
}

TEST(ShardIndex, ATruncatedShardKeepsItsWholeSamplesAndSaysWhere) {
  const std::string whole = ustar(concat({sample("a-00000000", 2), sample("b-00000001", 2)}));
  const std::string path = write("cut.tar", whole.substr(0, whole.size() - 1024 - 600));
  const Indexed r = indexOf(path);
  EXPECT_EQ(r.keys, std::vector<std::string>{"a-00000000"});
  EXPECT_NE(r.damage.find("shard is truncated or corrupt: entry 'b-00000001.json' is cut off"),
            std::string::npos)
      << r.damage;
  // A header whose checksum is wrong is damage too.
  std::string bad = whole;
  bad[1] ^= 0x20;  // the first member's name
  const Indexed c = indexOf(write("checksum.tar", bad));
  EXPECT_TRUE(c.keys.empty());
  EXPECT_NE(c.damage.find("a damaged header at byte 0"), std::string::npos) << c.damage;
  // Nothing usable at all, through ShardSet: one line naming the shard.
  const std::string garbage = write("garbage.tar", std::string(4096, 'g'));
  testing::refusalOf(garbage, [&] { ShardSet::open({garbage}); });
  testing::refusalOf("none.tar", [&] { ShardIndex::open(testing::scratchDir("x") + "/none.tar"); });
}

TEST(ShardIndex, GnuLongNamesAndPaxPathsNameTheNextMember) {
  auto members = sample("a-00000000", 2);
  std::vector<TarMember> withLong;
  const std::string longKey = "s" + std::string(110, 'x') + "-00000001";
  withLong.push_back({"././@LongLink", memberName(longKey, MemberKind::kImage, 1) + '\0', 'L'});
  withLong.push_back({"placeholder1", testing::jpegBytes(10)});
  withLong.push_back({"PaxHeader", "", 'x'});
  const std::string pax = " path=" + memberName(longKey, MemberKind::kImage, 2) + "\n";
  const std::string record = std::to_string(pax.size() + 3) + pax;  // the length counts itself
  withLong.back().data = record;
  withLong.push_back({"placeholder2", testing::jpegBytes(20)});
  withLong.push_back({"././@LongLink", longKey + ".json", 'L'});
  withLong.push_back({"placeholder3", recordMember(longKey, 2).data});
  members.insert(members.end(), withLong.begin(), withLong.end());
  const Indexed r = indexOf(write("long.tar", ustar(members)));
  EXPECT_EQ(r.keys, (std::vector<std::string>{"a-00000000", longKey})) << r.warnings;
}

// Pax records whose lengths are lies: one so large that adding it to the position wraps around
// to the start (which looped for ever), a zero, and one shorter than its own digits. The scan
// stops reading the header and the samples around it are still indexed.
TEST(ShardIndex, PaxRecordsWhoseLengthsLieEndTheHeaderWithoutLooping) {
  for (const std::string& lie : {std::string("6 a=b\n18446744073709551610 x\n"),
                                 std::string("0 path=x\n"), std::string("2 path=x\n")}) {
    auto members = sample("a-00000000", 2);
    members.push_back({"PaxHeader", lie, 'x'});
    const auto next = sample("b-00000001", 2);
    members.insert(members.end(), next.begin(), next.end());
    const Indexed r = indexOf(write("pax.tar", ustar(members)));
    EXPECT_EQ(r.keys, (std::vector<std::string>{"a-00000000", "b-00000001"})) << lie;
  }
}

// A sample's record is parsed into nested containers several times its size: one past 1 MiB is
// skipped, named, without being read.
TEST(ShardIndex, AnOversizedRecordIsSkippedUnread) {
  auto members = sample("a-00000000", 2);
  auto big = sample("b-00000001", 2);
  big.back().data = std::string((1 << 20) + 1, '[');
  members.insert(members.end(), big.begin(), big.end());
  const Indexed r = indexOf(write("record.tar", ustar(members)));
  EXPECT_EQ(r.keys, (std::vector<std::string>{"a-00000000"}));
  EXPECT_NE(r.warnings.find("sample 'b-00000001''s record is 1048577 bytes (at most 1048576), "
                            "skipped"),
            std::string::npos)
      << r.warnings;
}

}  // namespace
}  // namespace paircast
