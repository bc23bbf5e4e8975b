#include "render/packet_shading.h"

#include <algorithm>
#include <array>
#include <cmath>

#include "render/mesh.h"
#include "render/texture_kernel.h"
#include "render/texture_pyramid.h"
#include "util/error.h"

namespace paircast {
namespace {

void lightLanesScalar(const float* dirX, const float* dirY, const float* dirZ, const float* t,
                      const PacketLight& light, PacketShading& s) {
  const float* sd = light.sunDir;
  for (int i = 0; i < kLanes; ++i) {
    const float dx = dirX[i], dy = dirY[i], dz = dirZ[i];
    const float nd = s.n[0][i] * dx + s.n[1][i] * dy + s.n[2][i] * dz;
    const float cosView = std::fabs(nd) / std::sqrt(dx * dx + dy * dy + dz * dz);
    const float ns = s.n[0][i] * sd[0] + s.n[1][i] * sd[1] + s.n[2][i] * sd[2];
    const float sunCos = nd > 0 ? -ns : ns;  // the normal turned towards the camera
    s.light[i] = light.ambient + light.headlight * cosView + light.sun * std::max(0.0f, sunCos);
    const float side = s.texelsPerMetre[i] * (t[i] * light.sampleSize);
    s.lod[i] = TexturePyramid::lodForArea(side * side / std::max(cosView, 1e-3f));
  }
}

void combineLanesScalar(const PacketShading& s, const PacketLight& light, float (&rgb)[3][kLanes]) {
  for (int c = 0; c < 3; ++c) {
    for (int i = 0; i < kLanes; ++i) {
      const bool hit = (s.hits >> i) & 1;
      const float texel = s.texture[i] >= 0 ? s.texel[c][i] : 1.0f;
      rgb[c][i] = hit ? s.albedo[c][i] * texel * s.light[i] : light.background[c];
    }
  }
}

void srgbLanesScalar(const float (&rgb)[3][kLanes], float scale, int count, uint8_t* out) {
  for (int i = 0; i < count; ++i)
    for (int c = 0; c < 3; ++c) out[3 * i + c] = linearToSrgb8(rgb[c][i] * scale);
}

#ifdef PAIRCAST_HAVE_AVX2
// kLinearToSrgb8 widened to 32 bits, for gathers.
const int32_t* linearToSrgb8Table() {
  static const std::array<int32_t, 4097> table = [] {
    std::array<int32_t, 4097> t{};
    for (size_t i = 0; i < t.size(); ++i) t[i] = kLinearToSrgb8[i];
    return t;
  }();
  return table.data();
}

// srgbLanesScalar in AVX2 lanes: linearToSrgb8's table index and its two bounds per lane.
PAIRCAST_AVX2 void srgbLanesAvx2(const float (&rgb)[3][kLanes], float scale, int count,
                                 uint8_t* out) {
  const int32_t* table = linearToSrgb8Table();
  __m256i packed = _mm256_setzero_si256();  // lane i: R | G << 8 | B << 16
  for (int c = 0; c < 3; ++c) {
    const __m256 x = _mm256_mul_ps(_mm256_loadu_ps(rgb[c]), _mm256_set1_ps(scale));
    __m256i index = _mm256_cvttps_epi32(
        _mm256_add_ps(_mm256_mul_ps(x, _mm256_set1_ps(4096.0f)), _mm256_set1_ps(0.5f)));
    index =
        _mm256_min_epi32(_mm256_max_epi32(index, _mm256_setzero_si256()), _mm256_set1_epi32(4096));
    const __m256i looked = _mm256_i32gather_epi32(table, index, 4);
    const __m256 positive = _mm256_cmp_ps(x, _mm256_setzero_ps(), _CMP_GT_OQ);  // else 0
    const __m256 below = _mm256_cmp_ps(x, _mm256_set1_ps(1.0f), _CMP_LT_OQ);    // else 255
    const __m256i v = _mm256_and_si256(
        _mm256_blendv_epi8(_mm256_set1_epi32(255), looked, _mm256_castps_si256(below)),
        _mm256_castps_si256(positive));
    packed = _mm256_or_si256(packed, _mm256_sll_epi32(v, _mm_cvtsi32_si128(8 * c)));
  }
  if (count < kLanes) {
    alignas(32) uint32_t p[kLanes];
    _mm256_store_si256(reinterpret_cast<__m256i*>(p), packed);
    for (int i = 0; i < count; ++i)
      for (int c = 0; c < 3; ++c) out[3 * i + c] = static_cast<uint8_t>(p[i] >> (8 * c));
    return;
  }
  // Drop every fourth byte: 12 bytes of pixels in each half, stored as 24 contiguous bytes
  // (16 + 8, never past them: the next pixels may belong to another thread's tile).
  const __m256i drop = _mm256_setr_epi8(0, 1, 2, 4, 5, 6, 8, 9, 10, 12, 13, 14, -1, -1, -1, -1, 0,
                                        1, 2, 4, 5, 6, 8, 9, 10, 12, 13, 14, -1, -1, -1, -1);
  const __m256i bytes = _mm256_shuffle_epi8(packed, drop);  // [12 B, 4 zero | 12 B, 4 zero]
  // Lanes as 32-bit words: 0 1 2 (pixels 0-3), 4 5 6 (pixels 4-7): pack to words 0-5.
  const __m256i words =
      _mm256_permutevar8x32_epi32(bytes, _mm256_setr_epi32(0, 1, 2, 4, 5, 6, 3, 7));
  _mm_storeu_si128(reinterpret_cast<__m128i*>(out), _mm256_castsi256_si128(words));
  _mm_storel_epi64(reinterpret_cast<__m128i*>(out + 16), _mm256_extracti128_si256(words, 1));
}

PAIRCAST_AVX2 inline __m256 dot(const __m256 (&a)[3], __m256 x, __m256 y, __m256 z) {
  return _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(a[0], x), _mm256_mul_ps(a[1], y)),
                       _mm256_mul_ps(a[2], z));
}

