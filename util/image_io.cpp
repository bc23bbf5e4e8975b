#include "util/image_io.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

#include <filesystem>

#include "util/atomic_file.h"
#include "util/decode_limits.h"
#include "util/error.h"
#include "util/jpeg_encoder.h"

namespace paircast {
namespace {

namespace fs = std::filesystem;
using OIIO::ImageInput;
using OIIO::ImageOutput;
using OIIO::ImageSpec;
using OIIO::TypeDesc;

// Writes through an in-memory proxy so that every file write goes through writeFileAtomic.
template <typename T>
std::vector<unsigned char> encode(const Image<T>& image, const std::string& format, TypeDesc type,
                                  int jpegQuality) {
  if (image.width <= 0 || image.height <= 0 || image.channels <= 0)
    throw Error("cannot encode an empty image");
  std::vector<unsigned char> bytes;
  OIIO::Filesystem::IOVecOutput proxy(bytes);
  const std::string name = "image." + format;
  auto out = ImageOutput::create(name);
  if (!out) throw Error(name, "no OpenImageIO writer: " + OIIO::geterror());
  ImageSpec spec(image.width, image.height, image.channels, type);
  if (format == "jpg" || format == "jpeg") {
    spec.attribute("Compression", "jpeg:" + std::to_string(jpegQuality));
  } else if (format == "exr") {
    // Uncompressed: a rendered depth map's float mantissas are nearly random, so zip barely
    // shrinks it, and compressing it costs several times the rest of a pair's encoding.
    spec.attribute("compression", "none");
    // OpenEXR output otherwise stamps the current time (capDate): fixed, so equal images give
    // equal bytes.
    spec.attribute("DateTime", "1970:01:01 00:00:00");
    if (image.channels == 1) spec.channelnames = {"Y"};
  }
  if (!out->set_ioproxy(&proxy) || !out->open(name, spec))
    throw Error(name, "cannot open encoder: " + out->geterror());
  const TypeDesc src = std::is_same_v<T, float> ? TypeDesc::FLOAT : TypeDesc::UINT8;
  if (!out->write_image(src, image.data.data())) throw Error(name, out->geterror());
  if (!out->close()) throw Error(name, out->geterror());
  return bytes;
}

template <typename T>
Image<T> decode(std::unique_ptr<ImageInput> in, const std::string& name, int channels,
                uint64_t fileBytes) {
  const ImageSpec& spec = in->spec();
  if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0)
    throw Error(name, "image has no pixels");
  // Checked before anything is allocated: a few bytes of header can claim any size (a 1 KB JPEG
  // saying 60000 x 60000), and the files come from shards and scenes users download.
  const uint64_t pixels = static_cast<uint64_t>(spec.width) * static_cast<uint64_t>(spec.height);
  if (pixels > (uint64_t(1) << 28) || spec.nchannels > 64 ||
      pixels * static_cast<uint64_t>(spec.nchannels) * sizeof(T) > (uint64_t(1) << 30))
    throw Error(name, "image is too large (" + std::to_string(spec.width) + "x" +
                          std::to_string(spec.height) + "x" + std::to_string(spec.nchannels) +
                          ", limit 1 GiB decoded)");
  if (pixels * static_cast<uint64_t>(spec.nchannels) > kMaxValuesPerByte * fileBytes)
    throw Error(name, "image header claims " + std::to_string(spec.width) + "x" +
                          std::to_string(spec.height) + "x" + std::to_string(spec.nchannels) +
                          " values in " + std::to_string(fileBytes) + " bytes");
  const int nc = channels > 0 ? channels : spec.nchannels;
  Image<T> image(spec.width, spec.height, nc);
  const TypeDesc dst = std::is_same_v<T, float> ? TypeDesc::FLOAT : TypeDesc::UINT8;
  std::vector<T> all(static_cast<size_t>(spec.width) * spec.height * spec.nchannels);
  if (!in->read_image(0, 0, 0, spec.nchannels, dst, all.data()))
    throw Error(name, "cannot decode image: " + in->geterror());
  const size_t n = static_cast<size_t>(spec.width) * spec.height;
  for (size_t i = 0; i < n; ++i) {
    for (int c = 0; c < nc; ++c) {
      int sc = spec.nchannels >= 3 ? std::min(c, spec.nchannels - 1) : 0;
      image.data[i * nc + c] = all[i * spec.nchannels + sc];
    }
  }
  return image;
}

template <typename T>
Image<T> readFileImage(const std::string& path, int channels) {
  if (!fs::exists(path)) throw Error(path, "no such file");
  auto in = ImageInput::open(path);
  if (!in) throw Error(path, "cannot read image: " + OIIO::geterror());
  std::error_code ec;
  const uintmax_t bytes = fs::file_size(path, ec);
  if (ec) throw Error(path, "cannot read image: " + ec.message());
  return decode<T>(std::move(in), path, channels, bytes);
}

// Bytes in memory are decoded by the reader their name's extension names, and by no other.
// ImageInput::open would offer bytes that fail that reader to every other one: a shard's .exr
// member that lies would reach libtiff, which prints to stderr, and a TIFF named .exr would
// decode. A name without a known extension still goes to every reader.
template <typename T>
Image<T> readMemImage(const void* data, size_t size, const std::string& name, int channels) {
  OIIO::Filesystem::IOMemReader proxy(data, size);
  // By the format's name: given a file name, create() looks for that file.
  const std::string ext = lowerExtension(name);
  auto in = ext.empty() ? nullptr : ImageInput::create(ext);
  if (in) {
    ImageSpec spec;
    if (!in->set_ioproxy(&proxy) || !in->open(name, spec))
      throw Error(name, "cannot decode image: " + in->geterror());
  } else {
    in = ImageInput::open(name, nullptr, &proxy);
    if (!in) throw Error(name, "cannot decode image: " + OIIO::geterror());
  }
  return decode<T>(std::move(in), name, channels, size);
}

}  // namespace

// JPEG straight through libjpeg-turbo (the same bytes as OpenImageIO's writer, faster); other
// formats through OpenImageIO.
std::vector<unsigned char> encodeImage(const Image8& image, std::string_view format,
                                       int jpegQuality) {
  if ((format == "jpg" || format == "jpeg") && (image.channels == 1 || image.channels == 3))
    return encodeJpeg(image, jpegQuality);
  return encode(image, std::string(format), TypeDesc::UINT8, jpegQuality);
}

std::vector<unsigned char> encodeExr(const ImageF& image, bool half) {
  return encode(image, "exr", half ? TypeDesc::HALF : TypeDesc::FLOAT, 0);
}

void writeExr(const std::string& path, const ImageF& image, bool half) {
  if (lowerExtension(path) != "exr") throw Error(path, "float maps are written as .exr");
  auto bytes = encodeExr(image, half);
  writeFileAtomic(path,
                  std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
}

Image8 readImage8(const std::string& path, int channels) {
  return readFileImage<uint8_t>(path, channels);
}

ImageF readImageF(const std::string& path) {
  return readFileImage<float>(path, 0);
}

Image8 decodeImage8(const void* data, size_t size, const std::string& name, int channels) {
  return readMemImage<uint8_t>(data, size, name, channels);
}

ImageF decodeImageF(const void* data, size_t size, const std::string& name) {
  return readMemImage<float>(data, size, name, 0);
}

}  // namespace paircast
