// The AVX2 kernels of texture sampling, with their lanes in registers: TexturePyramid::sample8
// stores them, the packet shader (render/packet_shading.cpp) goes on with them. Each does the
// scalar code's operations in the same order (no FMA), so it gives the same results to the bit.
#pragma once

#include "render/texture_pyramid.h"
#include "util/simd.h"

#ifdef PAIRCAST_HAVE_AVX2
namespace paircast::avx2 {

// Row offsets are 16-bit multiplies: levels must be narrower and lower than 2^15 texels.
inline bool fitsTextureKernel(const TexturePyramid& t) {
  return t.width(0) < 32768 && t.height(0) < 32768;
}

// fract in eight lanes: x - floor(x) where |x| < 2e9 (floor is exact there), else 0.
PAIRCAST_AVX2 inline __m256 fract8(__m256 x) {
  const __m256 absolute = _mm256_and_ps(x, _mm256_castsi256_ps(_mm256_set1_epi32(0x7FFFFFFF)));
  const __m256 small = _mm256_cmp_ps(absolute, _mm256_set1_ps(2.0e9f), _CMP_LT_OQ);
  return _mm256_and_ps(_mm256_sub_ps(x, _mm256_floor_ps(x)), small);
}

// TexturePyramid::levelForArea in eight lanes.
PAIRCAST_AVX2 inline __m256i levelForArea(__m256 area) {
  const __m256i exponent = _mm256_sub_epi32(
      _mm256_and_si256(_mm256_srli_epi32(_mm256_castps_si256(area), 23), _mm256_set1_epi32(255)),
      _mm256_set1_epi32(127));
  const __m256i level = _mm256_srai_epi32(_mm256_add_epi32(exponent, _mm256_set1_epi32(1)), 1);
  const __m256 above = _mm256_cmp_ps(area, _mm256_set1_ps(1.0f), _CMP_GT_OQ);  // else 0
  return _mm256_and_si256(level, _mm256_castps_si256(above));
}

// table[level] per lane, for levels 0-15 (fitsTextureKernel) and a table of kTableSize entries:
// two permutes in registers, with no branch on whether the lanes share a level.
PAIRCAST_AVX2 inline __m256i byLevel(const int32_t* table, __m256i level) {
  static_assert(TexturePyramid::kTableSize == 16);
  const __m256i low = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(table));
  const __m256i high = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(table + 8));
  return _mm256_blendv_epi8(_mm256_permutevar8x32_epi32(low, level),
                            _mm256_permutevar8x32_epi32(high, level),
                            _mm256_cmpgt_epi32(level, _mm256_set1_epi32(7)));
}

// Where TexturePyramid::sample reads, in eight lanes, and the weights of what it reads there.
// Apart from the reads (filterTexels) so that the packet shader computes several packets'
// addresses, a long chain each, before it reads any.
struct TexelAddresses {
  __m256i at0, at1;          // each lane's texel on its first and second row (texel index)
  __m256i weight0, weight1;  // (w00, w01) and (w10, w11) as 16-bit pairs
  __m256 finite;             // lanes with finite (u, v)
};