// a + u b + v c, as surfaces() interpolates texture coordinates.
PAIRCAST_AVX2 inline __m256 interpolate(__m256 a, __m256 b, __m256 c, __m256 u, __m256 v) {
  return _mm256_add_ps(_mm256_add_ps(a, _mm256_mul_ps(u, b)), _mm256_mul_ps(v, c));
}

// The light factor and level of detail of lightLanesScalar, for normals n.
struct Lit {
  __m256 light, lod;
};
PAIRCAST_AVX2 inline Lit lightAvx2(const __m256 (&n)[3], __m256 dx, __m256 dy, __m256 dz, __m256 t,
                                   __m256 texelsPerMetre, const PacketLight& light) {
  const __m256 nd = dot(n, dx, dy, dz);
  const __m256 absMask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7FFFFFFF));
  const __m256 length = _mm256_sqrt_ps(_mm256_add_ps(
      _mm256_add_ps(_mm256_mul_ps(dx, dx), _mm256_mul_ps(dy, dy)), _mm256_mul_ps(dz, dz)));
  const __m256 cosView = _mm256_div_ps(_mm256_and_ps(nd, absMask), length);
  const __m256 ns = dot(n, _mm256_set1_ps(light.sunDir[0]), _mm256_set1_ps(light.sunDir[1]),
                        _mm256_set1_ps(light.sunDir[2]));
  const __m256 zero = _mm256_setzero_ps();
  const __m256 negated = _mm256_xor_ps(ns, _mm256_set1_ps(-0.0f));
  const __m256 sunCos = _mm256_blendv_ps(ns, negated, _mm256_cmp_ps(nd, zero, _CMP_GT_OQ));
  // std::max(a, b) is (a < b ? b : a), which is maxps(b, a), NaN included.
  const __m256 lit =
      _mm256_add_ps(_mm256_add_ps(_mm256_set1_ps(light.ambient),
                                  _mm256_mul_ps(_mm256_set1_ps(light.headlight), cosView)),
                    _mm256_mul_ps(_mm256_set1_ps(light.sun), _mm256_max_ps(sunCos, zero)));
  const __m256 side =
      _mm256_mul_ps(texelsPerMetre, _mm256_mul_ps(t, _mm256_set1_ps(light.sampleSize)));
  const __m256 area =
      _mm256_div_ps(_mm256_mul_ps(side, side), _mm256_max_ps(_mm256_set1_ps(1e-3f), cosView));
  return {lit, avx2::lodForArea(area)};
}

