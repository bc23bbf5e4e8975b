// Scene files from untrusted sources: counts and sizes a file claims are checked against the file
// and the LoadOptions limits before assimp allocates, and the files a scene names are opened only
// when they are regular files within the limits. Every refusal is a one-line paircast::Error
// naming the file. (docs/reliability.md, "Untrusted files", lists the threats.)
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <array>
#include <chrono>
#include <fstream>
#include <limits>

#include <nlohmann/json.hpp>

#include "util/camera.h"
#include "render/scene_loader.h"
#include "test_errors.h"
#include "test_paths.h"
#include "util/error.h"

namespace paircast {
namespace {

std::string refusal(const std::string& path, const LoadOptions& o = {}) {
  return testing::refusalOf(path, [&] { loadScene(path, o); });
}

std::string plyHeader(const std::string& format, const std::string& vertices,
                      const std::string& faces) {
  return "ply\nformat " + format + " 1.0\nelement vertex " + vertices +
         "\nproperty float x\nproperty float y\nproperty float z\nelement face " + faces +
         "\nproperty list uchar int vertex_indices\nend_header\n";
}

TEST(UntrustedScene, PlyClaimingBillionsOfVerticesIsRefusedBeforeAllocation) {
  const std::string dir = testing::scratchDir("ply");
  const auto start = std::chrono::steady_clock::now();
  // Over the vertex limit (150M by default), whatever the file holds.
  std::ofstream(dir + "/billions.ply")
      << plyHeader("ascii", "4000000000", "1") << "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  std::string why = refusal(dir + "/billions.ply");
  EXPECT_NE(why.find("4000000000"), std::string::npos) << why;
  // Under the limit, but more than the bytes after the header can hold: assimp would zero
  // 100M vertices (1.2 GB) before noticing.
  std::ofstream(dir + "/hollow.ply", std::ios::binary)
      << plyHeader("binary_little_endian", "100000000", "1") << std::string(64, '\0');
  why = refusal(dir + "/hollow.ply");
  EXPECT_NE(why.find("claims 100000000 'vertex' elements"), std::string::npos) << why;
  EXPECT_NE(why.find("at most 5"), std::string::npos) << why;  // 64 bytes / 12 per vertex
  std::ofstream(dir + "/faces.ply")
      << plyHeader("ascii", "3", "99999999999999999999999") << "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  why = refusal(dir + "/faces.ply");
  EXPECT_NE(why.find("'face' elements"), std::string::npos) << why;
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(5));
}

TEST(UntrustedScene, PlyHeaderLinesMustBeExactlyTheFormatsKeywords) {
  // assimp reads a name that starts with digits as the count: "element 5555555555face 3"
  // made it allocate 30 GB (fuzz_scene_ply found it). Every header line is checked whole.
  const std::string dir = testing::scratchDir("plylines");
  const std::string body = "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  struct Case {
    std::string from, to, why;
  } cases[] = {
      {"element face 1", "element 5555555555face 1", "'5555555555face' is not a name"},
      {"element face 1", "element face 1 2", "expected 'element <name> <count>'"},
      {"property float z", "property float z uchar blue", "expected 'property <type> <name>'"},
      {"property list uchar int vertex_indices", "property list uchar int",
       "expected 'property list"},
      {"format ascii 1.0", "format ascii 1 .0", "expected 'format <type> 1.0'"},
  };
  const std::string good = plyHeader("ascii", "3", "1");
  std::ofstream(dir + "/good.ply") << good << body;
  EXPECT_NO_THROW(loadScene(dir + "/good.ply"));
  int k = 0;
  for (const Case& c : cases) {
    std::string header = good;
    ASSERT_NE(header.find(c.from), std::string::npos) << c.from;
    header.replace(header.find(c.from), c.from.size(), c.to);
    const std::string path = dir + "/case" + std::to_string(k++) + ".ply";
    std::ofstream(path) << header << body;
    const std::string why = refusal(path);
    EXPECT_NE(why.find(c.why), std::string::npos) << c.to << ": " << why;
  }
}

