// glTF as the habitat datasets ship it: Basis Universal textures (HM3D's .basis.glb), meshopt
// and Draco compression. The files are built in code: a 4 x 4 m floor quad, z up.
#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>

#include "render/scene_loader.h"
#include "test_errors.h"
#include "test_paths.h"
#include "util/error.h"

#ifdef PAIRCAST_HAVE_DRACO
#include <draco/compression/encode.h>
#include <draco/mesh/triangle_soup_mesh_builder.h>
#endif

namespace paircast {
namespace {

using nlohmann::json;

void pad(std::string& s, char with) {
  while (s.size() % 4) s += with;
}

void appendU32(std::string& s, uint32_t v) {
  s.append(reinterpret_cast<const char*>(&v), 4);
}

// A binary glTF: header, JSON chunk, BIN chunk (when `bin` is not empty).
std::string glbBytes(const json& j, std::string bin) {
  std::string text = j.dump();
  pad(text, ' ');
  pad(bin, '\0');
  std::string out = "glTF";
  appendU32(out, 2);
  appendU32(out, static_cast<uint32_t>(12 + 8 + text.size() + (bin.empty() ? 0 : 8 + bin.size())));
  appendU32(out, static_cast<uint32_t>(text.size()));
  out += "JSON" + text;
  if (!bin.empty()) {
    appendU32(out, static_cast<uint32_t>(bin.size()));
    out += std::string("BIN\0", 4) + bin;
  }
  return out;
}

std::string writeGlb(const std::string& name, const json& j, const std::string& bin) {
  const std::string path = testing::scratchDir("gltf") + "/" + name + ".glb";
  std::ofstream(path, std::ios::binary) << glbBytes(j, bin);
  return path;
}

// The floor quad: buffer bytes (4 float3 positions, 6 uint16 indices, then `extra`) and the
// glTF JSON that reads them, with a base colour factor.
std::pair<json, std::string> floorQuad(const std::string& extra = "") {
  const float positions[12] = {0, 0, 0, 4, 0, 0, 4, 4, 0, 0, 4, 0};
  const uint16_t indices[6] = {0, 1, 2, 0, 2, 3};
  std::string bin(reinterpret_cast<const char*>(positions), sizeof positions);
  bin.append(reinterpret_cast<const char*>(indices), sizeof indices);
  bin += extra;
  pad(bin, '\0');
  json j = {
      {"asset", {{"version", "2.0"}}},
      {"scene", 0},
      {"scenes", {{{"nodes", {0}}}}},
      {"nodes", {{{"mesh", 0}}}},
      {"meshes",
       {{{"primitives", {{{"attributes", {{"POSITION", 0}}}, {"indices", 1}, {"material", 0}}}}}}},
      {"materials", {{{"pbrMetallicRoughness", {{"baseColorFactor", {0.2, 0.4, 0.6, 1.0}}}}}}},
      {"buffers", {{{"byteLength", bin.size()}}}},
      {"bufferViews",
       {{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", 48}},
        {{"buffer", 0}, {"byteOffset", 48}, {"byteLength", 12}}}},
      {"accessors",
       {{{"bufferView", 0},
         {"componentType", 5126},
         {"count", 4},
         {"type", "VEC3"},
         {"min", {0, 0, 0}},
         {"max", {4, 4, 0}}},
        {{"bufferView", 1}, {"componentType", 5123}, {"count", 6}, {"type", "SCALAR"}}}}};
  return {j, bin};
}

// Habitat's glbs (HM3D, MP3D, Gibson) are z-up whatever glTF's spec says: positions are never
// rotated, so a floor in the xy plane stays there, and --up z (or auto) finds it.
TEST(Gltf, ZUpFloorStaysInTheXyPlane) {
  auto [j, bin] = floorQuad();
  LoadOptions o;
  o.up = UpAxis::Auto;
  const Scene scene = loadScene(writeGlb("plain", j, bin), o);
  EXPECT_EQ(scene.mesh.numTriangles(), 2u);
  EXPECT_TRUE(scene.warnings.empty());
  EXPECT_EQ(scene.up, UpAxis::Z);
  const MeshStats stats = computeStats(scene.mesh);
  EXPECT_EQ(stats.boundsMin, Eigen::Vector3f(0, 0, 0));
  EXPECT_EQ(stats.boundsMax, Eigen::Vector3f(4, 4, 0));
}

TEST(Gltf, BasisTexturesLoadWithOneWarningAndTheBaseColours) {
  for (const std::string ext : {"GOOGLE_texture_basis", "KHR_texture_basisu"}) {
    // A texture whose only image is Basis Universal (.basis or KTX2 bytes), as in HM3D.
    const std::string image = "sB\x13\x4d not a real basis file";
    auto [j, bin] = floorQuad(image);
    j["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", 60}, {"byteLength", image.size()}});
    j["images"] = {{{"bufferView", 2},
                    {"mimeType", ext == "KHR_texture_basisu" ? "image/ktx2" : "image/basis"}}};
    j["textures"] = {{{"extensions", {{ext, {{"source", 0}}}}}}};
    j["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {{"index", 0}};
    j["extensionsUsed"] = {ext};
    j["extensionsRequired"] = {ext};
    const std::string path = writeGlb(ext, j, bin);
    const Scene scene = loadScene(path);
    ASSERT_EQ(scene.warnings.size(), 1u) << ext;
    const std::string& w = scene.warnings[0];
    EXPECT_NE(w.find(path), std::string::npos) << w;
    EXPECT_NE(w.find(ext), std::string::npos) << w;
    EXPECT_NE(w.find("plain .glb with JPEG textures"), std::string::npos) << w;
    EXPECT_EQ(scene.mesh.numTriangles(), 2u);
    EXPECT_TRUE(scene.mesh.textures.empty());
    for (int t = 0; t < 2; ++t) {
      const Material& m = scene.mesh.materials[scene.mesh.triangleMaterial[t]];
      EXPECT_EQ(m.texture, -1);
      EXPECT_NEAR(m.baseColor.x(), 0.2f, 1e-6f);
      EXPECT_NEAR(m.baseColor.z(), 0.6f, 1e-6f);
    }
  }
}

TEST(Gltf, MeshoptCompressionIsRefusedNotRenderedGarbled) {
  auto [j, bin] = floorQuad();
  j["bufferViews"][0]["extensions"] = {{"EXT_meshopt_compression",
                                        {{"buffer", 0},
                                         {"byteLength", 48},
                                         {"byteStride", 12},
                                         {"count", 4},
                                         {"mode", "ATTRIBUTES"}}}};
  j["extensionsUsed"] = {"EXT_meshopt_compression"};
  const std::string path = writeGlb("meshopt", j, bin);
  const std::string why = testing::refusalOf(path, [&] { loadScene(path); });
  EXPECT_NE(why.find(path), std::string::npos) << why;
  EXPECT_NE(why.find("EXT_meshopt_compression"), std::string::npos) << why;
  EXPECT_EQ(why.find('\n'), std::string::npos) << why;
}

#ifdef PAIRCAST_HAVE_DRACO
// Debian's assimp links libdraco: a KHR_draco_mesh_compression primitive with 16-bit indices
// decodes to the mesh.
TEST(Gltf, DracoCompressedMeshDecodes) {
  // A 10 x 10 grid of quads over 4 x 4 m, 200 triangles, as a Draco triangle soup.
  draco::TriangleSoupMeshBuilder builder;
  const int n = 10;
  builder.Start(2 * n * n);
  const int position =
      builder.AddAttribute(draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32);
  int face = 0;
  auto p = [&](int i, int j) { return std::array<float, 3>{0.4f * i, 0.4f * j, 0.0f}; };
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      const auto a = p(i, j), b = p(i + 1, j), c = p(i + 1, j + 1), d = p(i, j + 1);
      builder.SetAttributeValuesForFace(position, draco::FaceIndex(face++), a.data(), b.data(),
                                        c.data());
      builder.SetAttributeValuesForFace(position, draco::FaceIndex(face++), a.data(), c.data(),
                                        d.data());
    }
  }
  std::unique_ptr<draco::Mesh> mesh = builder.Finalize();
  ASSERT_TRUE(mesh);
  draco::Encoder encoder;
  encoder.SetAttributeQuantization(draco::GeometryAttribute::POSITION, 14);
  draco::EncoderBuffer buffer;
  ASSERT_TRUE(encoder.EncodeMeshToBuffer(*mesh, &buffer).ok());
  const std::string bin(buffer.data(), buffer.size());
  json j = {
      {"asset", {{"version", "2.0"}}},
      {"scene", 0},
      {"scenes", {{{"nodes", {0}}}}},
      {"nodes", {{{"mesh", 0}}}},
      {"meshes",
       {{{"primitives",
          {{{"attributes", {{"POSITION", 0}}},
            {"indices", 1},
            {"extensions",
             {{"KHR_draco_mesh_compression",
               {{"bufferView", 0},
                {"attributes", {{"POSITION", mesh->attribute(position)->unique_id()}}}}}}}}}}}}},
      {"buffers", {{{"byteLength", (bin.size() + 3) / 4 * 4}}}},
      {"bufferViews", {{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", bin.size()}}}},
      {"accessors",
       {{{"componentType", 5126},
         {"count", mesh->num_points()},
         {"type", "VEC3"},
         {"min", {0, 0, 0}},
         {"max", {4, 4, 0}}},
        {{"componentType", 5123}, {"count", 3 * mesh->num_faces()}, {"type", "SCALAR"}}}},
      {"extensionsUsed", {"KHR_draco_mesh_compression"}},
      {"extensionsRequired", {"KHR_draco_mesh_compression"}}};
  const Scene scene = loadScene(writeGlb("draco", j, bin));
  ASSERT_EQ(scene.mesh.numTriangles(), 200u);
  double area = 0;
  for (const auto& t : scene.mesh.triangles) {
    const auto& P = scene.mesh.positions;
    area += 0.5 * (P[t[1]] - P[t[0]]).cross(P[t[2]] - P[t[0]]).norm();
    for (int k = 0; k < 3; ++k) {
      EXPECT_GE(P[t[k]].x(), -1e-3f);
      EXPECT_LE(P[t[k]].x(), 4.001f);
      EXPECT_NEAR(P[t[k]].z(), 0.0f, 1e-3f);
    }
  }
  EXPECT_NEAR(area, 16.0, 0.05);
  // With 32-bit indices, assimp 5.2.5 drops them after decoding: refused with the reason.
  j["accessors"][1]["componentType"] = 5125;
  const std::string path = writeGlb("draco32", j, bin);
  const std::string why = testing::refusalOf(path, [&] { loadScene(path); });
  EXPECT_NE(why.find("32-bit indices"), std::string::npos) << why;
}
#endif

}  // namespace
}  // namespace paircast