// lightLanesScalar in AVX2 lanes, operation for operation.
PAIRCAST_AVX2 void lightLanesAvx2(const float* dirX, const float* dirY, const float* dirZ,
                                  const float* t, const PacketLight& light, PacketShading& s) {
  const __m256 n[3] = {_mm256_load_ps(s.n[0]), _mm256_load_ps(s.n[1]), _mm256_load_ps(s.n[2])};
  const Lit lit = lightAvx2(n, _mm256_loadu_ps(dirX), _mm256_loadu_ps(dirY), _mm256_loadu_ps(dirZ),
                            _mm256_loadu_ps(t), _mm256_load_ps(s.texelsPerMetre), light);
  _mm256_store_ps(s.light, lit.light);
  _mm256_store_ps(s.lod, lit.lod);
}

// The scalar passes' results for n packets inside flat triangles, in two phases: light and
// texture reads for all, then the filters and colours. A packet's texels come from memory (level 2
// cache, often): the reads of several packets under way at once take little longer than one
// packet's.
PAIRCAST_AVX2 void shadeFlatPacketsAvx2(const FlatPacket* p, int n, const PacketLight& light,
                                        LaneColours* const* rgb) {
  Lit lit[kMaxFlatPackets];
  avx2::TexelRows texels[kMaxFlatPackets];
  for (int k = 0; k < n; ++k) {
    const ShadeTriangle& t = *p[k].triangle;
    const ShadeTriangle::Surface& f = t.surface;
    const __m256 normal[3] = {_mm256_set1_ps(t.normal[0]), _mm256_set1_ps(t.normal[1]),
                              _mm256_set1_ps(t.normal[2])};
    const bool textured = p[k].texture != nullptr;
    lit[k] = lightAvx2(normal, _mm256_loadu_ps(p[k].dirX), _mm256_loadu_ps(p[k].dirY),
                       _mm256_loadu_ps(p[k].dirZ), _mm256_loadu_ps(p[k].t),
                       _mm256_set1_ps(textured ? f.texelsPerMetre : 0.0f), light);
    if (!textured) continue;
    const __m256 bu = _mm256_loadu_ps(p[k].u), bv = _mm256_loadu_ps(p[k].v);
    __m256 uv[2];
    for (int c = 0; c < 2; ++c)
      uv[c] = interpolate(_mm256_set1_ps(f.uv0[c]), _mm256_set1_ps(f.duv1[c]),
                          _mm256_set1_ps(f.duv2[c]), bu, bv);
    texels[k] = avx2::texelRows(p[k].texture->arrays(), uv[0], uv[1], lit[k].lod);
  }
  for (int k = 0; k < n; ++k) {
    __m256 texel[3] = {_mm256_set1_ps(1.0f), _mm256_set1_ps(1.0f), _mm256_set1_ps(1.0f)};
    if (p[k].texture) avx2::filterTexels(p[k].texture->arrays(), texels[k], texel);
    const float* albedo = p[k].triangle->surface.albedo;
    for (int c = 0; c < 3; ++c)
      _mm256_storeu_ps(
          (*rgb[k])[c],
          _mm256_mul_ps(_mm256_mul_ps(_mm256_set1_ps(albedo[c]), texel[c]), lit[k].light));
  }
}

