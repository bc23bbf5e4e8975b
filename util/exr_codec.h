// EXR float maps through OpenEXR's C library (OpenEXRCore), for the trainer-only build, which has
// no OpenImageIO: finetune reads the shards' depth (K.k.depth.exr) and --predict writes depth
// maps. Its interface is C, so it links whatever C++ ABI the LibTorch beside it was built with.
// The full build reads and writes EXR through OpenImageIO; the tests check that each reads what
// the other writes.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "util/image.h"

namespace paircast {

// Decodes a scanline EXR (any compression OpenEXR knows; half, float or uint channels) into
// float32. Channels R, G, B come out in that order; other names in the file's (alphabetical)
// order. Throws paircast::Error naming `name` when the bytes are not such a file.
ImageF decodeExrCore(const void* data, size_t size, const std::string& name);

// Encodes float32 with ZIP compression: 1 channel named "Y", or 3 named "R", "G", "B".
std::vector<unsigned char> encodeExrCore(const ImageF& image);

}  // namespace paircast
