// Shading eight rays at once. The renderer casts rows of eight rays (one rtcIntersect8 packet);
// shading them lane by lane, in structure-of-arrays form, lets the arithmetic run in SIMD lanes
// (AVX2 where the CPU has it, see util/simd.h) instead of one hit at a time.
#pragma once

#include <Eigen/Core>
#include <cstdint>

namespace paircast {

class TexturePyramid;
constexpr int kLanes = 8;

// What shading one hit needs of its triangle, in one cache line: a hit costs one load here
// instead of five scattered ones (normal, material, vertex indices, three texture coordinates).
struct alignas(64) ShadeTriangle {
  enum Colour : int32_t {
    kFlat,       // albedo below
    kPerVertex,  // corner colours below, interpolated (untextured triangles)
    kFromMesh,   // albedo below times the mesh's vertex colours (textured triangles with them)
  };
  Eigen::Vector3f normal;  // unit geometric normal (sign fixed per hit)
  int32_t texture;         // index into the renderer's textures, or -1
  Colour colour;
  struct Surface {
    float albedo[3];                 // material factor x vertex colour (when uniform), linear
    float uv0[2], duv1[2], duv2[2];  // texture coordinates: uv0 + u duv1 + v duv2
    float texelsPerMetre;  // of the texture's level 0 over this triangle (mean of both axes)
  };
  struct Corners {
    float rgb[3][3];  // material factor x each vertex's colour, linear
  };
  union {
    Surface surface;  // kFlat, kFromMesh
    Corners corners;  // kPerVertex
  };
};

// A packet's shading inputs and intermediate values, lane by lane.
struct PacketShading {
  alignas(32) float n[3][kLanes];            // unit geometric normal, either sign
  alignas(32) float albedo[3][kLanes];       // linear: material and vertex colours, not the texture
  alignas(32) float u[kLanes], v[kLanes];    // texture coordinates (textured lanes)
  alignas(32) float texelsPerMetre[kLanes];  // of the texture's level 0; 0 untextured
  alignas(32) float lod[kLanes];             // texture level of detail (lightLanes)
  alignas(32) float light[kLanes];           // ambient + headlight + sun factor (lightLanes)
  alignas(32) float texel[3][kLanes];        // linear texture colour (textured lanes only)
  alignas(32) int32_t texture[kLanes];       // texture index, -1 for none and on misses
  uint32_t hits = 0;                         // bit i: ray i hit
};

// What lighting needs, fixed for one render.
struct PacketLight {
  float ambient, headlight, sun;  // as ShadingOptions
  float sunDir[3];                // unit, towards the sun
  float sampleSize;               // width of one colour sample at z-depth 1: 1 / (fx * supersample)
  float background[3];            // linear colour of a miss
};

// A packet whose rays all hit one kFlat triangle: the common case on scenes of large triangles.
struct FlatPacket {
  const ShadeTriangle* triangle;
  const TexturePyramid* texture;    // the triangle's texture, or null
  const float *dirX, *dirY, *dirZ;  // the rays' directions
  const float* t;                   // their hit distances (z-depths)
  const float *u, *v;               // the hits' barycentrics
};

// (*rgb[k])[c][i] of n <= kMaxFlatPackets such packets, as the passes below (lightLanes, the
// texture, combineLanes) give them, in one SIMD pass with the lanes in registers. False (and rgb
// untouched) where there is no SIMD kernel: then the passes do it.
constexpr int kMaxFlatPackets = 8;
using LaneColours = float[3][kLanes];
bool shadeFlatPackets(const FlatPacket* p, int n, const PacketLight& light,
                      LaneColours* const* rgb);

// A packet whose rays hit kFlat triangles, several of them, or nothing.
struct FlatLanes {
  const ShadeTriangle* triangles;   // the renderer's records, by primitive id
  const TexturePyramid* textures;   // the renderer's textures, by ShadeTriangle::texture
  const uint32_t* prim;             // each ray's primitive id
  uint32_t hits;                    // bit i: ray i hit
  const float *dirX, *dirY, *dirZ;  // the rays' directions
  const float* t;                   // their hit distances (z-depths)
  const float *u, *v;               // the hits' barycentrics
};

// rgb[c][i] of such a packet in SIMD lanes, the records transposed from memory; the background
// on the lanes that missed. False (and rgb untouched) where it has no SIMD kernel or a lane hit a
// triangle that is not kFlat: then the passes below do it.
bool shadeFlatLanes(const FlatLanes& p, const PacketLight& light, float (&rgb)[3][kLanes]);

// Each lane's light factor: ambient + headlight * cos(view) + sun * max(0, cos(sun)), the normal
// turned towards the camera; and its texture level of detail: the sample covers (z s)^2 / cos
// m^2 of the surface (z the z-depth, here `t` with the renderer's unnormalised directions), and
// the level matches its texel count by area. `dir` are the rays' directions.
void lightLanes(const float* dirX, const float* dirY, const float* dirZ, const float* t,
                const PacketLight& light, PacketShading& s);

// rgb[c][i] = albedo * texel * light on the lanes that hit, the background on the others.
void combineLanes(const PacketShading& s, const PacketLight& light, float (&rgb)[3][kLanes]);

// Pixel i < count of rgb * scale as 8-bit sRGB (linearToSrgb8): out[3 i + c].
void srgbLanes(const float (&rgb)[3][kLanes], float scale, int count, uint8_t* out);

}  // namespace paircast
