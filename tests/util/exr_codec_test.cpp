// OpenEXR's C library (the trainer-only build's EXR) against OpenImageIO (the full build's): each
// reads what the other writes, bit for bit, and bad bytes give an error naming the file.
#include "util/exr_codec.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <climits>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

#include "test_errors.h"
#include "util/image_io.h"

namespace paircast {
namespace {

// Depth-like values: zeros (no hit), +inf, a subnormal, and values no half holds.
ImageF depthLike(int w, int h, int channels) {
  ImageF image;
  image.width = w;
  image.height = h;
  image.channels = channels;
  image.data.resize(static_cast<size_t>(w) * h * channels);
  for (size_t i = 0; i < image.data.size(); ++i)
    image.data[i] = 0.25f + 7.0f * std::sin(0.37f * static_cast<float>(i)) *
                                std::sin(0.11f * static_cast<float>(i));
  image.data[0] = 0.0f;
  image.data[1] = std::numeric_limits<float>::infinity();
  image.data[2] = std::numeric_limits<float>::denorm_min();
  image.data[3] = 1.0f + std::numeric_limits<float>::epsilon();
  return image;
}

void expectSameBits(const ImageF& a, const ImageF& b) {
  ASSERT_EQ(a.width, b.width);
  ASSERT_EQ(a.height, b.height);
  ASSERT_EQ(a.channels, b.channels);
  ASSERT_EQ(a.data.size(), b.data.size());
  EXPECT_EQ(std::memcmp(a.data.data(), b.data.data(), a.data.size() * sizeof(float)), 0);
  for (size_t i = 0; i < a.data.size(); ++i)
    if (std::memcmp(&a.data[i], &b.data[i], sizeof(float)) != 0) {
      ADD_FAILURE() << "value " << i << ": " << a.data[i] << " against " << b.data[i];
      break;
    }
}

TEST(ExrCodec, ReadsWhatOpenImageIOWrites) {
  // 70 rows: ZIP packs 16 rows a chunk, so the last chunk is short.
  for (int channels : {1, 3}) {
    const ImageF image = depthLike(53, 70, channels);
    const std::vector<unsigned char> bytes = encodeExr(image);  // OpenImageIO
    expectSameBits(decodeExrCore(bytes.data(), bytes.size(), "oiio.exr"), image);
  }
}

TEST(ExrCodec, ReadsHalfFloatFilesAsOpenImageIODoes) {
  const ImageF image = depthLike(19, 33, 1);
  const std::vector<unsigned char> bytes = encodeExr(image, /*half=*/true);
  const ImageF ours = decodeExrCore(bytes.data(), bytes.size(), "half.exr");
  expectSameBits(ours, decodeImageF(bytes.data(), bytes.size(), "half.exr"));
  EXPECT_NE(ours.data[3], image.data[3]);  // half rounded it: the file really is half
}

TEST(ExrCodec, OpenImageIOReadsWhatItWrites) {
  for (int channels : {1, 3}) {
    const ImageF image = depthLike(64, 40, channels);
    const std::vector<unsigned char> bytes = encodeExrCore(image);
    expectSameBits(decodeImageF(bytes.data(), bytes.size(), "core.exr"), image);
    expectSameBits(decodeExrCore(bytes.data(), bytes.size(), "core.exr"), image);
  }
}

TEST(ExrCodec, BadBytesGiveAnErrorNamingTheFile) {
  const std::vector<unsigned char> bytes = encodeExr(depthLike(32, 48, 1));
  EXPECT_ERROR_CONTAINS(decodeExrCore(bytes.data(), bytes.size() / 2, "shard.tar: 7.1.depth.exr"),
                        "shard.tar: 7.1.depth.exr", "cannot");
  const std::string text = "not an image at all";
  EXPECT_ERROR_CONTAINS(decodeExrCore(text.data(), text.size(), "x.exr"), "x.exr", "cannot read");
  std::vector<unsigned char> flipped = bytes;
  for (size_t i = flipped.size() / 2; i < flipped.size(); i += 7) flipped[i] ^= 0x5a;
  EXPECT_ERROR_CONTAINS(decodeExrCore(flipped.data(), flipped.size(), "y.exr"), "y.exr", "cannot");
  ImageF two = depthLike(4, 4, 2);
  EXPECT_ERROR_CONTAINS(encodeExrCore(two), "1 or 3 channels");
}

// The file's own header with its data window widened to `side` x `side` (xmin, ymin, xmax, ymax
// after "dataWindow\0box2i\0" and the attribute's size, 16).
std::vector<unsigned char> withDataWindow(std::vector<unsigned char> bytes, int32_t side) {
  const std::string key("dataWindow\0box2i\0\x10\0\0\0", 21);
  const auto at = std::search(bytes.begin(), bytes.end(), key.begin(), key.end());
  EXPECT_NE(at, bytes.end()) << "no dataWindow attribute";
  const int32_t window[4] = {0, 0, side - 1, side - 1};
  std::memcpy(&*(at + key.size()), window, sizeof window);
  return bytes;
}

// A 1 KB depth map whose header claims 65,536 x 65,536 (16 GiB of floats): both codecs refuse it
// from its size before allocating, naming the member.
TEST(ExrCodec, AHeaderClaimingMoreThanItsBytesHoldIsRefusedBeforeAllocating) {
  const std::vector<unsigned char> bytes = withDataWindow(encodeExr(depthLike(8, 8, 1)), 65536);
  const std::string name = "shard.tar: 000001.depth.1.exr";
  const auto start = std::chrono::steady_clock::now();
  EXPECT_ERROR_CONTAINS(decodeExrCore(bytes.data(), bytes.size(), name), name,
                        "EXR header claims 65536x65536x1 values in a file of");
  // OpenImageIO's path: OpenEXR reads the chunk offsets the window implies, and the file ends.
  EXPECT_ERROR_CONTAINS(decodeImageF(bytes.data(), bytes.size(), name), name);
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(2));
  // A window from INT_MIN to INT_MAX, whose width overflows an int.
  std::vector<unsigned char> wide = encodeExr(depthLike(8, 8, 1));
  const std::string key("dataWindow\0box2i\0\x10\0\0\0", 21);
  const auto at = std::search(wide.begin(), wide.end(), key.begin(), key.end());
  ASSERT_NE(at, wide.end());
  const int32_t window[4] = {INT32_MIN, 0, INT32_MAX, 7};
  std::memcpy(&*(at + key.size()), window, sizeof window);
  EXPECT_ERROR_CONTAINS(decodeExrCore(wide.data(), wide.size(), "wide.exr"), "wide.exr");
}

}  // namespace
}  // namespace paircast
