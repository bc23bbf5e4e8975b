// Bounds the image decoders share against headers that lie about their size.
#pragma once

#include <cstdint>

namespace paircast {

// No image format stores more values per byte of file than this: the densest, DWA-compressed EXR
// on a flat image, keeps one DC value per 8 x 8 block and then deflates those at most 1,032:1
// (about 33,000 values a byte); a flat PNG of 1-bit pixels reaches about 8,000, zip-compressed
// EXR about 500. A header that claims more than its file's bytes can hold is refused before
// anything is allocated.
constexpr uint64_t kMaxValuesPerByte = 1 << 16;

}  // namespace paircast