TEST(UntrustedScene, GltfImageMediaTypesMustBeTypeSlashSubtype) {
  // assimp 5.2.5 reads address 1 for an embedded image whose mimeType has no '/'
  // (fuzz_scene_glb found it); the glTF JSON is checked before assimp sees it.
  const std::string dir = testing::scratchDir("gltfmime");
  auto gltf = [&](const std::string& name, const std::string& image) {
    const std::string path = dir + "/" + name + ".gltf";
    std::ofstream(path) << R"({"asset":{"version":"2.0"},"images":[)" << image << "]}";
    return path;
  };
  std::string path = gltf("mime", R"({"bufferView":0,"mimeType":"imagepng"})");
  EXPECT_NE(refusal(path).find("glTF image 0 has media type 'imagepng', not type/subtype"),
            std::string::npos);
  path = gltf("uri", R"({"uri":"data:png;base64,AAAA"})");
  EXPECT_NE(refusal(path).find("media type 'png'"), std::string::npos);
  path = gltf("utf8", "{\"mimeType\":\"image/\xff\"}");
  EXPECT_NE(refusal(path).find("not a valid JSON object"), std::string::npos);
  // The same check runs on a GLB's JSON chunk.
  const std::string json = R"({"asset":{"version":"2.0"},"images":[{"mimeType":"x"}]}    )";
  std::string glb = std::string("glTF\x02\0\0\0", 8);
  const uint32_t total = 12 + 8 + static_cast<uint32_t>(json.size());
  const uint32_t chunk = static_cast<uint32_t>(json.size());
  glb.append(reinterpret_cast<const char*>(&total), 4);
  glb.append(reinterpret_cast<const char*>(&chunk), 4);
  glb += "JSON" + json;
  std::ofstream(dir + "/mime.glb", std::ios::binary) << glb;
  EXPECT_NE(refusal(dir + "/mime.glb").find("media type 'x'"), std::string::npos);
}

TEST(UntrustedScene, ConfiguredLimitsAreEnforced) {
  const std::string dir = testing::scratchDir("limits");
  const std::string ply =
      plyHeader("ascii", "4", "2") + "0 0 0\n1 0 0\n1 1 0\n0 1 0\n" + "3 0 1 2\n3 0 2 3\n";
  std::ofstream(dir + "/quad.ply") << ply;
  EXPECT_NO_THROW(loadScene(dir + "/quad.ply"));
  LoadOptions fewFaces;
  fewFaces.maxTriangles = 1;
  EXPECT_NE(refusal(dir + "/quad.ply", fewFaces).find("more than the limit of 1"),
            std::string::npos);
  LoadOptions fewVertices;
  fewVertices.maxVertices = 3;
  EXPECT_NE(refusal(dir + "/quad.ply", fewVertices).find("vertices, more than the limit of 3"),
            std::string::npos);
  // OBJ states no counts: the file size bounds what assimp builds.
  std::ofstream obj(dir + "/big.obj");
  for (int i = 0; i < 2000; ++i) obj << "v " << i << " " << i % 7 << " 0\n";
  for (int i = 1; i + 2 <= 2000; ++i) obj << "f " << i << " " << i + 1 << " " << i + 2 << "\n";
  obj.close();
  LoadOptions smallFiles;
  smallFiles.maxFileBytes = 4096;
  EXPECT_NE(refusal(dir + "/big.obj", smallFiles).find("larger than the limit"), std::string::npos);
  LoadOptions fewObjVertices;
  fewObjVertices.maxVertices = 100;
  EXPECT_NE(refusal(dir + "/big.obj", fewObjVertices).find("more than the limit of 100"),
            std::string::npos);
}

// A binary little-endian PLY as ScanNet writes it (float x y z, uchar RGBA, uchar-counted int
// index lists), from raw vertices and faces; `header` overrides the element counts.
std::string scannetPly(const std::vector<std::array<float, 3>>& vertices,
                       const std::vector<std::vector<int32_t>>& faces,
                       const std::string& vertexCount = "", const std::string& faceCount = "") {
  std::string out = "ply\nformat binary_little_endian 1.0\nelement vertex " +
                    (vertexCount.empty() ? std::to_string(vertices.size()) : vertexCount) +
                    "\nproperty float x\nproperty float y\nproperty float z\n"
                    "property uchar red\nproperty uchar green\nproperty uchar blue\n"
                    "property uchar alpha\nelement face " +
                    (faceCount.empty() ? std::to_string(faces.size()) : faceCount) +
                    "\nproperty list uchar int vertex_indices\nend_header\n";
  for (const auto& v : vertices) {
    out.append(reinterpret_cast<const char*>(v.data()), 12);
    out += std::string("\x80\x80\x80\xff", 4);
  }
  for (const auto& f : faces) {
    out += static_cast<char>(f.size());
    out.append(reinterpret_cast<const char*>(f.data()), 4 * f.size());
  }
  return out;
}

