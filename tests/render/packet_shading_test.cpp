// The SIMD kernels against the scalar code they replace: the same bytes, on the shipped textured
// scenes and on inputs chosen to reach every branch.
#include "render/packet_shading.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>

#include "render/ray_caster.h"
#include "render/scene_loader.h"
#include "render/texture_pyramid.h"
#include "util/simd.h"

namespace paircast {
namespace {

// Runs f with the AVX2 kernels off, then on, and restores them.
template <typename F>
auto scalarThenSimd(F f) {
  simdKernelsEnabled() = false;
  auto scalar = f();
  simdKernelsEnabled() = true;
  auto simd = f();
  return std::make_pair(scalar, simd);
}

bool haveSimd() {
  return cpuHasAvx2();
}

// A render with the SIMD kernels off, then on: the colour bytes that differ (the depth must not
// differ at all), of how many, and the pixels that hit something.
struct Comparison {
  size_t differing = 0, bytes = 0, hits = 0;
};
Comparison compareRenders(const RayCaster& caster, const Camera& cam, int supersample) {
  RenderOptions o;
  o.normals = o.ids = false;
  o.supersample = supersample;
  const auto [scalar, simd] = scalarThenSimd([&] {
    Frame f;
    caster.render(cam, o, f);
    return f;
  });
  EXPECT_EQ(scalar.depth.data, simd.depth.data);
  Comparison c;
  for (size_t k = 0; k < scalar.rgb.data.size(); ++k)
    c.differing += scalar.rgb.data[k] != simd.rgb.data[k];
  c.bytes = scalar.rgb.data.size();
  for (float d : scalar.depth.data) c.hits += d > 0;
  return c;
}

TEST(PacketShading, SimdRendersTheSameBytesAsScalarOnTexturedScenes) {
  if (!haveSimd()) GTEST_SKIP() << "no AVX2 on this CPU: only the scalar code runs";
  for (const char* name : {"apartment", "room", "studio"}) {
    const std::string path =
        std::string(PAIRCAST_SOURCE_DIR) + "/scenes/" + name + "/" + name + ".obj";
    const Scene scene = loadScene(path, {});
    const RayCaster caster(scene.mesh);
    const MeshStats stats = computeStats(scene.mesh);
    const Eigen::Vector3f lo = stats.boundsMin, hi = stats.boundsMax;
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> unit(0.1f, 0.9f);
    size_t differing = 0, pixels = 0, hits = 0;
    for (int view = 0; view < 12; ++view) {
      // Inside the bounds at eye height, looking at another point: walls, floors, edges, and
      // (widths not a multiple of 8) partial packets; supersampling on every third view.
      Camera cam = Camera::fromHfov(100 + 12 * view, 96, 60);
      const Eigen::Vector3f eye(lo.x() + unit(rng) * (hi.x() - lo.x()), lo.y() + 1.5f,
                                lo.z() + unit(rng) * (hi.z() - lo.z()));
      const Eigen::Vector3f at(lo.x() + unit(rng) * (hi.x() - lo.x()),
                               lo.y() + unit(rng) * (hi.y() - lo.y()),
                               lo.z() + unit(rng) * (hi.z() - lo.z()));
      cam.lookAt(eye.cast<double>(), at.cast<double>(), {0, 1, 0});
      const Comparison c = compareRenders(caster, cam, view % 3 == 2 ? 2 : 1);
      differing += c.differing;
      pixels += c.bytes;
      hits += c.hits;
    }
    EXPECT_EQ(differing, 0u) << name << ": " << differing << " of " << pixels << " bytes differ";
    EXPECT_GT(hits, pixels / 6) << name << ": the views saw too little to test anything";
  }
}

// A wall of vertical stripes a pixel or two wide, each of four textures, one untextured
// material or a hole: packets over one, two, three or more textures, with untextured lanes and
// misses, which the shipped scenes reach only at a few seams.
TEST(PacketShading, SimdRendersTheSameBytesAsScalarAcrossStripesOfTextures) {
  if (!haveSimd()) GTEST_SKIP() << "no AVX2 on this CPU: only the scalar code runs";
  Mesh mesh;
  std::mt19937 rng(3);
  for (int k = 0; k < 4; ++k) {
    Texture t;
    t.name = "stripe" + std::to_string(k);
    t.width = 16 + 8 * k;
    t.height = 8 + 4 * k;
    for (int i = 0; i < t.width * t.height * 3; ++i) t.texels.push_back(rng() & 255);
    mesh.textures.push_back(t);
    mesh.addMaterial({t.name, Eigen::Vector3f(1.0f, 0.9f - 0.1f * k, 0.8f), k});
  }
  const int plain = mesh.addMaterial({"plain", Eigen::Vector3f(0.2f, 0.5f, 0.7f), -1});
  std::uniform_real_distribution<float> width(0.004f, 0.03f);  // about 0.5 to 4 pixels at 2 m
  int stripe = 0;
  for (float x = -1.5f; x < 1.5f; x += width(rng), ++stripe) {
    const float x1 = x + width(rng) * 0.999f;
    const int kind = static_cast<int>(rng() % 6);  // 0-3 textures, 4 plain, 5 a hole
    if (kind == 5) continue;
    const int material = kind == 4 ? plain : kind;
    const Eigen::Vector3f a(x, -1.5f, 2.0f + 0.1f * x), b(x1, -1.5f, 2.0f + 0.1f * x1),
        c(x1, 1.5f, 2.0f + 0.1f * x1), d(x, 1.5f, 2.0f + 0.1f * x);
    mesh.addTriangle(a, b, c, material, {x, 0}, {x1, 0}, {x1, 3});
    mesh.addTriangle(a, c, d, material, {x, 0}, {x1, 3}, {x, 3});
  }
  const RayCaster caster(mesh);
  Camera cam = Camera::fromHfov(203, 77, 70);  // partial packets on both axes
  for (int ss : {1, 2}) {
    const Comparison c = compareRenders(caster, cam, ss);
    EXPECT_EQ(c.differing, 0u) << c.differing << " of " << c.bytes << " bytes differ, " << ss << "x"
                               << ss << " samples";
    EXPECT_GT(c.hits, c.bytes / 3 / 2) << "the wall should fill most of the view";
  }
  EXPECT_GT(stripe, 100);
}

TEST(PacketShading, TextureSamplesAgreeToTheBitIncludingEdgeCases) {
  if (!haveSimd()) GTEST_SKIP() << "no AVX2 on this CPU: only the scalar code runs";
  Texture t;
  t.name = "noise";
  t.width = 37;  // odd sizes: levels 37x19, 18x9, ... 1x1, and wrapping at odd edges
  t.height = 19;
  t.channels = 3;
  std::mt19937 rng(9);
  for (int i = 0; i < t.width * t.height * 3; ++i) t.texels.push_back(rng() & 255);
  const TexturePyramid p(t);
  std::uniform_real_distribution<float> coord(-3.0f, 3.0f);
  std::uniform_int_distribution<int32_t> level(-1, 7);  // 37x19 has six levels: clamped past
  const float special[] = {0.0f, 1.0f, -1.0f, 1e-30f, 0.9999999f, 3e9f, -3e9f, INFINITY, NAN};
  for (int round = 0; round < 400; ++round) {
    float u[8], v[8];
    int32_t l[8];
    for (int i = 0; i < 8; ++i) {
      u[i] = coord(rng);
      v[i] = coord(rng);
      l[i] = level(rng);
    }
    if (round % 4 == 0) u[round / 4 % 8] = special[round / 32 % 9];
    if (round % 4 == 1) v[round / 4 % 8] = special[round / 32 % 9];
    if (round % 4 == 2) l[round / 4 % 8] = round % 8 < 4 ? 100 : l[0];  // mixed levels
    const uint32_t lanes = round % 5 == 0 ? 0xA5u : 0xFFu;
    float got[3][8], want[3][8];
    for (auto& c : got)
      for (float& x : c) x = -7.0f;  // lanes outside `lanes` must stay untouched
    p.sample8(u, v, l, lanes, got);
    for (int i = 0; i < 8; ++i) {
      const Eigen::Vector3f s = p.sample(u[i], v[i], l[i]);
      for (int c = 0; c < 3; ++c) want[c][i] = (lanes >> i) & 1 ? s[c] : -7.0f;
    }
    for (int c = 0; c < 3; ++c)
      for (int i = 0; i < 8; ++i)
        ASSERT_EQ(std::memcmp(&got[c][i], &want[c][i], sizeof(float)), 0)
            << "lane " << i << " u " << u[i] << " v " << v[i] << " level " << l[i];
  }
}

TEST(PacketShading, SrgbRowsAgreeWithLinearToSrgb8) {
  float rgb[3][kLanes];
  // The table's ends (0, 1 and just inside them), out of range, and not finite.
  const float values[] = {-1.0f,    0.0f, 1e-6f, 1.2e-4f, 0.002f, 0.2f,     0.5f,      0.9999f,
                          0.99999f, 1.0f, 7.0f,  1e30f,   -1e30f, INFINITY, -INFINITY, NAN};
  constexpr int kValues = sizeof values / sizeof values[0];
  for (float scale : {0.75f, 1.0f}) {
    for (int start = 0; start < kValues; ++start) {
      for (int c = 0; c < 3; ++c)
        for (int i = 0; i < kLanes; ++i) rgb[c][i] = values[(start + 3 * c + i) % kValues];
      for (int count : {8, 5, 1}) {
        uint8_t out[3 * kLanes + 4];
        std::fill(std::begin(out), std::end(out), 0xEE);
        srgbLanes(rgb, scale, count, out);
        for (int i = 0; i < count; ++i)
          for (int c = 0; c < 3; ++c)
            ASSERT_EQ(out[3 * i + c], linearToSrgb8(rgb[c][i] * scale)) << rgb[c][i];
        for (int k = 3 * count; k < 3 * kLanes + 4; ++k)
          ASSERT_EQ(out[k], 0xEE) << "wrote past pixel " << count;  // the next tile's pixels
      }
    }
  }
}

}  // namespace
}  // namespace paircast
