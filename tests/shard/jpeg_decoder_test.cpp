// Decoding straight into a crop: the same pixels as the same window of a full decode, in every
// layout, for many seeded boxes; bad boxes and bad data name the image.
#include "util/jpeg_decoder.h"

#include <gtest/gtest.h>

#include <cmath>

#include "test_errors.h"
#include "util/image_io.h"
#include "util/random.h"

namespace paircast {
namespace {

// A smooth image with detail in every channel, so that chroma upsampling matters at the edges.
std::vector<unsigned char> jpegOf(int width, int height, uint64_t seed) {
  Rng rng(seed);
  const double f[3] = {0.05 + 0.3 * rng.uniform(), 0.05 + 0.3 * rng.uniform(),
                       0.05 + 0.3 * rng.uniform()};
  Image8 img(width, height, 3);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x)
      for (int c = 0; c < 3; ++c)
        img.pixel(x, y)[c] =
            static_cast<uint8_t>(127 + 120 * std::sin(f[c] * x + f[(c + 1) % 3] * y + c));
  return encodeImage(img, "jpg", 90);
}

TEST(JpegCrop, EqualsTheSameWindowOfAFullDecodeForManyBoxes) {
  Rng rng(11);
  for (int trial = 0; trial < 40; ++trial) {
    const int W = 17 + static_cast<int>(rng.below(120)), H = 17 + static_cast<int>(rng.below(120));
    const auto jpeg = jpegOf(W, H, trial);
    const Image8 full = decodeImage8(jpeg.data(), jpeg.size(), "full.jpg");
    const JpegSize size = jpegSize(jpeg.data(), jpeg.size(), "x.jpg");
    ASSERT_EQ(size.width, W);
    ASSERT_EQ(size.height, H);
    CropBox box;
    box.width = 1 + static_cast<int>(rng.below(W));
    box.height = 1 + static_cast<int>(rng.below(H));
    box.left = static_cast<int>(rng.below(W - box.width + 1));
    box.top = static_cast<int>(rng.below(H - box.height + 1));
    Image8 crop(box.width, box.height, 3);
    decodeJpegCrop(jpeg.data(), jpeg.size(), "x.jpg", box, PixelLayout::kUint8HWC,
                   crop.data.data());
    int differ = 0;
    for (int y = 0; y < box.height; ++y)
      for (int x = 0; x < box.width; ++x)
        for (int c = 0; c < 3; ++c)
          differ += crop.pixel(x, y)[c] != full.pixel(box.left + x, box.top + y)[c];
    EXPECT_EQ(differ, 0) << W << "x" << H << " box " << box.width << "x" << box.height << " at ("
                         << box.left << ", " << box.top << ")";
  }
}

TEST(JpegCrop, LayoutsHoldTheSamePixels) {
  const auto jpeg = jpegOf(64, 48, 3);
  const CropBox box{5, 9, 30, 40};
  const size_t n = 30 * 40;
  std::vector<uint8_t> hwc(3 * n), chw(3 * n);
  std::vector<float> normalized(3 * n);
  decodeJpegCrop(jpeg.data(), jpeg.size(), "x", box, PixelLayout::kUint8HWC, hwc.data());
  decodeJpegCrop(jpeg.data(), jpeg.size(), "x", box, PixelLayout::kUint8CHW, chw.data());
  decodeJpegCrop(jpeg.data(), jpeg.size(), "x", box, PixelLayout::kNormalizedFloatCHW,
                 normalized.data());
  for (size_t i = 0; i < n; ++i) {
    for (int c = 0; c < 3; ++c) {
      const uint8_t v = hwc[3 * i + c];
      ASSERT_EQ(chw[c * n + i], v);
      const float expected = (v / 255.0f - kImagenetMean[c]) / kImagenetStd[c];
      ASSERT_FLOAT_EQ(normalized[c * n + i], expected);
    }
  }
}

TEST(JpegCrop, BadBoxesAndBadDataNameTheImage) {
  const auto jpeg = jpegOf(32, 24, 1);
  std::vector<uint8_t> out(3 * 64 * 64);
  for (const CropBox& box :
       {CropBox{0, 0, 25, 10}, CropBox{0, 30, 4, 4}, CropBox{-1, 0, 4, 4}, CropBox{0, 0, 0, 4}}) {
    const std::string why = testing::refusalOf("view.jpg", [&] {
      decodeJpegCrop(jpeg.data(), jpeg.size(), "view.jpg", box, PixelLayout::kUint8HWC, out.data());
    });
    EXPECT_NE(why.find("is not inside the 32x24 image"), std::string::npos) << why;
  }
  const std::string garbage = "certainly not a JPEG";
  const auto* g = reinterpret_cast<const uint8_t*>(garbage.data());
  testing::refusalOf("g.jpg", [&] { jpegSize(g, garbage.size(), "g.jpg"); });
  // Cut after the header: the crop's rows are missing.
  std::vector<unsigned char> cut(jpeg.begin(), jpeg.begin() + jpeg.size() / 3);
  const std::string why = testing::refusalOf("cut.jpg", [&] {
    decodeJpegCrop(cut.data(), cut.size(), "cut.jpg", CropBox{16, 0, 8, 32}, PixelLayout::kUint8HWC,
                   out.data());
  });
  EXPECT_NE(why.find("cannot decode JPEG"), std::string::npos) << why;
}

}  // namespace
}  // namespace paircast