// Both PLY readers (our binary one and assimp's, for ASCII and binary files) refuse the same bad
// files, each with one line naming the file; none allocates what the header claims.
TEST(UntrustedScene, BadPlyFilesAreRefusedByBothReaders) {
  const std::string dir = testing::scratchDir("badply");
  const std::vector<std::array<float, 3>> quad = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  const std::vector<std::vector<int32_t>> faces = {{0, 1, 2}, {0, 2, 3}};
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  struct Case {
    std::string name, bytes, why;
  };
  const std::string good = scannetPly(quad, faces);
  const std::vector<Case> cases = {
      {"truncated", good.substr(0, good.size() - 5), "truncated"},
      {"index", scannetPly(quad, {{0, 1, 2}, {0, 2, 4}}), "index"},
      {"negative", scannetPly(quad, {{0, 1, 2}, {0, -1, 3}}), "index"},
      {"empty", scannetPly(quad, {}), "no triangles"},
      {"lines", scannetPly(quad, {{0, 1}, {2, 3}}), "no triangles"},
      {"nan", scannetPly({{0, 0, 0}, {1, 0, 0}, {1, nan, 0}, {0, 1, 0}}, faces), "not finite"},
      {"inf", scannetPly({{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, -inf}}, faces), "not finite"},
      {"huge", scannetPly(quad, faces, "1000000000000"), "1000000000000"},
      {"hugefaces", scannetPly(quad, faces, "", "1000000000000"), "1000000000000"},
  };
  const auto start = std::chrono::steady_clock::now();
  std::ofstream(dir + "/good.ply", std::ios::binary) << good;
  for (bool fast : {true, false}) {
    LoadOptions o;
    o.plyFastPath = fast;
    EXPECT_EQ(loadScene(dir + "/good.ply", o).mesh.numTriangles(), 2u);
    for (const Case& c : cases) {
      const std::string path = dir + "/" + c.name + ".ply";
      std::ofstream(path, std::ios::binary) << c.bytes;
      const std::string why = refusal(path, o);
      EXPECT_NE(why.find(c.why), std::string::npos)
          << c.name << (fast ? " (fast path): " : " (assimp): ") << why;
    }
  }
  // The same in ASCII, which assimp reads.
  const std::string ascii = plyHeader("ascii", "4", "2");
  const std::vector<Case> asciiCases = {
      {"a_index", ascii + "0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 9\n", "index"},
      {"a_nan", ascii + "0 0 0\n1 0 0\nnan 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n", "not finite"},
      {"a_empty", plyHeader("ascii", "3", "0") + "0 0 0\n1 0 0\n0 1 0\n", "no triangles"},
      {"a_huge", plyHeader("ascii", "1000000000000", "2") + "0 0 0\n", "1000000000000"},
  };
  for (const Case& c : asciiCases) {
    const std::string path = dir + "/" + c.name + ".ply";
    std::ofstream(path) << c.bytes;
    const std::string why = refusal(path);
    EXPECT_NE(why.find(c.why), std::string::npos) << c.name << ": " << why;
  }
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(10));
}

// A glTF whose one triangle is instanced by `nodes` nodes.
std::string instancedGltf(int nodes) {
  std::string nodeList, sceneNodes;
  for (int i = 0; i < nodes; ++i) {
    nodeList +=
        std::string(i ? "," : "") + R"({"mesh":0,"translation":[)" + std::to_string(i) + ",0,0]}";
    sceneNodes += (i ? "," : "") + std::to_string(i);
  }
  // Three float32 VEC3 positions (0,0,0), (1,0,0), (0,1,0), base64.
  const std::string positions = "AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA";
  return R"({"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[)" + sceneNodes +
         R"(]}],"nodes":[)" + nodeList +
         R"(],"meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],)"
         R"("buffers":[{"byteLength":36,"uri":"data:application/octet-stream;base64,)" +
         positions +
         R"("}],"bufferViews":[{"buffer":0,"byteLength":36}],)"
         R"("accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3",)"
         R"("min":[0,0,0],"max":[1,1,0]}]})";
}

TEST(UntrustedScene, InstancingIsCountedAgainstTheLimitsWhileBuilding) {
  const std::string path = testing::scratchDir("inst") + "/many.gltf";
  std::ofstream(path) << instancedGltf(10);
  EXPECT_EQ(loadScene(path).mesh.numTriangles(), 10u);
  LoadOptions o;
  o.maxTriangles = 5;
  EXPECT_NE(refusal(path, o).find("after instancing"), std::string::npos);
}

