// A triangle scene flattened into one mesh: every assimp mesh, with its node transform applied,
// is appended here. Per-vertex attributes are always present (defaults when the file has none),
// so the renderer never branches on their existence.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace paircast {

// An 8-bit sRGB texture; sampled bilinearly with wrap-around, in linear space.
struct Texture {
  std::string name;
  int width = 0;
  int height = 0;
  int channels = 3;             // 3 (RGB) or 4 (RGBA, alpha ignored)
  std::vector<uint8_t> texels;  // [H, W, channels], row 0 is the top of the image (v = 1)

  // Linear RGB at texture coordinates (u, v), glTF/OBJ convention: v = 0 at the bottom.
  Eigen::Vector3f sample(float u, float v) const;
};

struct Material {
  std::string name;
  Eigen::Vector3f baseColor = Eigen::Vector3f::Ones();  // linear RGB factor
  int texture = -1;                                     // index into Mesh::textures, or -1
};

struct Mesh {
  std::vector<Eigen::Vector3f> positions;  // [V] world, metres
  std::vector<Eigen::Vector2f> uvs;        // [V] texture coordinates (0 when absent)
  std::vector<Eigen::Vector3f> colors;     // [V] linear vertex colours (1 when absent)
  std::vector<Eigen::Vector3i> triangles;  // [T] vertex indices
  std::vector<int32_t> triangleMaterial;   // [T] index into materials
  std::vector<Material> materials;
  std::vector<Texture> textures;

  size_t numTriangles() const { return triangles.size(); }
  size_t numVertices() const { return positions.size(); }
  // Appends `other`, offsetting indices and material/texture ids.
  void append(const Mesh& other);
  // Adds a material and returns its index.
  int addMaterial(const Material& m);
  // Adds a triangle with its own three vertices.
  void addTriangle(const Eigen::Vector3f& a, const Eigen::Vector3f& b, const Eigen::Vector3f& c,
                   int material, const Eigen::Vector2f& ta = {0, 0},
                   const Eigen::Vector2f& tb = {0, 0}, const Eigen::Vector2f& tc = {0, 0});
  // Throws paircast::Error (naming `source`) on out-of-range indices or non-finite vertices.
  void validate(const std::string& source) const;
};

// Scene statistics, printed by the tools and tested.
struct MeshStats {
  size_t triangles = 0;
  size_t vertices = 0;
  size_t materials = 0;
  size_t textures = 0;
  Eigen::Vector3f boundsMin = Eigen::Vector3f::Zero();
  Eigen::Vector3f boundsMax = Eigen::Vector3f::Zero();
  std::string summary() const;  // one line
};
MeshStats computeStats(const Mesh& mesh);

// sRGB <-> linear, per channel in [0, 1].
float srgbToLinear(float c);
float linearToSrgb(float c);
// Table of linearToSrgb over [0, 1] in 4096 steps, rounded to 8 bits.
extern const std::array<uint8_t, 4097> kLinearToSrgb8;
inline uint8_t linearToSrgb8(float c) {
  if (!(c > 0.0f)) return 0;
  if (c >= 1.0f) return 255;
  return kLinearToSrgb8[static_cast<int>(c * 4096.0f + 0.5f)];
}
// Table of srgbToLinear over the 256 8-bit values.
extern const std::array<float, 256> kSrgb8ToLinear;

// Linear RGB to 8-bit sRGB packed in 32 bits (R in the low byte, then G and B), and back.
inline uint32_t packSrgb8(const Eigen::Vector3f& linear) {
  return linearToSrgb8(linear.x()) | (uint32_t(linearToSrgb8(linear.y())) << 8) |
         (uint32_t(linearToSrgb8(linear.z())) << 16);
}
inline Eigen::Vector3f unpackSrgb8(uint32_t p) {
  return {kSrgb8ToLinear[p & 255], kSrgb8ToLinear[(p >> 8) & 255], kSrgb8ToLinear[(p >> 16) & 255]};
}

}  // namespace paircast
