#include "render/mesh.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <sstream>

#include "util/error.h"

namespace paircast {
float srgbToLinear(float c) {
  return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
}

float linearToSrgb(float c) {
  c = std::clamp(c, 0.0f, 1.0f);
  return c <= 0.0031308f ? 12.92f * c : 1.055f * std::pow(c, 1.0f / 2.4f) - 0.055f;
}

const std::array<float, 256> kSrgb8ToLinear = [] {
  std::array<float, 256> t{};
  for (int i = 0; i < 256; ++i) t[i] = srgbToLinear(i / 255.0f);
  return t;
}();

const std::array<uint8_t, 4097> kLinearToSrgb8 = [] {
  std::array<uint8_t, 4097> t{};
  for (int i = 0; i <= 4096; ++i)
    t[i] = static_cast<uint8_t>(std::lround(255.0f * linearToSrgb(i / 4096.0f)));
  return t;
}();

Eigen::Vector3f Texture::sample(float u, float v) const {
  const auto& lut = kSrgb8ToLinear;
  if (!std::isfinite(u) || !std::isfinite(v)) return Eigen::Vector3f::Zero();
  // Wrap to [0, 1) first, so that the texel indices below need no modulo. Texel centres are at
  // (i + 0.5) / W; image row 0 is v = 1.
  u -= std::floor(u);
  v -= std::floor(v);
  const float x = u * width - 0.5f, y = (1.0f - v) * height - 0.5f;
  const float fx = std::floor(x), fy = std::floor(y);
  const float ax = x - fx, ay = y - fy;
  int x0 = static_cast<int>(fx), y0 = static_cast<int>(fy);
  int x1 = x0 + 1, y1 = y0 + 1;
  if (x0 < 0) x0 += width;
  if (y0 < 0) y0 += height;
  if (x1 >= width) x1 -= width;
  if (y1 >= height) y1 -= height;
  const uint8_t* r0 = texels.data() + static_cast<size_t>(y0) * width * channels;
  const uint8_t* r1 = texels.data() + static_cast<size_t>(y1) * width * channels;
  const uint8_t* p00 = r0 + x0 * channels;
  const uint8_t* p10 = r0 + x1 * channels;
  const uint8_t* p01 = r1 + x0 * channels;
  const uint8_t* p11 = r1 + x1 * channels;
  const float w00 = (1 - ax) * (1 - ay), w10 = ax * (1 - ay), w01 = (1 - ax) * ay, w11 = ax * ay;
  Eigen::Vector3f out;
  for (int c = 0; c < 3; ++c)
    out[c] = w00 * lut[p00[c]] + w10 * lut[p10[c]] + w01 * lut[p01[c]] + w11 * lut[p11[c]];
  return out;
}

void Mesh::append(const Mesh& other) {
  const int vOffset = static_cast<int>(positions.size());
  const int mOffset = static_cast<int>(materials.size());
  const int tOffset = static_cast<int>(textures.size());
  positions.insert(positions.end(), other.positions.begin(), other.positions.end());
  uvs.insert(uvs.end(), other.uvs.begin(), other.uvs.end());
  colors.insert(colors.end(), other.colors.begin(), other.colors.end());
  for (const auto& t : other.triangles) triangles.push_back(t.array() + vOffset);
  for (int m : other.triangleMaterial) triangleMaterial.push_back(m + mOffset);
  for (Material m : other.materials) {
    if (m.texture >= 0) m.texture += tOffset;
    materials.push_back(m);
  }
  textures.insert(textures.end(), other.textures.begin(), other.textures.end());
}

int Mesh::addMaterial(const Material& m) {
  materials.push_back(m);
  return static_cast<int>(materials.size()) - 1;
}

void Mesh::addTriangle(const Eigen::Vector3f& a, const Eigen::Vector3f& b, const Eigen::Vector3f& c,
                       int material, const Eigen::Vector2f& ta, const Eigen::Vector2f& tb,
                       const Eigen::Vector2f& tc) {
  const int base = static_cast<int>(positions.size());
  positions.insert(positions.end(), {a, b, c});
  uvs.insert(uvs.end(), {ta, tb, tc});
  colors.insert(colors.end(), 3, Eigen::Vector3f::Ones());
  triangles.emplace_back(base, base + 1, base + 2);
  triangleMaterial.push_back(material);
}

void Mesh::validate(const std::string& source) const {
  const size_t V = positions.size();
  if (uvs.size() != V || colors.size() != V)
    throw Error(source, "vertex attribute arrays have different lengths");
  if (triangleMaterial.size() != triangles.size())
    throw Error(source, "triangle material array has the wrong length");
  for (size_t i = 0; i < V; ++i) {
    if (!positions[i].allFinite())
      throw Error(source, "vertex " + std::to_string(i) + " is not finite (NaN or inf)");
  }
  for (size_t t = 0; t < triangles.size(); ++t) {
    for (int k = 0; k < 3; ++k) {
      if (triangles[t][k] < 0 || static_cast<size_t>(triangles[t][k]) >= V)
        throw Error(source, "triangle " + std::to_string(t) + " has an out-of-range index");
    }
    if (triangleMaterial[t] < 0 || static_cast<size_t>(triangleMaterial[t]) >= materials.size())
      throw Error(source, "triangle " + std::to_string(t) + " has an out-of-range material");
  }
  for (const auto& m : materials) {
    if (m.texture >= static_cast<int>(textures.size()))
      throw Error(source, "material '" + m.name + "' names a missing texture");
  }
  for (const auto& t : textures) {
    if (t.width <= 0 || t.height <= 0 || (t.channels != 3 && t.channels != 4) ||
        t.texels.size() != static_cast<size_t>(t.width) * t.height * t.channels)
      throw Error(source, "texture '" + t.name + "' is malformed");
  }
}

MeshStats computeStats(const Mesh& mesh) {
  MeshStats s;
  s.triangles = mesh.numTriangles();
  s.vertices = mesh.numVertices();
  s.materials = mesh.materials.size();
  s.textures = mesh.textures.size();
  if (!mesh.positions.empty()) {
    s.boundsMin = s.boundsMax = mesh.positions[0];
    for (const auto& p : mesh.positions) {
      s.boundsMin = s.boundsMin.cwiseMin(p);
      s.boundsMax = s.boundsMax.cwiseMax(p);
    }
  }
  return s;
}

std::string MeshStats::summary() const {
  std::ostringstream os;
  os << triangles << " triangles, " << vertices << " vertices, " << materials << " materials, "
     << textures << " textures, bounds [" << boundsMin.x() << ", " << boundsMin.y() << ", "
     << boundsMin.z() << "] .. [" << boundsMax.x() << ", " << boundsMax.y() << ", " << boundsMax.z()
     << "]";
  return os.str();
}

}  // namespace paircast