PAIRCAST_AVX2 inline TexelAddresses texelAddresses(const TexturePyramid::Arrays& a, __m256 U,
                                                   __m256 V, __m256i level) {
  TexelAddresses t;
  constexpr float kMaxFloat = 3.40282347e38f;
  const __m256 absMask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7FFFFFFF));
  const __m256 maxFloat = _mm256_set1_ps(kMaxFloat);
  t.finite = _mm256_and_ps(_mm256_cmp_ps(_mm256_and_ps(U, absMask), maxFloat, _CMP_LE_OQ),
                           _mm256_cmp_ps(_mm256_and_ps(V, absMask), maxFloat, _CMP_LE_OQ));
  level =
      _mm256_min_epi32(_mm256_max_epi32(level, _mm256_setzero_si256()), _mm256_set1_epi32(a.top));
  const __m256i w = byLevel(a.width, level), h = byLevel(a.height, level);
  const __m256i offset = byLevel(a.offset, level);
  const __m256 one = _mm256_set1_ps(1.0f), bias = _mm256_set1_ps(8.5f);
  const __m256 w16 = _mm256_cvtepi32_ps(_mm256_slli_epi32(w, 4));
  const __m256 h16 = _mm256_cvtepi32_ps(_mm256_slli_epi32(h, 4));
  const __m256i k16 = _mm256_set1_epi32(16), k15 = _mm256_set1_epi32(15), k1 = _mm256_set1_epi32(1);
  const __m256i fx = _mm256_sub_epi32(
      _mm256_cvttps_epi32(_mm256_add_ps(_mm256_mul_ps(fract8(U), w16), bias)), k16);
  const __m256i fy = _mm256_sub_epi32(
      _mm256_cvttps_epi32(_mm256_add_ps(_mm256_mul_ps(_mm256_sub_ps(one, fract8(V)), h16), bias)),
      k16);
  const __m256i ix = _mm256_srai_epi32(fx, 4), iy = _mm256_srai_epi32(fy, 4);
  const __m256i ax = _mm256_and_si256(fx, k15), ay = _mm256_and_si256(fy, k15);
  const __m256i zero = _mm256_setzero_si256();
  // x0 = ix < 0 ? w - 1 : ix, and its right neighbour is the next texel in memory (rows end with
  // a copy of their first texel); y0 = iy < 0 ? h - 1 : iy, y1 = iy + 1 < h ? iy + 1 : 0.
  const __m256i x0 = _mm256_blendv_epi8(ix, _mm256_sub_epi32(w, k1), _mm256_cmpgt_epi32(zero, ix));
  const __m256i y0 = _mm256_blendv_epi8(iy, _mm256_sub_epi32(h, k1), _mm256_cmpgt_epi32(zero, iy));
  const __m256i y1 =
      _mm256_and_si256(_mm256_add_epi32(iy, k1), _mm256_cmpgt_epi32(h, _mm256_add_epi32(iy, k1)));
  // y * (w + 1) as a multiply-add of 16-bit pairs (y, 0) . (w + 1, 0): half the latency of a
  // 32-bit multiply; levels are narrower than 2^15 (fitsTextureKernel).
  const __m256i stride = _mm256_add_epi32(w, k1);
  t.at0 = _mm256_add_epi32(_mm256_add_epi32(offset, _mm256_madd_epi16(y0, stride)), x0);
  t.at1 = _mm256_add_epi32(_mm256_add_epi32(offset, _mm256_madd_epi16(y1, stride)), x0);
  // The weights as 16-bit pairs, (w00, w01) for row 0 and (w10, w11) for row 1, at most 256 each:
  // one multiply-add of 16-bit pairs then weighs a channel of both texels of a row.
  const __m256i xPair = _mm256_or_si256(_mm256_sub_epi32(k16, ax), _mm256_slli_epi32(ax, 16));
  const __m256i by = _mm256_sub_epi32(k16, ay);
  t.weight0 = _mm256_mullo_epi16(xPair, _mm256_or_si256(by, _mm256_slli_epi32(by, 16)));
  t.weight1 = _mm256_mullo_epi16(xPair, _mm256_or_si256(ay, _mm256_slli_epi32(ay, 16)));
  return t;
}