// Rows r[0..7] of 8 floats to columns: out[k] holds element k of every row.
PAIRCAST_AVX2 inline void transpose8(const __m256 (&r)[8], __m256 (&out)[8]) {
  __m256 t[8], u[8];
  for (int k = 0; k < 4; ++k) {
    t[2 * k] = _mm256_unpacklo_ps(r[2 * k], r[2 * k + 1]);
    t[2 * k + 1] = _mm256_unpackhi_ps(r[2 * k], r[2 * k + 1]);
  }
  for (int k = 0; k < 2; ++k) {
    u[4 * k] = _mm256_shuffle_ps(t[4 * k], t[4 * k + 2], 0x44);
    u[4 * k + 1] = _mm256_shuffle_ps(t[4 * k], t[4 * k + 2], 0xEE);
    u[4 * k + 2] = _mm256_shuffle_ps(t[4 * k + 1], t[4 * k + 3], 0x44);
    u[4 * k + 3] = _mm256_shuffle_ps(t[4 * k + 1], t[4 * k + 3], 0xEE);
  }
  for (int k = 0; k < 4; ++k) {
    out[k] = _mm256_permute2f128_ps(u[k], u[k + 4], 0x20);
    out[k + 4] = _mm256_permute2f128_ps(u[k], u[k + 4], 0x31);
  }
}

// The scalar passes' results for packets over several kFlat triangles: each lane's 64-byte
// record as two vectors, transposed to one vector per field.
PAIRCAST_AVX2 bool shadeFlatLanesAvx2(const FlatLanes& p, const PacketLight& light,
                                      float (&rgb)[3][kLanes]) {
  static_assert(sizeof(ShadeTriangle) == 16 * sizeof(float));
  __m256 rows[2][8];
  for (int i = 0; i < kLanes; ++i) {
    const auto* r =
        reinterpret_cast<const float*>(p.triangles + ((p.hits >> i) & 1 ? p.prim[i] : 0));
    rows[0][i] = _mm256_load_ps(r);
    rows[1][i] = _mm256_load_ps(r + 8);
  }
  // Fields: normal x y z, texture, colour, albedo r g b | uv0, duv1, duv2 (x y each), density.
  __m256 f[8], g[8];
  transpose8(rows[0], f);
  transpose8(rows[1], g);
  const __m256 hit = _mm256_castsi256_ps(avx2::laneMask(p.hits));
  const __m256i colour = _mm256_and_si256(_mm256_castps_si256(f[4]), _mm256_castps_si256(hit));
  if (!_mm256_testz_si256(colour, colour)) return false;  // some lane is not kFlat (0)
  const __m256i texture =
      _mm256_or_si256(_mm256_and_si256(_mm256_castps_si256(f[3]), _mm256_castps_si256(hit)),
                      _mm256_andnot_si256(_mm256_castps_si256(hit), _mm256_set1_epi32(-1)));
  const __m256 textured = _mm256_castsi256_ps(_mm256_cmpgt_epi32(texture, _mm256_set1_epi32(-1)));
  const __m256 n[3] = {f[0], f[1], f[2]};
  const Lit lit =
      lightAvx2(n, _mm256_loadu_ps(p.dirX), _mm256_loadu_ps(p.dirY), _mm256_loadu_ps(p.dirZ),
                _mm256_loadu_ps(p.t), _mm256_and_ps(g[6], textured), light);
  __m256 texel[3] = {_mm256_set1_ps(1.0f), _mm256_set1_ps(1.0f), _mm256_set1_ps(1.0f)};
  int todo = _mm256_movemask_ps(textured);
  if (todo) {
    const __m256 bu = _mm256_loadu_ps(p.u), bv = _mm256_loadu_ps(p.v);
    const __m256 tu = interpolate(g[0], g[2], g[4], bu, bv);
    const __m256 tv = interpolate(g[1], g[3], g[5], bu, bv);
    alignas(32) int32_t ids[kLanes];
    _mm256_store_si256(reinterpret_cast<__m256i*>(ids), texture);
    while (todo) {  // a texture at a time, usually one
      const int id = ids[__builtin_ctz(static_cast<unsigned>(todo))];
      const TexturePyramid& pyramid = p.textures[id];
      if (!avx2::fitsTextureKernel(pyramid)) return false;
      const __m256 lanes = _mm256_castsi256_ps(_mm256_cmpeq_epi32(texture, _mm256_set1_epi32(id)));
      __m256 c[3];
      avx2::sampleTexture(pyramid.arrays(), tu, tv, lit.lod, c);
      for (int k = 0; k < 3; ++k) texel[k] = _mm256_blendv_ps(texel[k], c[k], lanes);
      todo &= ~_mm256_movemask_ps(lanes);
    }
  }
  for (int c = 0; c < 3; ++c) {
    const __m256 colour = _mm256_mul_ps(_mm256_mul_ps(f[5 + c], texel[c]), lit.light);
    _mm256_storeu_ps(rgb[c], _mm256_blendv_ps(_mm256_set1_ps(light.background[c]), colour, hit));
  }
  return true;
}

