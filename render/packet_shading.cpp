#include "render/packet_shading.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>

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
    s.level[i] = TexturePyramid::levelForArea(side * side / std::max(cosView, 1e-3f));
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

// srgbLanesScalar (with scale 1) in AVX2 lanes, from registers. linearToSrgb8's bounds come with
// the table: its first entry is 0 and its last 255, so x <= 0 (and NaN, which the float minimum
// passes on and the conversion makes negative) reads the first, x >= 1 the last.
PAIRCAST_AVX2 void srgbPixels(const __m256 (&rgb)[3], int count, uint8_t* out) {
  const int32_t* table = linearToSrgb8Table();
  __m256i packed = _mm256_setzero_si256();  // lane i: R | G << 8 | B << 16
  for (int c = 0; c < 3; ++c) {
    const __m256 at =
        _mm256_add_ps(_mm256_mul_ps(rgb[c], _mm256_set1_ps(4096.0f)), _mm256_set1_ps(0.5f));
    const __m256i index = _mm256_max_epi32(
        _mm256_cvttps_epi32(_mm256_min_ps(_mm256_set1_ps(4096.5f), at)), _mm256_setzero_si256());
    const __m256i v = _mm256_i32gather_epi32(table, index, 4);
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

PAIRCAST_AVX2 void srgbLanesAvx2(const float (&rgb)[3][kLanes], float scale, int count,
                                 uint8_t* out) {
  __m256 c[3];
  for (int k = 0; k < 3; ++k) c[k] = _mm256_mul_ps(_mm256_loadu_ps(rgb[k]), _mm256_set1_ps(scale));
  srgbPixels(c, count, out);
}

PAIRCAST_AVX2 inline __m256 dot(const __m256 (&a)[3], __m256 x, __m256 y, __m256 z) {
  return _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(a[0], x), _mm256_mul_ps(a[1], y)),
                       _mm256_mul_ps(a[2], z));
}

// a + u b + v c, as surfaces() interpolates texture coordinates.
PAIRCAST_AVX2 inline __m256 interpolate(__m256 a, __m256 b, __m256 c, __m256 u, __m256 v) {
  return _mm256_add_ps(_mm256_add_ps(a, _mm256_mul_ps(u, b)), _mm256_mul_ps(v, c));
}

// The light factor and texture level of lightLanesScalar, for normals n.
struct Lit {
  __m256 light;
  __m256i level;
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
  return {lit, avx2::levelForArea(area)};
}

