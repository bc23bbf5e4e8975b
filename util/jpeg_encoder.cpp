#include "util/jpeg_encoder.h"

#include <cstdlib>
#include <string>

#include "util/error.h"
#include "util/jpeg_errors.h"

namespace paircast {
namespace {

// The Exif segment OpenImageIO writes for an image without metadata: the TIFF header (little
// endian) and an empty first IFD.
constexpr unsigned char kEmptyExif[] = {'E', 'x', 'i', 'f', 0, 0, 'I', 'I', 42, 0,
                                        8,   0,   0,   0,   0, 0, 0,   0,   0,  0};

// Encodes into a malloc'd buffer (no C++ object lives across setjmp). Returns an empty string on
// success, else libjpeg's message.
std::string compress(const Image8& image, int quality, unsigned char** bytes, unsigned long* size) {
  jpeg_compress_struct cinfo;
  jpeg::ErrorManager err;
  cinfo.err = jpeg::install(err, jpeg::onMessageLenient);
  if (setjmp(err.jump)) {
    jpeg_destroy_compress(&cinfo);
    return err.message;
  }
  jpeg_create_compress(&cinfo);
  jpeg_mem_dest(&cinfo, bytes, size);
  cinfo.image_width = static_cast<JDIMENSION>(image.width);
  cinfo.image_height = static_cast<JDIMENSION>(image.height);
  cinfo.input_components = image.channels;
  cinfo.in_color_space = image.channels == 1 ? JCS_GRAYSCALE : JCS_RGB;
  jpeg_set_defaults(&cinfo);
  jpeg_set_quality(&cinfo, quality, TRUE);
  jpeg_start_compress(&cinfo, TRUE);
  jpeg_write_marker(&cinfo, JPEG_APP0 + 1, kEmptyExif, sizeof kEmptyExif);
  const size_t stride = static_cast<size_t>(image.width) * image.channels;
  while (cinfo.next_scanline < cinfo.image_height) {
    JSAMPROW row = const_cast<unsigned char*>(image.data.data()) + stride * cinfo.next_scanline;
    jpeg_write_scanlines(&cinfo, &row, 1);
  }
  jpeg_finish_compress(&cinfo);
  jpeg_destroy_compress(&cinfo);
  return {};
}

}  // namespace

std::vector<unsigned char> encodeJpeg(const Image8& image, int quality) {
  if (image.width <= 0 || image.height <= 0 || image.channels <= 0)
    throw Error("cannot encode an empty image");
  if (image.channels != 1 && image.channels != 3) throw Error("JPEG: 1 or 3 channels only");
  if (quality < 1 || quality > 100)
    throw Error("image.jpg", "JPEG quality must be in 1..100, got " + std::to_string(quality));
  unsigned char* bytes = nullptr;
  unsigned long size = 0;
  const std::string failure = compress(image, quality, &bytes, &size);
  std::vector<unsigned char> out;
  if (failure.empty()) out.assign(bytes, bytes + size);
  std::free(bytes);
  if (!failure.empty()) throw Error("image.jpg", "cannot encode: " + failure);
  return out;
}

}  // namespace paircast
