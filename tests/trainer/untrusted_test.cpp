// Shards from untrusted sources through the trainer's own tar index (PairDataset): links,
// folders and names with '/' are never indexed, sizes beyond the file stop the scan before any
// read, and a member that does not decode is an error naming the shard and the pair.
#include <gtest/gtest.h>

#include <fstream>

#include "test_errors.h"
#include "test_paths.h"
#include "test_tar.h"
#include "trainer/pair_dataset.h"
#include "util/error.h"
#include "util/image_io.h"

namespace paircast {
namespace {

using testing::ustar;

std::string jpeg() {
  return testing::jpegBytes();
}

testing::TarMember record(const std::string& key) {
  return testing::recordMember(key, 2);
}

std::string write(const std::string& name, const std::string& bytes) {
  const std::string path = testing::scratchDir("untrusted_index") + "/" + name;
  std::ofstream(path, std::ios::binary) << bytes;
  return path;
}

TEST(UntrustedShardIndex, LinksFoldersAndEscapingNamesAreNeverIndexed) {
  const std::string j = jpeg();
  const std::string path = write("links.tar", ustar({
                                                  {"a-0.1.jpg", j},
                                                  {"a-0.2.jpg", j},
                                                  record("a-0"),
                                                  {"b-0.1.jpg", "", '2'},  // symbolic link
                                                  {"b-0.2.jpg", j},
                                                  record("b-0"),
                                                  {"c-0.1.jpg", "", '1'},  // hard link
                                                  {"c-0.2.jpg", j},
                                                  record("c-0"),
                                                  {"../d-0.1.jpg", j},
                                                  {"../d-0.2.jpg", j},
                                                  {"e-0.1.jpg", "", '5'},  // folder
                                                  {"e-0.2.jpg", j},
                                                  record("e-0"),
                                              }));
  const PairDataset ds = PairDataset::fromShards({path});
  ASSERT_EQ(ds.size(), 1u);
  EXPECT_EQ(ds.key(0), "a-0");
  const auto [x, y] = ds.load(0);
  EXPECT_EQ(x.width, 8);
  EXPECT_EQ(y.height, 8);
}

TEST(UntrustedShardIndex, SizesBeyondTheFileStopTheScanBeforeAnyRead) {
  const std::string j = jpeg();
  // The second sample's first member claims 8 GiB (octal) in a file of a few KB: the scan stops
  // there, keeping the whole sample before it.
  const std::string path = write("huge.tar", ustar({{"a-0.1.jpg", j},
                                                    {"a-0.2.jpg", j},
                                                    record("a-0"),
                                                    {"b-0.1.jpg", j, '0', "77777777777"},
                                                    {"b-0.2.jpg", j},
                                                    record("b-0")}));
  const PairDataset ds = PairDataset::fromShards({path});
  ASSERT_EQ(ds.size(), 1u);
  EXPECT_EQ(ds.key(0), "a-0");
  // A size field that is not octal at all is the same.
  const std::string bad = write("garbage.tar", ustar({{"a-0.1.jpg", j, '0', "-12"}}));
  EXPECT_ERROR_CONTAINS(PairDataset::fromShards({bad}), bad + ": no complete pair in the shards");
}

TEST(UntrustedShardIndex, AMemberThatDoesNotDecodeNamesTheShardAndThePair) {
  const std::string j = jpeg();
  const std::string path =
      write("corrupt.tar",
            ustar({{"a-0.1.jpg", j}, {"a-0.2.jpg", "not a jpeg at all"}, record("a-0")}));
  const PairDataset ds = PairDataset::fromShards({path});
  ASSERT_EQ(ds.size(), 1u);
  const std::string why = testing::refusalOf(path, [&] { ds.load(0); });
  EXPECT_NE(why.find("a-0.2.jpg"), std::string::npos) << why;
}

}  // namespace
}  // namespace paircast
