// Image files through OpenImageIO: PNG and JPEG for 8-bit RGB, EXR for float maps (depth,
// normals). Every function throws paircast::Error naming the file on failure.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "util/image.h"

namespace paircast {

// Writes an 8-bit image; the format follows the extension (.png, .jpg/.jpeg). Atomic.
void writeImage(const std::string& path, const Image8& image, int jpegQuality = 95);
// Writes a float image as EXR (float32, or half when `half`), with 1 channel named "Y" or 3
// named "R","G","B". Atomic.
void writeExr(const std::string& path, const ImageF& image, bool half = false);

// The extension of `path` in lower case, without its dot ("" when none).
std::string lowerExtension(const std::string& path);

// Encodes to bytes in memory; `format` is "png", "jpg" or "exr".
std::vector<unsigned char> encodeImage(const Image8& image, std::string_view format,
                                       int jpegQuality = 95);
std::vector<unsigned char> encodeExr(const ImageF& image, bool half = false);

// Reads any 8-bit-convertible image; the result has `channels` channels (1 or 3; gray is
// replicated, alpha dropped).
Image8 readImage8(const std::string& path, int channels = 3);
// Reads a float image (e.g. a depth EXR), keeping its channel count.
ImageF readImageF(const std::string& path);

// An encoded image held in memory, with the name its messages give (a file, or "shard: member").
struct EncodedImage {
  std::vector<unsigned char> bytes;
  std::string name;
};

// Decodes images held in memory; `name` is used in error messages and to pick the format.
Image8 decodeImage8(const void* data, size_t size, const std::string& name, int channels = 3);
ImageF decodeImageF(const void* data, size_t size, const std::string& name);

}  // namespace paircast
