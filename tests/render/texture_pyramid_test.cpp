#include "render/texture_pyramid.h"

#include <gtest/gtest.h>

#include <cmath>

#include "render/ray_caster.h"
#include "render/render_albedo.h"

namespace paircast {
namespace {

// A w x h texture whose texel (x, y) is white where x + y is even and black elsewhere.
Texture checkerboard(int w, int h) {
  Texture t;
  t.name = "checker";
  t.width = w;
  t.height = h;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) t.texels.push_back((x + y) % 2 ? 0 : 255);
  return t;
}

TEST(TexturePyramid, HalvesEachSideDownToOneTexel) {
  const TexturePyramid square(checkerboard(256, 256));
  EXPECT_EQ(square.levels(), 9);
  EXPECT_EQ(square.width(8), 1);
  const TexturePyramid odd(checkerboard(5, 3));  // 5x3, 2x1, 1x1
  ASSERT_EQ(odd.levels(), 3);
  EXPECT_EQ(odd.width(1), 2);
  EXPECT_EQ(odd.height(1), 1);
}

TEST(TexturePyramid, LevelsAverageInLinearLight) {
  // Black and white average to linear 0.5 (sRGB 188), not to sRGB 128.
  const TexturePyramid p(checkerboard(8, 8));
  for (int level = 1; level < p.levels(); ++level) {
    const Eigen::Vector3f c = p.texel(level, 0, 0);
    EXPECT_NEAR(c.x(), 0.5f, 0.01f) << "level " << level;
    EXPECT_EQ(linearToSrgb8(c.x()), 188) << "level " << level;
  }
}

TEST(TexturePyramid, FullSizeMatchesTheTextureAtTexelCentres) {
  Texture t;
  t.width = 3;
  t.height = 2;
  t.texels = {10, 20, 30, 200, 100, 50, 7, 8, 9, 255, 0, 128, 60, 70, 80, 1, 2, 3};
  const TexturePyramid p(t);
  for (int y = 0; y < 2; ++y) {
    for (int x = 0; x < 3; ++x) {
      const float u = (x + 0.5f) / 3, v = 1.0f - (y + 0.5f) / 2;
      EXPECT_TRUE(p.sample(u, v, 0.0f).isApprox(t.sample(u, v), 1e-3f)) << x << "," << y;
      EXPECT_TRUE(p.sample(u + 2.0f, v - 3.0f, 0.0f).isApprox(t.sample(u, v), 1e-3f));  // wraps
    }
  }
  EXPECT_EQ(p.sample(NAN, 0.5f, 0.0f), Eigen::Vector3f::Zero());
  EXPECT_EQ(p.sample(0.5f, INFINITY, 0.0f), Eigen::Vector3f::Zero());
}

TEST(TexturePyramid, LevelIsLog2OfTheFootprintsSideRounded) {
  EXPECT_EQ(TexturePyramid::levelForArea(0.3f), 0);
  EXPECT_EQ(TexturePyramid::levelForArea(1.0f), 0);
  EXPECT_EQ(TexturePyramid::levelForArea(3.99f), 1);  // side 2.0: level 1 (side 2)
  EXPECT_EQ(TexturePyramid::levelForArea(16.0f), 2);
  EXPECT_EQ(TexturePyramid::levelForArea(31.9f), 2);  // side 5.65: nearer 4 than 8 in log2
  EXPECT_EQ(TexturePyramid::levelForArea(32.0f), 3);  // side 5.66 = 2^2.5: rounds up
  EXPECT_EQ(TexturePyramid::levelForArea(1024.0f * 1024.0f), 10);
  EXPECT_EQ(TexturePyramid::levelForArea(NAN), 0);
  EXPECT_GE(TexturePyramid::levelForArea(INFINITY), 30);
  // Against the logarithm itself, away from the rounding boundaries.
  for (float area = 1.5f; area < 1e12f; area *= 1.37f) {
    const double lod = 0.5 * std::log2(static_cast<double>(area));
    if (std::fabs(lod - std::floor(lod) - 0.5) < 1e-4) continue;
    EXPECT_EQ(TexturePyramid::levelForArea(area), static_cast<int>(std::lround(lod))) << area;
  }
}

// A far plane tiled with a one-texel checkerboard: each pixel covers many texels. Sampling the
// full-size texture would give a random mix of black and white pixels (aliasing); the pyramid
// gives the average everywhere.
TEST(TexturePyramid, MinifiedCheckerboardRendersAsItsMean) {
  Mesh mesh;
  mesh.textures.push_back(checkerboard(64, 64));
  Material mat;
  mat.texture = 0;
  const int m = mesh.addMaterial(mat);
  const float s = 50.0f, z = 20.0f, tiles = 200.0f;  // 64 * 200 texels over 100 m
  mesh.addTriangle({-s, -s, z}, {s, -s, z}, {s, s, z}, m, {0, 0}, {tiles, 0}, {tiles, tiles});
  mesh.addTriangle({-s, -s, z}, {s, s, z}, {-s, s, z}, m, {0, 0}, {tiles, tiles}, {0, tiles});
  Camera cam = Camera::fromHfov(64, 64, 40.0);  // 0.22 m per pixel at 20 m: ~28 texels
  const Frame frame = renderAlbedo(mesh, cam);
  int far = 0;
  for (uint8_t c : frame.rgb.data) far += std::abs(int(c) - 188) > 3;
  EXPECT_EQ(far, 0) << "pixels more than 3 levels from the mean grey";
}

}  // namespace
}  // namespace paircast
