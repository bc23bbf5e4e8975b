#include "util/image_io.h"

#include <gtest/gtest.h>

#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>
#include <filesystem>

#include <chrono>
#include <fstream>

#include "test_errors.h"
#include "test_paths.h"
#include "util/atomic_file.h"
#include "util/error.h"
#include "util/jpeg_encoder.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

namespace paircast {
namespace {

Image8 gradient(int w, int h) {
  Image8 img(w, h, 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      uint8_t* p = img.pixel(x, y);
      p[0] = static_cast<uint8_t>(x * 255 / (w - 1));
      p[1] = static_cast<uint8_t>(y * 255 / (h - 1));
      p[2] = 77;
    }
  return img;
}

TEST(ImageIo, PngRoundTripIsExact) {
  const std::string path = testing::scratchDir("png") + "/g.png";
  const Image8 img = gradient(37, 21);
  writeImage(path, img);
  const Image8 back = readImage8(path);
  EXPECT_EQ(back.width, 37);
  EXPECT_EQ(back.height, 21);
  EXPECT_EQ(back.data, img.data);
}

TEST(ImageIo, JpegRoundTripIsClose) {
  const Image8 img = gradient(64, 64);
  const auto bytes = encodeImage(img, "jpg", 95);
  const Image8 back = decodeImage8(bytes.data(), bytes.size(), "g.jpg");
  ASSERT_EQ(back.size(), img.size());
  double err = 0;
  for (size_t i = 0; i < img.size(); ++i) err += std::abs(int(back.data[i]) - int(img.data[i]));
  EXPECT_LT(err / img.size(), 2.0);
}

// JPEG as OpenImageIO's writer encodes it, for the comparison below.
std::vector<unsigned char> oiioJpeg(const Image8& img, int quality) {
  std::vector<unsigned char> bytes;
  OIIO::Filesystem::IOVecOutput proxy(bytes);
  auto out = OIIO::ImageOutput::create("image.jpg");
  OIIO::ImageSpec spec(img.width, img.height, img.channels, OIIO::TypeDesc::UINT8);
  spec.attribute("Compression", "jpeg:" + std::to_string(quality));
  EXPECT_TRUE(out->set_ioproxy(&proxy) && out->open("image.jpg", spec));
  EXPECT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, img.data.data()));
  EXPECT_TRUE(out->close());
  return bytes;
}

TEST(ImageIo, JpegBytesAreThoseOpenImageIOWrote) {
  // libjpeg-turbo straight, for speed: shards and CroCo folders keep the bytes they had.
  Image8 noisy = gradient(256, 256);
  for (size_t i = 0; i < noisy.data.size(); i += 7) noisy.data[i] ^= static_cast<uint8_t>(i * 31);
  for (int quality : {90, 95, 50}) {
    EXPECT_EQ(encodeImage(noisy, "jpg", quality), oiioJpeg(noisy, quality)) << quality;
  }
  Image8 grey(40, 24, 1);
  for (size_t i = 0; i < grey.data.size(); ++i) grey.data[i] = static_cast<uint8_t>(i * 13);
  EXPECT_EQ(encodeImage(grey, "jpg", 90), oiioJpeg(grey, 90));
  // What libjpeg cannot take is an error naming the image, not a crash.
  EXPECT_ERROR_CONTAINS(encodeJpeg(noisy, 0), "quality");
  EXPECT_ERROR_CONTAINS(encodeJpeg(Image8(4, 4, 2), 90), "channels");
  EXPECT_ERROR_CONTAINS(encodeJpeg(Image8(), 90), "empty");
}

TEST(ImageIo, HeadersClaimingHugeImagesAreRefusedBeforeDecoding) {
  // A real 16 x 16 JPEG whose frame header (SOF0) is patched to claim 60000 x 60000 pixels.
  auto bytes = encodeImage(gradient(16, 16), "jpg", 90);
  size_t sof = 0;
  for (size_t i = 0; i + 9 < bytes.size() && !sof; ++i)
    if (bytes[i] == 0xFF && bytes[i + 1] == 0xC0) sof = i;
  ASSERT_GT(sof, 0u) << "no SOF0 marker";
  for (size_t k : {sof + 5, sof + 7}) bytes[k] = 0xEA, bytes[k + 1] = 0x60;  // 60000, big-endian
  const auto start = std::chrono::steady_clock::now();
  try {
    decodeImage8(bytes.data(), bytes.size(), "bomb.jpg");
    ADD_FAILURE() << "a 60000 x 60000 JPEG was decoded";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("bomb.jpg: image is too large (60000x60000x3"),
              std::string::npos)
        << e.what();
  }
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(5));
  // 12,000 x 12,000 is under the 2^28 pixels and the 1 GiB, and libjpeg would decode it from the
  // few hundred bytes there are, padding with grey: refused from the file's size instead.
  for (size_t k : {sof + 5, sof + 7}) bytes[k] = 0x2E, bytes[k + 1] = 0xE0;  // 12000
  EXPECT_ERROR_CONTAINS(decodeImage8(bytes.data(), bytes.size(), "bomb.jpg"),
                        "bomb.jpg: image header claims 12000x12000x3 values in " +
                            std::to_string(bytes.size()) + " bytes");
}