// lightLanesScalar in AVX2 lanes, operation for operation.
PAIRCAST_AVX2 void lightLanesAvx2(const float* dirX, const float* dirY, const float* dirZ,
                                  const float* t, const PacketLight& light, PacketShading& s) {
  const __m256 n[3] = {_mm256_load_ps(s.n[0]), _mm256_load_ps(s.n[1]), _mm256_load_ps(s.n[2])};
  const Lit lit = lightAvx2(n, _mm256_loadu_ps(dirX), _mm256_loadu_ps(dirY), _mm256_loadu_ps(dirZ),
                            _mm256_loadu_ps(t), _mm256_load_ps(s.texelsPerMetre), light);
  _mm256_store_ps(s.light, lit.light);
  _mm256_store_si256(reinterpret_cast<__m256i*>(s.level), lit.level);
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

// Where ShadeTriangle's fields lie in its 16 words (floats, or 32-bit integers read as floats),
// as Records holds them: words 0-7 in f, 8-15 in g.
constexpr int wordOf(size_t offset) {
  return static_cast<int>(offset / sizeof(float));
}
constexpr int kNormalWord = wordOf(offsetof(ShadeTriangle, normal));          // x y z
constexpr int kTextureWord = wordOf(offsetof(ShadeTriangle, texture));        // int32
constexpr int kColourWord = wordOf(offsetof(ShadeTriangle, colour));          // int32
constexpr int kAlbedoWord = wordOf(offsetof(ShadeTriangle, surface.albedo));  // r g b
constexpr int kUv0Word = wordOf(offsetof(ShadeTriangle, surface.uv0));        // u v
constexpr int kDuv1Word = wordOf(offsetof(ShadeTriangle, surface.duv1));      // u v
constexpr int kDuv2Word = wordOf(offsetof(ShadeTriangle, surface.duv2));      // u v
constexpr int kTexelsPerMetreWord = wordOf(offsetof(ShadeTriangle, surface.texelsPerMetre));
static_assert(sizeof(ShadeTriangle) == 16 * sizeof(float));
static_assert(sizeof(Eigen::Vector3f) == 3 * sizeof(float));
static_assert(sizeof(int32_t) == sizeof(float) && sizeof(ShadeTriangle::Colour) == sizeof(float));
static_assert(kNormalWord + 3 <= 8 && kTextureWord < 8 && kColourWord < 8 && kAlbedoWord + 3 <= 8,
              "the fields that every packet reads lie in f");
static_assert(ShadeTriangle::kFlat == 0, "packetTextures tests the colour words against 0");

// Each lane's ShadeTriangle, one vector per word: f holds words 0-7, g words 8-15. Fields are
// read as word(k...Word above), never by position.
struct Records {
  __m256 f[8], g[8];
  PAIRCAST_AVX2 __m256 word(int k) const { return k < 8 ? f[k] : g[k - 8]; }
};

// When the lanes that hit share one triangle (most packets), its record broadcast, and the
// triangle returned; else each lane's 64-byte record as two vectors, transposed, and null. Lanes
// that missed read triangle 0.
PAIRCAST_AVX2 inline const ShadeTriangle* loadRecords(const ShadeScene& scene, const RayLanes& p,
                                                      __m256 hit, uint32_t hits, Records& r) {
  alignas(32) uint32_t prim[kLanes];
  const __m256i ids = _mm256_and_si256(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(p.prim)),
                                       _mm256_castps_si256(hit));
  _mm256_store_si256(reinterpret_cast<__m256i*>(prim), ids);
  const uint32_t first = hits ? prim[__builtin_ctz(hits)] : 0;
  const __m256i same = _mm256_cmpeq_epi32(ids, _mm256_set1_epi32(static_cast<int>(first)));
  if (((_mm256_movemask_ps(_mm256_castsi256_ps(same)) | ~hits) & 0xFF) == 0xFF) {
    const auto* record = reinterpret_cast<const float*>(scene.triangles + first);
    for (int k = 0; k < 8; ++k) {
      r.f[k] = _mm256_broadcast_ss(record + k);
      r.g[k] = _mm256_broadcast_ss(record + 8 + k);
    }
    return scene.triangles + first;
  }
  __m256 rows[2][8];
  for (int i = 0; i < kLanes; ++i) {
    const auto* record = reinterpret_cast<const float*>(scene.triangles + prim[i]);
    rows[0][i] = _mm256_load_ps(record);
    rows[1][i] = _mm256_load_ps(record + 8);
  }
  transpose8(rows[0], r.f);
  transpose8(rows[1], r.g);
  return nullptr;
}

// What a packet's stages leave for the next: light, albedo, and where to read its textures: one
// (most packets), none, two (the seams between textured materials), at most one a lane.
struct Prepared {
  Lit lit;
  __m256 albedo[3], hit;
  int textures;                           // how many
  const TexturePyramid* texture[kLanes];  // the textures
  __m256 lanes[kLanes];                   // the lanes of each
  __m256 u, v;                            // texture coordinates (stage 1)
  avx2::TexelAddresses texels[kLanes];    // where each texture is read (stage 2)
};

