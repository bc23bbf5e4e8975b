// A texture as the renderer samples it: 8-bit sRGB texels in a mip pyramid built in linear light,
// sampled bilinearly on the level that matches the footprint of the sample.
//
// Why a pyramid: a wall a few metres away at 256x256 covers several texels per pixel. Sampling
// the full-size texture there aliases (the image shimmers with the pose) and, since neighbouring
// pixels land on texels far apart, each hit misses the cache. The level whose texels match the
// pixel's footprint fixes both.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "render/mesh.h"

namespace paircast {

class TexturePyramid {
 public:
  // Level 0 is the texture itself; each next level halves both sides (to at least 1), averaging
  // 2x2 texels in linear space. Throws paircast::Error on an empty or inconsistent texture.
  explicit TexturePyramid(const Texture& texture);

  int levels() const { return static_cast<int>(levels_.size()); }
  int width(int level) const { return levels_[level].width; }
  int height(int level) const { return levels_[level].height; }
  // Linear RGB of texel (x, y) of `level` (row 0 at the top, v = 1).
  Eigen::Vector3f texel(int level, int x, int y) const;

  // Linear RGB at texture coordinates (u, v) (wrapping; v = 0 at the bottom) at level of detail
  // `lod` (0 is level 0): bilinear on the nearest level. Zero for non-finite (u, v).
  Eigen::Vector3f sample(float u, float v, float lod) const;

  // The level of detail for a sample `texelsPerPixel` texels of level 0 wide: log2 of it
  // (piecewise linear between powers of two), 0 below one texel.
  static float lodFor(float texelsPerPixel);

 private:
  struct Level {
    int width = 0, height = 0;
    std::vector<uint64_t> texels;  // [H, W] 8-bit sRGB R, G, B at bits 0, 21, 42 (see bilinear)
  };
  Eigen::Vector3f bilinear(const Level& level, float u, float v) const;
  std::vector<Level> levels_;
};

}  // namespace paircast