TEST(ImageIo, ExrKeepsFloatDepthExactly) {
  const std::string path = testing::scratchDir("exr") + "/d.exr";
  ImageF depth(5, 3, 1);
  for (size_t i = 0; i < depth.size(); ++i) depth.data[i] = i == 4 ? 0.0f : 0.1234567f * i;
  writeExr(path, depth);
  const ImageF back = readImageF(path);
  EXPECT_EQ(back.channels, 1);
  EXPECT_EQ(back.data, depth.data);
}

TEST(ImageIo, BytesInMemoryAreDecodedOnlyByTheReaderTheirNameNames) {
  // A shard's member named .exr that is not one is refused, not handed to every other reader
  // (libtiff, among them, prints to stderr); a name without an extension still finds its reader.
  const Image8 image = gradient(8, 6);
  const auto tiff = encodeImage(image, "tif", 0);
  ::testing::internal::CaptureStderr();
  EXPECT_ERROR_CONTAINS(decodeImageF(tiff.data(), tiff.size(), "shard.tar: p.1.depth.exr"),
                        "shard.tar: p.1.depth.exr: cannot decode image");
  EXPECT_ERROR_CONTAINS(decodeImage8(tiff.data(), tiff.size(), "shard.tar: p.1.png"),
                        "shard.tar: p.1.png: cannot decode image");
  EXPECT_EQ(::testing::internal::GetCapturedStderr(), "");
  EXPECT_EQ(decodeImage8(tiff.data(), tiff.size(), "p.1.tif").data, image.data);
  EXPECT_EQ(decodeImage8(tiff.data(), tiff.size(), "embedded texture").data, image.data);
}

TEST(ImageIo, BadFilesGiveErrorsNamingThem) {
  const std::string dir = testing::scratchDir("bad");
  EXPECT_ERROR_CONTAINS(readImage8(dir + "/none.png"), dir + "/none.png: no such file");
  std::ofstream(dir + "/junk.png") << "not a png at all";
  try {
    readImage8(dir + "/junk.png");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("junk.png"), std::string::npos);
  }
  EXPECT_ERROR_CONTAINS(writeImage(dir + "/x.bmp2", gradient(4, 4)),
                        dir + "/x.bmp2: unsupported image extension");
  EXPECT_ERROR_CONTAINS(decodeImage8("abc", 3, "mem.jpg"), "mem.jpg: cannot decode image");
}

TEST(AtomicFile, WritesWholeFilesAndLeavesNoTemporaries) {
  const std::string dir = testing::scratchDir("atomic");
  writeFileAtomic(dir + "/a.txt", "first");
  writeFileAtomic(dir + "/a.txt", "second");
  EXPECT_EQ(readFile(dir + "/a.txt"), "second");
  size_t files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir)) files += e.is_regular_file();
  EXPECT_EQ(files, 1u);
  EXPECT_ERROR_CONTAINS(writeFileAtomic(dir + "/no/such/folder/a.txt", "x"),
                        dir + "/no/such/folder/a.txt: cannot create temporary file");
}

TEST(AtomicFile, FullDiskIsAnErrorAndKeepsTheOldFile) {
  // A file-size limit makes write() fail like a full disk (EFBIG), inside a child process.
  const std::string dir = testing::scratchDir("full");
  writeFileAtomic(dir + "/keep.txt", "old");
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    signal(SIGXFSZ, SIG_IGN);
    rlimit lim{4096, 4096};
    setrlimit(RLIMIT_FSIZE, &lim);
    try {
      writeFileAtomic(dir + "/keep.txt", std::string(1 << 20, 'x'));
      _exit(2);  // should have failed
    } catch (const Error& e) {
      _exit(std::string(e.what()).find("keep.txt") != std::string::npos ? 0 : 3);
    }
  }
  int status = 0;
  waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0);
  EXPECT_EQ(readFile(dir + "/keep.txt"), "old");
  size_t files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir)) files += e.is_regular_file();
  EXPECT_EQ(files, 1u) << "no temporary left behind";
}

}  // namespace
}  // namespace paircast