// albedo * texel * light where a lane hit, the background elsewhere.
PAIRCAST_AVX2 inline void colours(const __m256 (&albedo)[3], const __m256 (&texel)[3], __m256 lit,
                                  __m256 hit, const PacketLight& light, __m256 (&rgb)[3]) {
  for (int c = 0; c < 3; ++c) {
    const __m256 colour = _mm256_mul_ps(_mm256_mul_ps(albedo[c], texel[c]), lit);
    rgb[c] = _mm256_blendv_ps(_mm256_set1_ps(light.background[c]), colour, hit);
  }
}

// A packet's colours to where the caller wants them: linear, or as sRGB pixels.
PAIRCAST_AVX2 inline void put(const __m256 (&rgb)[3], const PacketOut& out) {
  if (out.srgb) return srgbPixels(rgb, out.count, out.srgb);
  for (int c = 0; c < 3; ++c) _mm256_storeu_ps((*out.linear)[c], rgb[c]);
}

// The lanes of each texture, into q. `ids`: each lane's texture, -1 for none; `todo`: the lanes
// that have one.
PAIRCAST_AVX2 inline void splitTextures(const ShadeScene& scene, __m256i ids, int todo,
                                        Prepared& q) {
  alignas(32) int32_t id[kLanes];
  _mm256_store_si256(reinterpret_cast<__m256i*>(id), ids);
  for (q.textures = 0; todo; ++q.textures) {
    const int t = id[__builtin_ctz(static_cast<unsigned>(todo))];
    q.lanes[q.textures] = _mm256_castsi256_ps(_mm256_cmpeq_epi32(ids, _mm256_set1_epi32(t)));
    q.texture[q.textures] = &scene.textures[t];
    todo &= ~_mm256_movemask_ps(q.lanes[q.textures]);
  }
}

// The packet's textures, into q, and the lanes that have one. False when a lane hit a triangle
// that is not kFlat. `triangle`: as loadRecords returns it.
PAIRCAST_AVX2 inline bool packetTextures(const ShadeScene& scene, const ShadeTriangle* triangle,
                                         const Records& r, uint32_t hits, Prepared& q,
                                         __m256& textured) {
  textured = _mm256_setzero_ps();
  q.textures = 0;
  if (triangle) {  // one triangle: its colour and texture hold for all lanes
    if (hits && triangle->colour != ShadeTriangle::kFlat) return false;
    if (hits && triangle->texture >= 0) {
      q.textures = 1;
      q.texture[0] = &scene.textures[triangle->texture];
      q.lanes[0] = textured = q.hit;
    }
    return true;
  }
  const __m256i hit = _mm256_castps_si256(q.hit);
  const __m256i colour = _mm256_and_si256(_mm256_castps_si256(r.word(kColourWord)), hit);
  if (!_mm256_testz_si256(colour, colour)) return false;  // a lane is not kFlat (0)
  const __m256i ids =
      _mm256_or_si256(_mm256_and_si256(_mm256_castps_si256(r.word(kTextureWord)), hit),
                      _mm256_andnot_si256(hit, _mm256_set1_epi32(-1)));
  textured = _mm256_castsi256_ps(_mm256_cmpgt_epi32(ids, _mm256_set1_epi32(-1)));
  splitTextures(scene, ids, _mm256_movemask_ps(textured), q);
  return true;
}