PAIRCAST_AVX2 void combineLanesAvx2(const PacketShading& s, const PacketLight& light,
                                    float (&rgb)[3][kLanes]) {
  const __m256 hit = _mm256_castsi256_ps(avx2::laneMask(s.hits));
  const __m256 lit = _mm256_load_ps(s.light);
  const __m256 textured = _mm256_castsi256_ps(_mm256_cmpgt_epi32(
      _mm256_load_si256(reinterpret_cast<const __m256i*>(s.texture)), _mm256_set1_epi32(-1)));
  for (int c = 0; c < 3; ++c) {
    const __m256 texel =
        _mm256_blendv_ps(_mm256_set1_ps(1.0f), _mm256_load_ps(s.texel[c]), textured);
    const __m256 colour = _mm256_mul_ps(_mm256_mul_ps(_mm256_load_ps(s.albedo[c]), texel), lit);
    _mm256_storeu_ps(rgb[c], _mm256_blendv_ps(_mm256_set1_ps(light.background[c]), colour, hit));
  }
}
#endif

}  // namespace

bool shadeFlatPackets(const FlatPacket* p, int n, const PacketLight& light,
                      LaneColours* const* rgb) {
  PAIRCAST_CHECK(n >= 0 && n <= kMaxFlatPackets);
#ifdef PAIRCAST_HAVE_AVX2
  bool fits = cpuHasAvx2();
  for (int k = 0; k < n && fits; ++k)
    fits = !p[k].texture || avx2::fitsTextureKernel(*p[k].texture);
  if (fits) {
    shadeFlatPacketsAvx2(p, n, light, rgb);
    return true;
  }
#endif
  return false;
}

bool shadeFlatLanes(const FlatLanes& p, const PacketLight& light, float (&rgb)[3][kLanes]) {
#ifdef PAIRCAST_HAVE_AVX2
  if (cpuHasAvx2()) return shadeFlatLanesAvx2(p, light, rgb);
#endif
  return false;
}

void srgbLanes(const float (&rgb)[3][kLanes], float scale, int count, uint8_t* out) {
#ifdef PAIRCAST_HAVE_AVX2
  if (cpuHasAvx2()) return srgbLanesAvx2(rgb, scale, count, out);
#endif
  srgbLanesScalar(rgb, scale, count, out);
}

void lightLanes(const float* dirX, const float* dirY, const float* dirZ, const float* t,
                const PacketLight& light, PacketShading& s) {
#ifdef PAIRCAST_HAVE_AVX2
  if (cpuHasAvx2()) return lightLanesAvx2(dirX, dirY, dirZ, t, light, s);
#endif
  lightLanesScalar(dirX, dirY, dirZ, t, light, s);
}

void combineLanes(const PacketShading& s, const PacketLight& light, float (&rgb)[3][kLanes]) {
#ifdef PAIRCAST_HAVE_AVX2
  if (cpuHasAvx2()) return combineLanesAvx2(s, light, rgb);
#endif
  combineLanesScalar(s, light, rgb);
}

}  // namespace paircast
