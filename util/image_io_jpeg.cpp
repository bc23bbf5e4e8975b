// util/image_io.h for the trainer-only build (PAIRCAST_WITH_RENDER=OFF), without OpenImageIO:
// JPEG through libjpeg-turbo (decoded here, encoded by util/jpeg_encoder.cpp as in the full
// build), PNG written with stored (uncompressed) deflate blocks, which needs no zlib, and float
// maps as EXR through OpenEXR's C library (util/exr_codec.h) where it was found. PNG decoding and
// half-float EXR need the full build and say so.
#include <algorithm>
#include <csetjmp>
#include <cstdint>
#include <cstdio>  // before jpeglib.h, which uses FILE
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>

#include "util/atomic_file.h"
#include "util/error.h"
#ifdef PAIRCAST_HAVE_OPENEXR_CORE
#include "util/exr_codec.h"
#endif
#include "util/image_io.h"
#include "util/jpeg_encoder.h"
#include "util/jpeg_errors.h"

namespace paircast {
namespace {

namespace fs = std::filesystem;

const char* const kFullBuild =
    "needs the full build (this one was configured with PAIRCAST_WITH_RENDER=OFF)";
[[maybe_unused]] const char* const kNoOpenExr =
    "needs OpenEXR (libopenexr-dev) or the full build: this trainer-only build was configured "
    "without it";

// Decodes into a malloc'd buffer (no C++ object lives across setjmp). Returns an empty string on
// success, else libjpeg's message.
std::string decodeJpeg(const unsigned char* data, size_t size, int channels, int* width,
                       int* height, unsigned char** pixels) {
  jpeg_decompress_struct cinfo;
  jpeg::ErrorManager err;
  cinfo.err = jpeg::install(err, jpeg::onMessageLenient);  // corrupt data: decode what is there
  unsigned char* volatile out = nullptr;
  if (setjmp(err.jump)) {
    std::free(out);
    jpeg_destroy_decompress(&cinfo);
    return err.message;
  }
  jpeg_create_decompress(&cinfo);
  jpeg_mem_src(&cinfo, data, static_cast<unsigned long>(size));
  jpeg_read_header(&cinfo, TRUE);
  cinfo.out_color_space = channels == 1 ? JCS_GRAYSCALE : JCS_RGB;
  // Checked before anything is allocated: a few bytes of header can claim any size, and the
  // files come from shards users download.
  const uint64_t pixelCount = static_cast<uint64_t>(cinfo.image_width) * cinfo.image_height;
  // No JPEG holds more than about 300 pixels a byte (an 8 x 8 block costs at least 2 bits).
  if (pixelCount == 0 || pixelCount > (uint64_t(1) << 28) || pixelCount > 4096 * uint64_t(size)) {
    std::snprintf(err.message, sizeof err.message, "image is too large or empty (%ux%u)",
                  cinfo.image_width, cinfo.image_height);
    jpeg_destroy_decompress(&cinfo);
    return err.message;
  }
  jpeg_start_decompress(&cinfo);
  const size_t stride = static_cast<size_t>(cinfo.output_width) * cinfo.output_components;
  out = static_cast<unsigned char*>(std::malloc(stride * cinfo.output_height));
  if (!out) {
    std::snprintf(err.message, sizeof err.message, "out of memory");
    std::longjmp(err.jump, 1);
  }
  while (cinfo.output_scanline < cinfo.output_height) {
    JSAMPROW row = out + stride * cinfo.output_scanline;
    jpeg_read_scanlines(&cinfo, &row, 1);
  }
  jpeg_finish_decompress(&cinfo);
  *width = static_cast<int>(cinfo.output_width);
  *height = static_cast<int>(cinfo.output_height);
  *pixels = out;
  jpeg_destroy_decompress(&cinfo);
  return {};
}

uint32_t crc32(const unsigned char* p, size_t n, uint32_t crc = 0) {
  crc = ~crc;
  for (size_t i = 0; i < n; ++i) {
    crc ^= p[i];
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
  }
  return ~crc;
}

void put32(std::vector<unsigned char>& v, uint32_t x) {
  for (int s = 24; s >= 0; s -= 8) v.push_back(static_cast<unsigned char>(x >> s));
}

void pngChunk(std::vector<unsigned char>& png, const char* type,
              const std::vector<unsigned char>& body) {
  put32(png, static_cast<uint32_t>(body.size()));
  const size_t start = png.size();
  png.insert(png.end(), type, type + 4);
  png.insert(png.end(), body.begin(), body.end());
  put32(png, crc32(png.data() + start, png.size() - start));
}

// An 8-bit gray or RGB PNG whose zlib stream holds stored blocks (no compression).
std::vector<unsigned char> encodePng(const Image8& image) {
  if (image.channels != 1 && image.channels != 3) throw Error("PNG: 1 or 3 channels only");
  const size_t stride = static_cast<size_t>(image.width) * image.channels;
  std::vector<unsigned char> raw;  // [H, 1 + W C]: filter byte 0, then the row
  raw.reserve((stride + 1) * image.height);
  for (int y = 0; y < image.height; ++y) {
    raw.push_back(0);
    raw.insert(raw.end(), image.data.begin() + y * stride, image.data.begin() + (y + 1) * stride);
  }
  std::vector<unsigned char> z = {0x78, 0x01};
  uint32_t a = 1, b = 0;  // Adler-32
  for (unsigned char c : raw) {
    a = (a + c) % 65521;
    b = (b + a) % 65521;
  }
  for (size_t at = 0; at < raw.size() || at == 0;) {
    const size_t n = std::min<size_t>(65535, raw.size() - at);
    const bool last = at + n == raw.size();
    z.push_back(last ? 1 : 0);
    z.push_back(static_cast<unsigned char>(n & 0xff));
    z.push_back(static_cast<unsigned char>(n >> 8));
    z.push_back(static_cast<unsigned char>(~n & 0xff));
    z.push_back(static_cast<unsigned char>((~n >> 8) & 0xff));
    z.insert(z.end(), raw.begin() + at, raw.begin() + at + n);
    at += n;
    if (last) break;
  }
  put32(z, (b << 16) | a);
  std::vector<unsigned char> png = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  std::vector<unsigned char> header;
  put32(header, static_cast<uint32_t>(image.width));
  put32(header, static_cast<uint32_t>(image.height));
  header.insert(header.end(),
                {8, static_cast<unsigned char>(image.channels == 1 ? 0 : 2), 0, 0, 0});
  pngChunk(png, "IHDR", header);
  pngChunk(png, "IDAT", z);
  pngChunk(png, "IEND", {});
  return png;
}

}  // namespace

std::vector<unsigned char> encodeImage(const Image8& image, std::string_view format,
                                       int jpegQuality) {
  if (image.width <= 0 || image.height <= 0 || image.channels <= 0)
    throw Error("cannot encode an empty image");
  if (format == "png") return encodePng(image);
  if (format != "jpg" && format != "jpeg")
    throw Error("image." + std::string(format), std::string("encoding ") + kFullBuild);
  return encodeJpeg(image, jpegQuality);
}

#ifdef PAIRCAST_HAVE_OPENEXR_CORE
std::vector<unsigned char> encodeExr(const ImageF& image, bool half) {
  if (half) throw Error("image.exr", std::string("half-float EXR ") + kFullBuild);
  return encodeExrCore(image);
}

void writeExr(const std::string& path, const ImageF& image, bool half) {
  const std::vector<unsigned char> bytes = encodeExr(image, half);
  writeFileAtomic(path,
                  std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
}
#else
std::vector<unsigned char> encodeExr(const ImageF&, bool) {
  throw Error("image.exr", std::string("EXR ") + kNoOpenExr);
}

void writeExr(const std::string& path, const ImageF&, bool) {
  throw Error(path, std::string("EXR ") + kNoOpenExr);
}
#endif

Image8 decodeImage8(const void* data, size_t size, const std::string& name, int channels) {
  const auto* p = static_cast<const unsigned char*>(data);
  if (size < 3 || p[0] != 0xFF || p[1] != 0xD8 || p[2] != 0xFF)
    throw Error(name, std::string("not a JPEG; other formats ") + kFullBuild);
  int w = 0, h = 0;
  unsigned char* pixels = nullptr;
  const int nc = channels == 1 ? 1 : 3;
  const std::string failure = decodeJpeg(p, size, nc, &w, &h, &pixels);
  if (!failure.empty()) throw Error(name, "cannot decode image: " + failure);
  Image8 image;
  image.width = w;
  image.height = h;
  image.channels = nc;
  image.data.assign(pixels, pixels + static_cast<size_t>(w) * h * nc);
  std::free(pixels);
  return image;
}

Image8 readImage8(const std::string& path, int channels) {
  if (!fs::exists(path)) throw Error(path, "no such file");
  const std::string bytes = readFile(path);
  return decodeImage8(bytes.data(), bytes.size(), path, channels);
}

#ifdef PAIRCAST_HAVE_OPENEXR_CORE
ImageF decodeImageF(const void* data, size_t size, const std::string& name) {
  const auto* p = static_cast<const unsigned char*>(data);
  if (size < 4 || p[0] != 0x76 || p[1] != 0x2f || p[2] != 0x31 || p[3] != 0x01)
    throw Error(name, std::string("not an EXR; other float formats ") + kFullBuild);
  return decodeExrCore(data, size, name);
}

ImageF readImageF(const std::string& path) {
  if (!fs::exists(path)) throw Error(path, "no such file");
  const std::string bytes = readFile(path);
  return decodeImageF(bytes.data(), bytes.size(), path);
}
#else
ImageF decodeImageF(const void*, size_t, const std::string& name) {
  throw Error(name, std::string("float images (EXR) ") + kNoOpenExr);
}

ImageF readImageF(const std::string& path) {
  throw Error(path, std::string("float images (EXR) ") + kNoOpenExr);
}
#endif

}  // namespace paircast
