// Shards from untrusted sources: readShard never writes or follows anything, skips links and
// escaping names with a message naming the shard and the entry, and refuses huge or negative
// entry sizes before allocating. (docs/reliability.md, "Untrusted files", lists the threats.)
#include <archive.h>
#include <archive_entry.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cstring>
#include <filesystem>

#include "dataset/shard.h"
#include "fake_sample.h"
#include "test_paths.h"
#include "util/atomic_file.h"
#include "util/error.h"

namespace paircast {
namespace {

namespace fs = std::filesystem;

std::string goodRecord(const std::string& scene, uint64_t index) {
  return sampleRecord(testing::fakeSample(scene, index, 2, false, 0.5)).dump();
}

struct Entry {
  std::string name, data;
  unsigned type = AE_IFREG;
  std::string symlink, hardlink;
};

void writeTar(const std::string& path, const std::vector<Entry>& entries) {
  archive* a = archive_write_new();
  archive_write_set_format_pax_restricted(a);
  ASSERT_EQ(archive_write_open_filename(a, path.c_str()), ARCHIVE_OK);
  for (const Entry& in : entries) {
    archive_entry* e = archive_entry_new();
    archive_entry_set_pathname(e, in.name.c_str());
    archive_entry_set_filetype(e, in.type);
    archive_entry_set_perm(e, 0644);
    if (!in.symlink.empty()) archive_entry_set_symlink(e, in.symlink.c_str());
    if (!in.hardlink.empty()) archive_entry_set_hardlink(e, in.hardlink.c_str());
    archive_entry_set_size(e, static_cast<la_int64_t>(in.data.size()));
    archive_write_header(a, e);
    if (!in.data.empty()) archive_write_data(a, in.data.data(), in.data.size());
    archive_entry_free(e);
  }
  archive_write_close(a);
  archive_write_free(a);
}

struct ReadResult {
  std::vector<std::string> keys;
  std::string errors;  // one per line
  std::string thrown;  // what() of an Error, if any
};

ReadResult read(const std::string& path) {
  ReadResult r;
  try {
    readShard(
        path, [&](ShardSample&& s) { r.keys.push_back(s.key); },
        [&](const std::string& e) { r.errors += e + "\n"; });
  } catch (const Error& e) {
    r.thrown = e.what();
  }
  return r;
}

TEST(UntrustedShard, LinksAndEscapingNamesAreNeverFollowedAndAreNamed) {
  const std::string dir = testing::scratchDir("links");
  const std::string path = dir + "/links.tar";
  const std::string jpg = "\xff\xd8\xff\xd9";
  writeTar(path, {
                     // A whole sample whose members are links to files outside.
                     {"a-1.1.jpg", "", AE_IFLNK, "/etc/passwd", ""},
                     {"a-1.2.jpg", "", AE_IFREG, "", "/etc/shadow"},
                     {"a-1.json", goodRecord("a", 1), AE_IFREG, "", ""},
                     // Names that would land outside a folder they were extracted to.
                     {"../b-1.1.jpg", jpg},
                     {"/tmp/b-1.2.jpg", jpg},
                     {"sub/../../b-1.json", goodRecord("b", 1)},
                     {"dir", "", AE_IFDIR, "", ""},
                     // The one good sample.
                     {"c-1.1.jpg", jpg},
                     {"c-1.2.jpg", jpg},
                     {"c-1.json", goodRecord("c", 1)},
                 });
  const ReadResult r = read(path);
  EXPECT_EQ(r.thrown, "");
  EXPECT_EQ(r.keys, std::vector<std::string>{"c-1"});
  for (const char* fragment :
       {"entry 'a-1.1.jpg' is a link", "entry 'a-1.2.jpg' is a link",
        "entry '../b-1.1.jpg' is not a plain file name",
        "entry '/tmp/b-1.2.jpg' is not a plain file name",
        "entry 'sub/../../b-1.json' is not a plain file name",
        "entry 'dir/' is a link or not a plain file", "sample 'a-1' is incomplete"}) {
    EXPECT_NE(r.errors.find(path + ": " + fragment), std::string::npos) << fragment << " in\n"
                                                                        << r.errors;
  }
  // Nothing was written anywhere: the folder holds the shard alone, /tmp no b-1.2.jpg.
  EXPECT_EQ(std::distance(fs::directory_iterator(dir), fs::directory_iterator()), 1);
  EXPECT_FALSE(fs::exists(dir + "/../b-1.1.jpg"));
}

// A ustar header written byte by byte, so that its size field can say anything.
std::string ustarHeader(const std::string& name, const char* sizeField, size_t sizeLen) {
  std::string h(512, '\0');
  std::memcpy(&h[0], name.data(), name.size());
  std::memcpy(&h[100], "0000644", 7);
  std::memcpy(&h[108], "0000000", 7);
  std::memcpy(&h[116], "0000000", 7);
  std::memcpy(&h[124], sizeField, sizeLen);
  std::memcpy(&h[136], "00000000000", 11);
  h[156] = '0';
  std::memcpy(&h[257],
              "ustar\0"
              "00",
              8);
  std::memset(&h[148], ' ', 8);
  unsigned sum = 0;
  for (unsigned char c : h) sum += c;
  std::snprintf(&h[148], 8, "%06o", sum);
  return h;
}

TEST(UntrustedShard, HugeAndNegativeSizesAreRefusedBeforeAllocation) {
  const std::string dir = testing::scratchDir("sizes");
  const std::string tail(1024, '\0');
  struct Case {
    const char* what;
    std::string sizeField;
  };
  const std::vector<Case> cases = {
      {"8 GiB in octal", "77777777777"},
      // GNU base-256: the high bit marks binary; 0xff... is negative.
      {"negative base-256", std::string("\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\xfe", 12)},
      {"2^62 in base-256", std::string("\x80\x00\x00\x00\x40\x00\x00\x00\x00\x00\x00\x00", 12)},
      {"100 MB in octal, over maxEntryBytes", "00620000000"},
      {"1 MB in octal, under the limit but more than the shard holds", "00004000000"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.what);
    const std::string path = dir + "/s.tar";
    writeFileAtomic(path, ustarHeader("k-1.json", c.sizeField.data(), c.sizeField.size()) +
                              std::string(512, 'x') + tail);
    const auto start = std::chrono::steady_clock::now();
    const ReadResult r = read(path);
    EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(2));
    EXPECT_TRUE(r.keys.empty());
    // Either refused as an entry (reported, naming it) or the shard is corrupt (thrown); both
    // name the shard.
    const std::string all = r.errors + r.thrown;
    EXPECT_NE(all.find(path), std::string::npos) << all;
    if (r.thrown.empty()) EXPECT_NE(all.find("k-1.json"), std::string::npos) << all;
  }
  // The entry-size limit is the caller's: a 600-byte entry against a 100-byte limit.
  const std::string path = dir + "/limit.tar";
  writeFileAtomic(path, ustarHeader("k-1.json", "00000001130", 11) + std::string(1024, 'x') + tail);
  ShardReadOptions small;
  small.maxEntryBytes = 100;
  std::string errors;
  readShard(
      path, [](ShardSample&&) {}, [&](const std::string& e) { errors += e; }, small);
  EXPECT_NE(errors.find("'k-1.json' has an invalid size (600 bytes, limit 100)"), std::string::npos)
      << errors;
}

TEST(UntrustedShard, RecordsAreCheckedBeforeDelivery) {
  const std::string dir = testing::scratchDir("records");
  const std::string jpg = "\xff\xd8\xff\xd9";
  nlohmann::json badCamera = nlohmann::json::parse(goodRecord("b", 1));
  badCamera["camera2"]["width"] = 4294967297;  // would wrap to 1 as an int
  nlohmann::json badCovis = nlohmann::json::parse(goodRecord("c", 1));
  badCovis["covis"] = "high";
  writeTar(dir + "/r.tar", {{"b-1.1.jpg", jpg},
                            {"b-1.2.jpg", jpg},
                            {"b-1.json", badCamera.dump()},
                            {"c-1.1.jpg", jpg},
                            {"c-1.2.jpg", jpg},
                            {"c-1.json", badCovis.dump()},
                            {"d-1\n\x1b[2J.1.jpg", jpg}});
  const ReadResult r = read(dir + "/r.tar");
  EXPECT_TRUE(r.keys.empty());
  EXPECT_NE(r.errors.find("sample 'b-1' camera2: camera size must be in 1..16384"),
            std::string::npos)
      << r.errors;
  EXPECT_NE(r.errors.find("sample 'c-1': record has no number 'covis'"), std::string::npos)
      << r.errors;
  // Names with control characters are refused, and escaped so that each message is one line.
  EXPECT_NE(r.errors.find("entry 'd-1\\x0a\\x1b[2J.1.jpg' is not a plain file name"),
            std::string::npos)
      << r.errors;
}

TEST(SampleRecord, ParsesWhatSampleRecordWritesAndNamesWhatIsWrong) {
  const nlohmann::json good = nlohmann::json::parse(goodRecord("room", 7));
  const SampleRecord r = parseSampleRecord(good, "x");
  EXPECT_EQ(r.scene, "room");
  EXPECT_EQ(r.index, 7u);
  EXPECT_DOUBLE_EQ(r.covis, 0.5);
  EXPECT_EQ(r.camera[1].width, 16);
  auto expectError = [&](nlohmann::json j, const std::string& fragment) {
    try {
      parseSampleRecord(j, "rec.json");
      ADD_FAILURE() << "accepted " << j.dump();
    } catch (const Error& e) {
      EXPECT_EQ(std::string(e.what()).rfind("rec.json", 0), 0u) << e.what();
      EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    }
  };
  expectError(nlohmann::json::array(), "not a JSON object");
  auto j = good;
  j["paircast_shard_version"] = 2;
  expectError(j, "regenerate the shard with generate_pairs");
  j = good;
  j.erase("camera1");
  expectError(j, "no 'camera1'");
  j = good;
  j["index"] = -1;
  expectError(j, "'index'");
  j = good;
  j["v_ji"] = 1.5;
  expectError(j, "'v_ji' is not in [0, 1]");
  j = good;
  j["camera1"]["camera_intrinsics"][0][0] = -3;
  expectError(j, "camera1: invalid camera");
}

}  // namespace
}  // namespace paircast