// The first stage of a packet: its records, light, and its texture coordinates. False (the
// packet declined) when it hits a triangle that is not kFlat or a texture too large for the
// kernel.
PAIRCAST_AVX2 bool prepare(const ShadeScene& scene, const RayLanes& p, const PacketLight& light,
                           Prepared& q) {
  const __m256i miss = _mm256_cmpeq_epi32(
      _mm256_loadu_si256(reinterpret_cast<const __m256i*>(p.geomID)), _mm256_set1_epi32(-1));
  q.hit = _mm256_castsi256_ps(_mm256_xor_si256(miss, _mm256_set1_epi32(-1)));
  const auto hits = static_cast<uint32_t>(_mm256_movemask_ps(q.hit));
  Records r;
  const ShadeTriangle* triangle = loadRecords(scene, p, q.hit, hits, r);
  __m256 textured;
  if (!packetTextures(scene, triangle, r, hits, q, textured)) return false;
  for (int k = 0; k < q.textures; ++k)
    if (!avx2::fitsTextureKernel(*q.texture[k])) return false;
  for (int c = 0; c < 3; ++c) q.albedo[c] = r.word(kAlbedoWord + c);
  const __m256 n[3] = {r.word(kNormalWord), r.word(kNormalWord + 1), r.word(kNormalWord + 2)};
  q.lit =
      lightAvx2(n, _mm256_loadu_ps(p.dirX), _mm256_loadu_ps(p.dirY), _mm256_loadu_ps(p.dirZ),
                _mm256_loadu_ps(p.t), _mm256_and_ps(r.word(kTexelsPerMetreWord), textured), light);
  if (!q.textures) return true;
  const __m256 bu = _mm256_loadu_ps(p.u), bv = _mm256_loadu_ps(p.v);
  q.u = interpolate(r.word(kUv0Word), r.word(kDuv1Word), r.word(kDuv2Word), bu, bv);
  q.v = interpolate(r.word(kUv0Word + 1), r.word(kDuv1Word + 1), r.word(kDuv2Word + 1), bu, bv);
  return true;
}

// The third stage: read and filter the texels, and the colours.
PAIRCAST_AVX2 void finish(const Prepared& q, const PacketLight& light, __m256 (&rgb)[3]) {
  __m256 texel[3] = {_mm256_set1_ps(1.0f), _mm256_set1_ps(1.0f), _mm256_set1_ps(1.0f)};
  for (int t = 0; t < q.textures; ++t) {
    __m256 c[3];
    avx2::filterTexels(q.texture[t]->arrays(), q.texels[t], c);
    for (int k = 0; k < 3; ++k) texel[k] = _mm256_blendv_ps(texel[k], c[k], q.lanes[t]);
  }
  colours(q.albedo, texel, q.lit.light, q.hit, light, rgb);
}

// The scalar passes' results for n packets, in stages, each over all the packets: records, light
// and texture coordinates; texel addresses; texel reads, filters and colours; sRGB. Within a
// packet each stage waits on a long chain of the one before (a square root and two divisions,
// the level, the addresses, the gathers); packet after packet, those chains would not fit the
// CPU's window of instructions in flight, stage by stage the packets' operations are independent
// and overlap.
PAIRCAST_AVX2 uint32_t shadeFlatPacketsAvx2(const ShadeScene& scene, const RayLanes* p, int n,
                                            const PacketLight& light, const PacketOut* out) {
  Prepared q[kMaxPackets];
  uint32_t prepared = 0;
  for (int k = 0; k < n; ++k)
    prepared |= static_cast<uint32_t>(prepare(scene, p[k], light, q[k])) << k;
  for (int k = 0; k < n; ++k)
    for (int t = 0; (prepared >> k) & 1 && t < q[k].textures; ++t)
      q[k].texels[t] =
          avx2::texelAddresses(q[k].texture[t]->arrays(), q[k].u, q[k].v, q[k].lit.level);
  __m256 rgb[kMaxPackets][3];
  for (int k = 0; k < n; ++k)
    if ((prepared >> k) & 1) finish(q[k], light, rgb[k]);
  for (int k = 0; k < n; ++k)
    if ((prepared >> k) & 1) put(rgb[k], out[k]);
  return prepared;
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

uint32_t shadeFlatPackets(const ShadeScene& scene, const RayLanes* p, int n,
                          const PacketLight& light, const PacketOut* out) {
  PAIRCAST_CHECK(n >= 0 && n <= kMaxPackets);
#ifdef PAIRCAST_HAVE_AVX2
  if (cpuHasAvx2()) return shadeFlatPacketsAvx2(scene, p, n, light, out);
#endif
  return 0;
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
