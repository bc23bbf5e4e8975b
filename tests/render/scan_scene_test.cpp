// Procedural scans in the scan datasets' formats (make_scenes --scan), and the binary PLY reader
// that loads ScanNet's and Replica's files, against assimp's.
#include "render/scan_scene.h"

#include <gtest/gtest.h>

#include <filesystem>

#include "dataset/test_scenes.h"
#include "render/scene_loader.h"
#include "test_errors.h"
#include "test_paths.h"

namespace paircast {
namespace {

ScanSpec smallScan(ScanKind kind, uint64_t seed = 1) {
  ScanSpec spec;
  spec.kind = kind;
  spec.triangles = 60'000;
  spec.seed = seed;
  return spec;
}

LoadOptions zUp(bool fast = true) {
  LoadOptions o;
  o.up = UpAxis::Z;
  o.plyFastPath = fast;
  return o;
}

TEST(ScanScene, EachKindIsWrittenInItsDatasetsFormatAndLoads) {
  const std::string dir = testing::scratchDir("scans");
  for (ScanKind kind : {ScanKind::ScanNet, ScanKind::Replica, ScanKind::Matterport}) {
    const ScanSpec spec = smallScan(kind);
    const Mesh built = buildScan(spec);
    EXPECT_NEAR(static_cast<double>(built.numTriangles()), 60'000.0, 6'000.0);
    const std::string path = writeScan(spec, dir);
    const std::string file = std::filesystem::path(path).filename().string();
    const Scene scene = loadScene(path, zUp());
    EXPECT_EQ(scene.mesh.numTriangles(), built.numTriangles()) << path;
    const MeshStats stats = computeStats(scene.mesh);
    EXPECT_NEAR(stats.boundsMin.z(), 0.0f, 0.02f);  // z up, floor at 0, millimetre noise
    EXPECT_GT(stats.boundsMax.z(), 2.4f);
    EXPECT_LT(stats.boundsMax.z(), 2.9f);
    if (kind == ScanKind::Matterport) {
      EXPECT_EQ(std::filesystem::path(path).parent_path().filename(), "matterport_mesh");
      EXPECT_GE(scene.mesh.textures.size(), 30u);
      EXPECT_TRUE(scene.warnings.empty()) << scene.warnings[0];
    } else {
      EXPECT_EQ(file, kind == ScanKind::ScanNet ? "scan_scannet_1_vh_clean_2.ply" : "mesh.ply");
      // Vertex colours, not the white default.
      size_t coloured = 0;
      for (const auto& c : scene.mesh.colors)
        coloured += (c - Eigen::Vector3f::Ones()).norm() > 0.1f;
      EXPECT_GT(coloured, scene.mesh.numVertices() * 9 / 10);
    }
  }
}

TEST(ScanScene, DeterministicInTheSeed) {
  const Mesh a = buildScan(smallScan(ScanKind::ScanNet, 5));
  const Mesh b = buildScan(smallScan(ScanKind::ScanNet, 5));
  const Mesh c = buildScan(smallScan(ScanKind::ScanNet, 6));
  ASSERT_EQ(a.positions.size(), b.positions.size());
  EXPECT_TRUE(std::equal(a.positions.begin(), a.positions.end(), b.positions.begin()));
  EXPECT_FALSE(a.positions.size() == c.positions.size() &&
               std::equal(a.positions.begin(), a.positions.end(), c.positions.begin()));
}

// The fast reader and assimp's give the same triangles, corner positions and colours (assimp may
// order vertices differently, so corners are compared through the triangles).
TEST(ScanScene, BinaryPlyReaderMatchesAssimp) {
  const std::string dir = testing::scratchDir("scans_match");
  for (ScanKind kind : {ScanKind::ScanNet, ScanKind::Replica}) {
    ScanSpec spec = smallScan(kind, 2);
    spec.triangles = 5'000;
    const std::string path = writeScan(spec, dir);
    const Scene fast = loadScene(path, zUp(true));
    const Scene slow = loadScene(path, zUp(false));
    ASSERT_EQ(fast.mesh.numTriangles(), slow.mesh.numTriangles());
    for (size_t t = 0; t < fast.mesh.numTriangles(); ++t) {
      const auto& A = fast.mesh;
      const auto& B = slow.mesh;
      for (int k = 0; k < 3; ++k) {
        ASSERT_TRUE(A.positions[A.triangles[t][k]].isApprox(B.positions[B.triangles[t][k]], 1e-6f))
            << scanKindName(kind) << " triangle " << t;
        ASSERT_TRUE(A.colors[A.triangles[t][k]].isApprox(B.colors[B.triangles[t][k]], 1e-5f))
            << scanKindName(kind) << " triangle " << t;
      }
      ASSERT_TRUE(A.materials[A.triangleMaterial[t]].baseColor.isApprox(
          B.materials[B.triangleMaterial[t]].baseColor))
          << B.materials[B.triangleMaterial[t]].baseColor.transpose();
    }
  }
}

TEST(UpAxis, AutoPicksTheAxisAcrossFloorsAndCeilings) {
  const std::string dir = testing::scratchDir("upauto");
  LoadOptions o;
  o.up = UpAxis::Auto;
  for (bool z : {false, true}) {
    const std::string path = dir + (z ? "/room_z.obj" : "/room_y.obj");
    testing::writeBoxesObj(path, testing::roomBoxes(), z);
    EXPECT_EQ(loadScene(path, o).up, z ? UpAxis::Z : UpAxis::Y) << path;
  }
  for (ScanKind kind : {ScanKind::ScanNet, ScanKind::Replica, ScanKind::Matterport}) {
    const std::string path = writeScan(smallScan(kind), dir);
    EXPECT_EQ(loadScene(path, o).up, UpAxis::Z) << path;
  }
  // A long plan of narrow rooms: its walls have as much area across z (353 m^2) as its floor and
  // ceiling across y (348 m^2), but it is 3.1 m high and 7 m deep.
  std::vector<testing::BoxSpec> plan = {{{0, -0.1f, 0}, {12, 0, 7}}, {{0, 2.9f, 0}, {12, 3, 7}}};
  for (float z : {0.0f, 1.7f, 3.4f, 5.1f, 6.9f}) plan.push_back({{0, 0, z}, {12, 2.9f, z + 0.1f}});
  for (bool z : {false, true}) {
    const std::string path = dir + (z ? "/plan_z.obj" : "/plan_y.obj");
    testing::writeBoxesObj(path, plan, z);
    EXPECT_EQ(loadScene(path, o).up, z ? UpAxis::Z : UpAxis::Y) << path;
  }
  // A cube has as much area across y as across z, and is as high as it is deep: no guess.
  const std::string cube = dir + "/cube.obj";
  testing::writeBoxesObj(cube, {{{0, 0, 0}, {1, 1, 1}}});
  const std::string why = testing::refusalOf(cube, [&] { loadScene(cube, o); });
  EXPECT_NE(why.find("1.000000 m along y, 1.000000 m along z): pass --up y or --up z"),
            std::string::npos)
      << why;
  EXPECT_ERROR_CONTAINS(parseUpAxis("x"), "invalid up axis 'x'");
}

}  // namespace
}  // namespace paircast
