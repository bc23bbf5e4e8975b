#include "render/texture_pyramid.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>

#include "util/error.h"

namespace paircast {
namespace {

// sRGB in 8.4 fixed point (what the filter below yields, 0..4080) to linear.
const std::array<float, 4096> kSrgb12ToLinear = [] {
  std::array<float, 4096> t{};
  for (int i = 0; i < 4096; ++i) t[i] = srgbToLinear(std::min(1.0f, i / (16.0f * 255.0f)));
  return t;
}();

// A texel with its channels 21 bits apart, so that a weighted sum of four with weights summing
// to 256 fits in each channel's lane.
uint64_t spread(uint32_t p) {
  return (p & 255) | (uint64_t((p >> 8) & 255) << 21) | (uint64_t((p >> 16) & 255) << 42);
}

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

// x - floor(x) for finite x; floats this large are whole numbers.
float fract(float x) {
  if (!(std::fabs(x) < 2.0e9f)) return 0.0f;
  const int i = static_cast<int>(x);
  return x - static_cast<float>(i - (x < static_cast<float>(i)));
}

}  // namespace

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
    Level level{w, h, std::vector<uint64_t>(packed.size())};
    for (size_t i = 0; i < packed.size(); ++i) level.texels[i] = spread(packed[i]);
    levels_.push_back(std::move(level));
    if (w == 1 && h == 1) break;
    packed = halve(packed, w, h);
    w = std::max(1, w / 2);
    h = std::max(1, h / 2);
  }
}

Eigen::Vector3f TexturePyramid::texel(int level, int x, int y) const {
  const Level& l = levels_.at(level);
  PAIRCAST_CHECK(x >= 0 && x < l.width && y >= 0 && y < l.height);
  const uint64_t p = l.texels[static_cast<size_t>(y) * l.width + x];
  return unpackSrgb8((p & 255) | (((p >> 21) & 255) << 8) | (((p >> 42) & 255) << 16));
}

Eigen::Vector3f TexturePyramid::sample(float u, float v, float lod) const {
  if (!std::isfinite(u) || !std::isfinite(v)) return Eigen::Vector3f::Zero();
  const int level = std::clamp(static_cast<int>(std::min(lod, 64.0f) + 0.5f), 0, levels() - 1);
  return bilinear(levels_[level], fract(u), fract(v));
}

// Texel centres are at (i + 0.5) / W; row 0 is v = 1. u and v are in [0, 1). The weights (in
// 1/16 of a texel) apply to the sRGB values, in integer lanes; the sum is decoded once.
Eigen::Vector3f TexturePyramid::bilinear(const Level& l, float u, float v) const {
  const float x = u * l.width - 0.5f, y = (1.0f - v) * l.height - 0.5f;
  // Positions in 1/16 texel, rounded to the nearest step; the shift floors (fx >= -8).
  const int fx = static_cast<int>((x + 1.0f) * 16.0f + 0.5f) - 16;
  const int fy = static_cast<int>((y + 1.0f) * 16.0f + 0.5f) - 16;
  const int ix = fx >> 4, iy = fy >> 4;
  const uint64_t ax = fx & 15, ay = fy & 15;
  const int x0 = ix < 0 ? l.width - 1 : ix, x1 = ix + 1 >= l.width ? 0 : ix + 1;
  const int y0 = iy < 0 ? l.height - 1 : iy, y1 = iy + 1 >= l.height ? 0 : iy + 1;
  const uint64_t* r0 = l.texels.data() + static_cast<size_t>(y0) * l.width;
  const uint64_t* r1 = l.texels.data() + static_cast<size_t>(y1) * l.width;
  const uint64_t sum = (16 - ay) * ((16 - ax) * r0[x0] + ax * r0[x1]) +
                       ay * ((16 - ax) * r1[x0] + ax * r1[x1]);  // 255 * 256 per lane at most
  constexpr uint64_t kLane = (1u << 21) - 1;
  return {kSrgb12ToLinear[(sum & kLane) >> 4], kSrgb12ToLinear[((sum >> 21) & kLane) >> 4],
          kSrgb12ToLinear[((sum >> 42) & kLane) >> 4]};
}

float TexturePyramid::lodFor(float texelsPerPixel) {
  if (!(texelsPerPixel > 1.0f)) return 0.0f;
  if (!(texelsPerPixel < 1e30f)) return 100.0f;
  // The float's exponent is floor(log2), its mantissa in [1, 2) the linear rest.
  uint32_t bits;
  std::memcpy(&bits, &texelsPerPixel, sizeof bits);
  const int exponent = static_cast<int>((bits >> 23) & 255) - 127;
  const float mantissa = 1.0f + static_cast<float>(bits & 0x7FFFFF) / 8388608.0f;
  return static_cast<float>(exponent) + (mantissa - 1.0f);
}

}  // namespace paircast
