// Shards from untrusted sources through the trainer's own tar index (PairDataset): links,
// folders and names with '/' are never indexed, sizes beyond the file stop the scan before any
// read, and a member that does not decode is an error naming the shard and the pair.
#include <gtest/gtest.h>

#include <cstring>
#include <fstream>

#include "test_errors.h"
#include "test_paths.h"
#include "trainer/pair_dataset.h"
#include "util/error.h"
#include "util/image_io.h"

namespace paircast {
namespace {

struct Member {
  Member(std::string n, std::string d, char t = '0', std::string size = "")
      : name(std::move(n)), data(std::move(d)), type(t), sizeField(std::move(size)) {}
  std::string name, data;
  char type;              // ustar type flag: '0' file, '1' hard link, '2' symlink, '5' folder
  std::string sizeField;  // written instead of the real size when set
};

// A ustar archive, header by header, so that a test can write what no tar tool would.
std::string ustar(const std::vector<Member>& members) {
  std::string out;
  for (const Member& m : members) {
    char h[512] = {};
    std::strncpy(h, m.name.c_str(), 100);
    std::snprintf(h + 100, 8, "%07o", 0644);
    std::snprintf(h + 108, 8, "%07o", 0);
    std::snprintf(h + 116, 8, "%07o", 0);
    if (m.sizeField.empty())
      std::snprintf(h + 124, 12, "%011o", static_cast<unsigned>(m.data.size()));
    else
      std::memcpy(h + 124, m.sizeField.data(), std::min<size_t>(12, m.sizeField.size()));
    std::snprintf(h + 136, 12, "%011o", 0);
    h[156] = m.type;
    std::memcpy(h + 257,
                "ustar\0"
                "00",
                8);
    std::memset(h + 148, ' ', 8);
    unsigned sum = 0;
    for (unsigned char c : std::string(h, 512)) sum += c;
    std::snprintf(h + 148, 8, "%06o", sum);
    out.append(h, 512);
    out += m.data;
    out.append((512 - m.data.size() % 512) % 512, '\0');
  }
  return out + std::string(1024, '\0');
}

std::string jpeg() {
  Image8 img(8, 8, 3);
  for (size_t i = 0; i < img.data.size(); ++i) img.data[i] = static_cast<uint8_t>(i * 7);
  const auto bytes = encodeImage(img, "jpg", 90);
  return std::string(bytes.begin(), bytes.end());
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
                                                  {"b-0.1.jpg", "", '2'},  // symbolic link
                                                  {"b-0.2.jpg", j},
                                                  {"c-0.1.jpg", "", '1'},  // hard link
                                                  {"c-0.2.jpg", j},
                                                  {"../d-0.1.jpg", j},
                                                  {"../d-0.2.jpg", j},
                                                  {"e-0.1.jpg", "", '5'},  // folder
                                                  {"e-0.2.jpg", j},
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
                                                    {"b-0.1.jpg", j, '0', "77777777777"},
                                                    {"b-0.2.jpg", j}}));
  const PairDataset ds = PairDataset::fromShards({path});
  ASSERT_EQ(ds.size(), 1u);
  EXPECT_EQ(ds.key(0), "a-0");
  // A size field that is not octal at all is the same.
  const std::string bad = write("garbage.tar", ustar({{"a-0.1.jpg", j, '0', "-12"}}));
  EXPECT_THROW(PairDataset::fromShards({bad}), Error);
}

TEST(UntrustedShardIndex, AMemberThatDoesNotDecodeNamesTheShardAndThePair) {
  const std::string j = jpeg();
  const std::string path =
      write("corrupt.tar", ustar({{"a-0.1.jpg", j}, {"a-0.2.jpg", "not a jpeg at all"}}));
  const PairDataset ds = PairDataset::fromShards({path});
  ASSERT_EQ(ds.size(), 1u);
  const std::string why = testing::refusalOf(path, [&] { ds.load(0); });
  EXPECT_NE(why.find("a-0.2.jpg"), std::string::npos) << why;
}

}  // namespace
}  // namespace paircast
