// A texture as the renderer samples it: 8-bit sRGB texels in a mip pyramid built in linear light,
// sampled bilinearly on the level that matches the footprint of the sample.
//
// Why a pyramid: a wall a few metres away at 256x256 covers several texels per pixel. Sampling
// the full-size texture there aliases (the image shimmers with the pose) and, since neighbouring
// pixels land on texels far apart, each hit misses the cache. The level whose texels match the
// pixel's footprint fixes both.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <cstring>
#include <vector>

#include "render/mesh.h"

namespace paircast {

class TexturePyramid {
 public:
  // Level 0 is the texture itself; each next level halves both sides (to at least 1), averaging
  // 2x2 texels in linear space. Throws paircast::Error on an empty or inconsistent texture.
  explicit TexturePyramid(const Texture& texture);

  int levels() const { return levels_; }
  int width(int level) const { return width_[level]; }
  int height(int level) const { return height_[level]; }
  // Linear RGB of texel (x, y) of `level` (row 0 at the top, v = 1).
  Eigen::Vector3f texel(int level, int x, int y) const;

  // Linear RGB at texture coordinates (u, v) (wrapping; v = 0 at the bottom), bilinear on
  // `level` (clamped to the pyramid's). Zero for non-finite (u, v).
  Eigen::Vector3f sample(float u, float v, int level) const;
  // `sample` for the lanes i of eight whose bit is set in `lanes`: rgb[c][i] from (u[i], v[i])
  // on level[i]. Other lanes are left alone.
  void sample8(const float* u, const float* v, const int32_t* level, uint32_t lanes,
               float (*rgb)[8]) const;

  // The pyramid's arrays as SIMD kernels read them (render/texture_kernel.h).
  // The level tables hold at least kTableSize entries (zeros past the last level), so that a
  // kernel can load the first 16 whole.
  static constexpr size_t kTableSize = 16;
  struct Arrays {
    const uint32_t* texels;                  // see texels_ below
    const int32_t *width, *height, *offset;  // by level
    int top;                                 // the last level
    const float* decode;                     // sRGB in 8.4 fixed point (0..4080) to linear
  };
  Arrays arrays() const {
    return {texels_.data(), width_.data(), height_.data(),
            offset_.data(), levels() - 1,  kDecode.data()};
  }

  // The level for a sample that covers `area` texels of level 0: the one whose texel side is
  // nearest its side, round(log2(area) / 2), which is (floor(log2(area)) + 1) / 2 rounded down:
  // the float's exponent gives it without a logarithm. 0 at most one texel (and NaN); not clamped
  // to the pyramid's levels (sample does). The area, since the renderer gets it without a square
  // root.
  static int levelForArea(float area) {
    if (!(area > 1.0f)) return 0;
    uint32_t bits;
    std::memcpy(&bits, &area, sizeof bits);
    const int exponent = static_cast<int>((bits >> 23) & 255) - 127;  // 128 for infinity
    return (exponent + 1) >> 1;
  }

 private:
  // All levels in one array (so that one gather with one base reads any level's texels): 8-bit
  // sRGB, R in the low byte; level l is [height_[l], width_[l] + 1] from offset_[l], each row
  // ending with a copy of its first texel, so that a texel and its right neighbour (wrapping)
  // are one 64-bit load.
  std::vector<uint32_t> texels_;
  std::vector<int32_t> width_, height_, offset_;  // by level, padded to kTableSize
  int levels_ = 0;
  static const std::array<float, 4096> kDecode;  // Arrays::decode
};

}  // namespace paircast