TEST(UntrustedScene, NamedFilesMustBeRegularFiles) {
  const std::string dir = testing::scratchDir("named");
  // A FIFO would block assimp's open() of the material library forever, /dev/zero would never
  // end as a texture: both are skipped and the geometry still loads.
  ASSERT_EQ(::mkfifo((dir + "/pipe.mtl").c_str(), 0600), 0);
  std::ofstream(dir + "/fifo.obj") << "mtllib pipe.mtl\nusemtl m\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                      "f 1 2 3\n";
  EXPECT_EQ(loadScene(dir + "/fifo.obj").mesh.numTriangles(), 1u);
  std::ofstream(dir + "/dev.mtl") << "newmtl m\nKd 1 1 1\nmap_Kd /dev/zero\n";
  std::ofstream(dir + "/dev.obj") << "mtllib dev.mtl\nusemtl m\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                     "vt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n";
  const Scene s = loadScene(dir + "/dev.obj");
  EXPECT_EQ(s.mesh.numTriangles(), 1u);
  EXPECT_TRUE(s.mesh.textures.empty());
  ASSERT_EQ(s.warnings.size(), 1u);
  EXPECT_NE(s.warnings[0].find("/dev/zero: not a regular file"), std::string::npos)
      << s.warnings[0];
  // A texture larger than maxFileBytes is skipped the same way.
  std::ofstream(dir + "/big.png") << std::string(5000, 'x');
  std::ofstream(dir + "/bigtex.mtl") << "newmtl m\nmap_Kd big.png\n";
  std::ofstream(dir + "/bigtex.obj") << "mtllib bigtex.mtl\nusemtl m\nv 0 0 0\nv 1 0 0\n"
                                        "v 0 1 0\nf 1 2 3\n";
  LoadOptions o;
  o.maxFileBytes = 4096;
  const Scene b = loadScene(dir + "/bigtex.obj", o);
  ASSERT_EQ(b.warnings.size(), 1u);
  EXPECT_NE(b.warnings[0].find("larger than the limit"), std::string::npos) << b.warnings[0];
}

TEST(UntrustedScene, GlbChunkLengthsAreCheckedAgainstTheFile) {
  const std::string dir = testing::scratchDir("glb");
  // Header (magic, version 2, total length), then a JSON chunk claiming 4 GB: assimp would
  // allocate it before reading.
  std::string glb = std::string("glTF\x02\0\0\0", 8) + std::string("\x1c\0\0\0", 4) +
                    std::string("\0\xff\xff\xff", 4) + "JSON" + "{}          ";
  std::ofstream(dir + "/chunk.glb", std::ios::binary) << glb;
  EXPECT_NE(refusal(dir + "/chunk.glb").find("GLB chunk at byte 12 claims 4294967040 bytes"),
            std::string::npos);
  glb.replace(8, 4, std::string("\0\0\0\x10", 4));  // total length 256 MB
  std::ofstream(dir + "/length.glb", std::ios::binary) << glb;
  EXPECT_NE(refusal(dir + "/length.glb").find("GLB header claims 268435456 bytes"),
            std::string::npos);
}

TEST(UntrustedCamera, SizesAreRangeCheckedBeforeNarrowing) {
  nlohmann::json j = cameraToJson(Camera::fromHfov(64, 48, 60));
  auto refused = [](const nlohmann::json& cam, const std::string& fragment) {
    try {
      cameraFromJson(cam, "cam.json");
      ADD_FAILURE() << "accepted " << cam.dump();
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("cam.json: " + fragment), std::string::npos) << e.what();
    }
  };
  EXPECT_EQ(cameraFromJson(j, "cam.json").width, 64);
  j["width"] = 4294967297;  // 2^32 + 1: an int cast would make it 1
  refused(j, "camera size must be in 1..16384");
  j["width"] = -64;
  refused(j, "camera size must be in 1..16384");
  j["width"] = 64.5;
  refused(j, "'width' is not an integer");
  // Without a size, the principal point gives it: 2 cx must be a sane number too.
  j.erase("width");
  j["camera_intrinsics"][0][2] = 1e308;
  refused(j, "no 'width' and the principal point implies no size in 1..16384");
}

}  // namespace
}  // namespace paircast
