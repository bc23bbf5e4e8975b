// Middlebury .flo files (what stereoflow's readFlowFile reads): the float 202021.25 ("PIEH" in
// little-endian bytes), int32 width, int32 height, then width x height (u, v) float32 pairs,
// row-major. All little-endian.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "util/image.h"

namespace paircast {

constexpr float kFloMagic = 202021.25f;

// [H, W, 2] float -> the file's bytes.
std::vector<unsigned char> encodeFlo(const ImageF& flow);
// The bytes of a .flo file -> [H, W, 2]. Throws paircast::Error naming `name` when the magic,
// the size or the length is wrong.
ImageF decodeFlo(const void* data, size_t size, const std::string& name);
ImageF readFlo(const std::string& path);

}  // namespace paircast