// The texels at those addresses, filtered bilinearly and decoded to linear RGB (0 where (u, v)
// was not finite).
PAIRCAST_AVX2 inline void filterTexels(const TexturePyramid::Arrays& a, const TexelAddresses& t,
                                       __m256 (&rgb)[3]) {
  // Each lane's two texels of a row as one 64-bit load, four lanes a gather: lanes 0-3, 4-7.
  const auto* pairs = reinterpret_cast<const long long*>(a.texels);
  const __m256i row0[2] = {_mm256_i32gather_epi64(pairs, _mm256_castsi256_si128(t.at0), 4),
                           _mm256_i32gather_epi64(pairs, _mm256_extracti128_si256(t.at0, 1), 4)};
  const __m256i row1[2] = {_mm256_i32gather_epi64(pairs, _mm256_castsi256_si128(t.at1), 4),
                           _mm256_i32gather_epi64(pairs, _mm256_extracti128_si256(t.at1, 1), 4)};
  // Per half (lanes 0-3, 4-7): each lane's weights twice, for its R and G pairs.
  const __m256i twice[2] = {_mm256_setr_epi32(0, 0, 1, 1, 2, 2, 3, 3),
                            _mm256_setr_epi32(4, 4, 5, 5, 6, 6, 7, 7)};
  // Bytes of a pair (R G B x | R' G' B' x') to the 16-bit pairs (R, R') (G, G'), and (B, B') 0.
  const __m256i toRG = _mm256_setr_epi8(0, -1, 4, -1, 1, -1, 5, -1, 8, -1, 12, -1, 9, -1, 13, -1, 0,
                                        -1, 4, -1, 1, -1, 5, -1, 8, -1, 12, -1, 9, -1, 13, -1);
  const __m256i toB =
      _mm256_setr_epi8(2, -1, 6, -1, -1, -1, -1, -1, 10, -1, 14, -1, -1, -1, -1, -1, 2, -1, 6, -1,
                       -1, -1, -1, -1, 10, -1, 14, -1, -1, -1, -1, -1);
  __m256i rg[2], b[2];  // rg: R G of lanes 0, 1 | 2, 3 (or 4-7); b: B 0 of the same
  for (int part = 0; part < 2; ++part) {
    const __m256i w0 = _mm256_permutevar8x32_epi32(t.weight0, twice[part]);
    const __m256i w1 = _mm256_permutevar8x32_epi32(t.weight1, twice[part]);
    rg[part] = _mm256_add_epi32(_mm256_madd_epi16(_mm256_shuffle_epi8(row0[part], toRG), w0),
                                _mm256_madd_epi16(_mm256_shuffle_epi8(row1[part], toRG), w1));
    b[part] = _mm256_add_epi32(_mm256_madd_epi16(_mm256_shuffle_epi8(row0[part], toB), w0),
                               _mm256_madd_epi16(_mm256_shuffle_epi8(row1[part], toB), w1));
  }
  // Decode (255 * 256 >> 4 at most), then back to one vector per channel.
  const float* table = a.decode;
  const __m256 lowRG = _mm256_i32gather_ps(table, _mm256_srli_epi32(rg[0], 4), 4);
  const __m256 highRG = _mm256_i32gather_ps(table, _mm256_srli_epi32(rg[1], 4), 4);
  const __m256i bb = _mm256_or_si256(b[0], _mm256_slli_epi64(b[1], 32));  // B0 B4 B1 B5 ...
  const __m256 blue = _mm256_i32gather_ps(table, _mm256_srli_epi32(bb, 4), 4);
  const __m256i unzip = _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7);
  const __m256 low = _mm256_permutevar8x32_ps(lowRG, unzip);    // R0-3 G0-3
  const __m256 high = _mm256_permutevar8x32_ps(highRG, unzip);  // R4-7 G4-7
  rgb[0] = _mm256_and_ps(_mm256_permute2f128_ps(low, high, 0x20), t.finite);
  rgb[1] = _mm256_and_ps(_mm256_permute2f128_ps(low, high, 0x31), t.finite);
  rgb[2] = _mm256_and_ps(_mm256_permutevar8x32_ps(blue, unzip), t.finite);
}

// TexturePyramid::sample in eight lanes: linear RGB at (u, v) on `level`. Texel pairs and the
// decode are gathers.
PAIRCAST_AVX2 inline void sampleTexture(const TexturePyramid::Arrays& a, __m256 U, __m256 V,
                                        __m256i level, __m256 (&rgb)[3]) {
  filterTexels(a, texelAddresses(a, U, V, level), rgb);
}

// The same, from and to memory, for the lanes whose bit is set in `lanes`.
PAIRCAST_AVX2 inline void sampleTexture(const TexturePyramid::Arrays& a, const float* u,
                                        const float* v, const int32_t* level, uint32_t lanes,
                                        float (*rgb)[8]) {
  __m256 c[3];
  sampleTexture(a, _mm256_loadu_ps(u), _mm256_loadu_ps(v),
                _mm256_loadu_si256(reinterpret_cast<const __m256i*>(level)), c);
  const __m256i store = laneMask(lanes);
  for (int k = 0; k < 3; ++k) {
    // A masked store is not forwarded to a later load: a full one is.
    if (lanes == 255)
      _mm256_storeu_ps(rgb[k], c[k]);
    else
      _mm256_maskstore_ps(rgb[k], store, c[k]);
  }
}

}  // namespace paircast::avx2
#endif
