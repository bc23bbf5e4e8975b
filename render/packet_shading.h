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
  alignas(32) int32_t level[kLanes];         // texture pyramid level (lightLanes)
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

// What shading reads of the renderer's scene.
struct ShadeScene {
  const ShadeTriangle* triangles;  // by primitive id
  const TexturePyramid* textures;  // by ShadeTriangle::texture
};

// A packet of eight rays as cast: which hit, what, and where.
struct RayLanes {
  const uint32_t* geomID;           // each ray's geometry id: all ones on a miss
  const uint32_t* prim;             // each ray's primitive id
  const float *dirX, *dirY, *dirZ;  // the rays' directions
  const float* t;                   // their hit distances (z-depths)
  const float *u, *v;               // the hits' barycentrics
};

using LaneColours = float[3][kLanes];

// Where a packet's colours go: linear (rgb[c][i]), or, when `srgb` is set, as the 8-bit sRGB
// pixels of srgbLanes with scale 1 (the first `count`).
struct PacketOut {
  LaneColours* linear;
  uint8_t* srgb;
  int count;
};

// The colours of n <= kMaxPackets packets whose rays hit kFlat triangles (or nothing), as the
// passes below (lightLanes, the texture, combineLanes) give them, in SIMD lanes, stage by stage
// over all the packets (light, texel addresses, texel reads and colours, sRGB) so that the
// packets' long chains of dependent operations overlap. Returns bit k set for each packet done;
// the others (a triangle that is not kFlat, no SIMD kernel) are left to the passes, their output
// untouched.
constexpr int kMaxPackets = 8;
uint32_t shadeFlatPackets(const ShadeScene& scene, const RayLanes* p, int n,
                          const PacketLight& light, const PacketOut* out);

// Each lane's light factor: ambient + headlight * cos(view) + sun * max(0, cos(sun)), the normal
// turned towards the camera; and its texture level: the sample covers (z s)^2 / cos m^2 of the
// surface (z the z-depth, here `t` with the renderer's unnormalised directions), and the level
// matches its texel count by area (TexturePyramid::levelForArea). `dir` are the rays' directions.
void lightLanes(const float* dirX, const float* dirY, const float* dirZ, const float* t,
                const PacketLight& light, PacketShading& s);

// rgb[c][i] = albedo * texel * light on the lanes that hit, the background on the others.
void combineLanes(const PacketShading& s, const PacketLight& light, float (&rgb)[3][kLanes]);

// Pixel i < count of rgb * scale as 8-bit sRGB (linearToSrgb8): out[3 i + c].
void srgbLanes(const float (&rgb)[3][kLanes], float scale, int count, uint8_t* out);

}  // namespace paircast
