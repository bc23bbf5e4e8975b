#include "render/texture_pyramid.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>

#include "render/texture_kernel.h"
#include "util/error.h"

namespace paircast {
namespace {

// The next level of a w x h level: each side halved (to at least 1), each texel the mean of a
// 2x2 block in linear light (1x2 or 2x1 where a side is already 1, wrapping on odd sides).
std::vector<uint32_t> halve(const std::vector<uint32_t>& a, int w, int h) {
  const int W = std::max(1, w / 2), H = std::max(1, h / 2);
  std::vector<uint32_t> b(static_cast<size_t>(W) * H);
  for (int y = 0; y < H; ++y) {
    const uint32_t* r0 = a.data() + static_cast<size_t>(2 * y % h) * w;
    const uint32_t* r1 = a.data() + static_cast<size_t>((2 * y + 1) % h) * w;
    for (int x = 0; x < W; ++x) {
      const int x0 = 2 * x % w, x1 = (2 * x + 1) % w;
      const Eigen::Vector3f sum =
          unpackSrgb8(r0[x0]) + unpackSrgb8(r0[x1]) + unpackSrgb8(r1[x0]) + unpackSrgb8(r1[x1]);
      b[static_cast<size_t>(y) * W + x] = packSrgb8(0.25f * sum);
    }
  }
  return b;
}

constexpr float kMaxFloat = 3.40282347e38f;

// x - floor(x) for finite x; floats this large are whole numbers.
float fract(float x) {
  if (!(std::fabs(x) < 2.0e9f)) return 0.0f;
  const int i = static_cast<int>(x);
  return x - static_cast<float>(i - (x < static_cast<float>(i)));
}

}  // namespace

// sRGB in 8.4 fixed point (what the bilinear filter yields, 0..4080) to linear.
const std::array<float, 4096> TexturePyramid::kDecode = [] {
  std::array<float, 4096> t{};
  for (int i = 0; i < 4096; ++i) t[i] = srgbToLinear(std::min(1.0f, i / (16.0f * 255.0f)));
  return t;
}();

TexturePyramid::TexturePyramid(const Texture& t) {
  if (t.width <= 0 || t.height <= 0 || (t.channels != 3 && t.channels != 4) ||
      t.texels.size() != static_cast<size_t>(t.width) * t.height * t.channels)
    throw Error("texture '" + t.name + "' has inconsistent size");
  std::vector<uint32_t> packed(static_cast<size_t>(t.width) * t.height);
  for (size_t i = 0; i < packed.size(); ++i) {
    const uint8_t* p = t.texels.data() + i * t.channels;
    packed[i] = p[0] | (uint32_t(p[1]) << 8) | (uint32_t(p[2]) << 16);
  }
  int w = t.width, h = t.height;
  for (;;) {
    width_.push_back(w);
    height_.push_back(h);
    offset_.push_back(static_cast<int32_t>(texels_.size()));
    for (int y = 0; y < h; ++y) {  // each row, then its first texel again
      const auto row = packed.begin() + static_cast<ptrdiff_t>(y) * w;
      texels_.insert(texels_.end(), row, row + w);
      texels_.push_back(*row);
    }
    if (w == 1 && h == 1) break;
    packed = halve(packed, w, h);
    w = std::max(1, w / 2);
    h = std::max(1, h / 2);
  }
  levels_ = static_cast<int>(width_.size());
  for (auto* table : {&width_, &height_, &offset_})
    table->resize(std::max<size_t>(table->size(), kTableSize), 0);
}

Eigen::Vector3f TexturePyramid::texel(int level, int x, int y) const {
  PAIRCAST_CHECK(level >= 0 && level < levels());
  PAIRCAST_CHECK(x >= 0 && x < width_[level] && y >= 0 && y < height_[level]);
  return unpackSrgb8(texels_[offset_[level] + static_cast<size_t>(y) * (width_[level] + 1) + x]);
}

void TexturePyramid::sample8(const float* u, const float* v, const int32_t* level, uint32_t lanes,
                             float (*rgb)[8]) const {
#ifdef PAIRCAST_HAVE_AVX2
  if (cpuHasAvx2() && avx2::fitsTextureKernel(*this))
    return avx2::sampleTexture(arrays(), u, v, level, lanes, rgb);
#endif
  for (int i = 0; i < 8; ++i) {
    if ((lanes >> i) & 1) {
      const Eigen::Vector3f c = sample(u[i], v[i], level[i]);
      for (int k = 0; k < 3; ++k) rgb[k][i] = c[k];
    }
  }
}

// The four texels around (u, v) on `level` weighted in 1/16 of a texel; the weights apply to the
// sRGB values, in integer lanes; the sum is decoded once. Texel centres are at (i + 0.5) / W; row
// 0 is v = 1.
Eigen::Vector3f TexturePyramid::sample(float u, float v, int level) const {
  if (!(std::fabs(u) <= kMaxFloat && std::fabs(v) <= kMaxFloat)) return Eigen::Vector3f::Zero();
  level = std::clamp(level, 0, levels() - 1);
  const int w = width_[level], h = height_[level];
  // Positions x = fract(u) w - 0.5 (y from the top) in 1/16 texel, rounded to the nearest step:
  // (x + 1) 16 + 0.5 is positive, so the cast floors; the shift floors fx >= -8.
  const int fx = static_cast<int>(fract(u) * static_cast<float>(16 * w) + 8.5f) - 16;
  const int fy = static_cast<int>((1.0f - fract(v)) * static_cast<float>(16 * h) + 8.5f) - 16;
  const int ix = fx >> 4, iy = fy >> 4;
  const uint32_t ax = fx & 15, ay = fy & 15;
  const int x0 = ix < 0 ? w - 1 : ix, x1 = ix + 1 >= w ? 0 : ix + 1;
  const int y0 = iy < 0 ? h - 1 : iy, y1 = iy + 1 >= h ? 0 : iy + 1;
  const uint32_t* r0 = texels_.data() + offset_[level] + static_cast<size_t>(y0) * (w + 1);
  const uint32_t* r1 = texels_.data() + offset_[level] + static_cast<size_t>(y1) * (w + 1);
  const uint32_t w00 = (16 - ax) * (16 - ay), w01 = ax * (16 - ay), w10 = (16 - ax) * ay,
                 w11 = ax * ay;
  Eigen::Vector3f c;
  for (int k = 0; k < 3; ++k) {
    const int s = 8 * k;
    const uint32_t sum = w00 * ((r0[x0] >> s) & 255) + w01 * ((r0[x1] >> s) & 255) +
                         w10 * ((r1[x0] >> s) & 255) + w11 * ((r1[x1] >> s) & 255);
    c[k] = kDecode[sum >> 4];  // 255 * 256 >> 4 at most
  }
  return c;
}

}  // namespace paircast
