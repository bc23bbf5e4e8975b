#include "render/procedural_scene.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <set>

#include "render/obj_writer.h"
#include "render/ray_caster.h"
#include "render/scene_loader.h"
#include "test_paths.h"

namespace paircast {
namespace {

const LayoutSpec& apartment() {
  static const LayoutSpec spec = [] {
    for (const auto& l : shippedLayouts())
      if (l.name == "apartment") return l;
    throw std::runtime_error("no apartment layout");
  }();
  return spec;
}

TEST(ProceduralScene, SameSeedSameMesh) {
  const Mesh a = buildLayout(apartment()), b = buildLayout(apartment());
  ASSERT_EQ(a.numTriangles(), b.numTriangles());
  EXPECT_EQ(a.positions, b.positions);
  ASSERT_EQ(a.textures.size(), b.textures.size());
  for (size_t t = 0; t < a.textures.size(); ++t)
    EXPECT_EQ(a.textures[t].texels, b.textures[t].texels);
  LayoutSpec other = apartment();
  other.seed += 1;
  EXPECT_NE(buildLayout(other).textures[0].texels, a.textures[0].texels);
}

// From the middle of each room at 1.5 m: floor below, ceiling above, walls all around.
void expectValidAndEnclosed(const LayoutSpec& layout) {
  SCOPED_TRACE(layout.name);
  const Mesh mesh = buildLayout(layout);
  EXPECT_NO_THROW(mesh.validate(layout.name));
  EXPECT_LT(mesh.numTriangles(), 20000u);
  RayCaster caster(mesh);
  for (const auto& r : layout.rooms) {
    const Eigen::Vector3f c(0.5f * (r.x0 + r.x1) + 0.13f, 1.5f, 0.5f * (r.z0 + r.z1) + 0.17f);
    std::vector<Ray> rays = {{c, -Eigen::Vector3f::UnitY()}, {c, Eigen::Vector3f::UnitY()}};
    for (int k = 0; k < 16; ++k) {
      const float a = 2.0f * static_cast<float>(M_PI) * k / 16;
      rays.push_back({c, Eigen::Vector3f(std::cos(a), 0.0f, std::sin(a))});
    }
    std::vector<Hit> hits(rays.size());
    caster.intersect(rays.data(), hits.data(), rays.size());
    EXPECT_NEAR(hits[1].t, layout.height - 1.5f, 1e-3f) << "ceiling";
    EXPECT_LE(hits[0].t, 1.5f + 1e-3f) << "floor (or furniture on it)";
    for (size_t k = 0; k < hits.size(); ++k)
      EXPECT_GE(hits[k].triangle, 0) << "ray " << k << " escapes";
  }
}

// A horizontal ray at 1 m through each door's centre, from 0.3 m before to 0.3 m after the wall,
// passes; one a door's width beside it hits the wall.
void expectDoorsOpen(const LayoutSpec& layout) {
  SCOPED_TRACE(layout.name);
  RayCaster caster(buildLayout(layout));
  for (const auto& d : layout.doors) {
    const RoomSpec& a = layout.rooms[d.roomA];
    const RoomSpec& b = layout.rooms[d.roomB];
    const bool sharedX = std::abs(a.x1 - b.x0) < 1e-3f || std::abs(a.x0 - b.x1) < 1e-3f;
    const float wall = sharedX ? (std::abs(a.x1 - b.x0) < 1e-3f ? a.x1 : a.x0)
                               : (std::abs(a.z1 - b.z0) < 1e-3f ? a.z1 : a.z0);
    Eigen::Vector3f o, dir;
    if (sharedX)
      o = {wall - 0.3f, 1.0f, d.at}, dir = Eigen::Vector3f::UnitX();
    else
      o = {d.at, 1.0f, wall - 0.3f}, dir = Eigen::Vector3f::UnitZ();
    Ray through{o, dir, 0.0f, 0.6f};
    Hit hit;
    caster.intersect(&through, &hit, 1);
    EXPECT_LT(hit.triangle, 0) << "door between rooms " << d.roomA << " and " << d.roomB
                               << " is blocked";
    // Beside the door, on the side where more of the shared wall is left.
    const float from = sharedX ? std::max(a.z0, b.z0) : std::max(a.x0, b.x0);
    const float to = sharedX ? std::min(a.z1, b.z1) : std::min(a.x1, b.x1);
    const float side = d.at - from > to - d.at ? -d.width : d.width;
    Ray beside{o + (sharedX ? Eigen::Vector3f(0, 0, side) : Eigen::Vector3f(side, 0, 0)), dir, 0.0f,
               0.6f};
    caster.intersect(&beside, &hit, 1);
    EXPECT_GE(hit.triangle, 0) << "no wall beside the door";
  }
}

TEST(ProceduralScene, EveryShippedLayoutIsValidAndEnclosed) {
  for (const auto& layout : shippedLayouts()) expectValidAndEnclosed(layout);
}

TEST(ProceduralScene, DoorsConnectRooms) {
  expectDoorsOpen(apartment());
}

TEST(ProceduralScene, RandomLayoutsAreValidEnclosedAndConnected) {
  std::set<size_t> roomCounts;
  for (uint64_t seed = 1; seed <= 20; ++seed) {
    const LayoutSpec layout = randomLayout("random_" + std::to_string(seed), seed);
    SCOPED_TRACE(layout.name);
    roomCounts.insert(layout.rooms.size());
    for (const auto& r : layout.rooms) {
      EXPECT_GE(r.x1 - r.x0, 3.0f - 1e-3f);
      EXPECT_GE(r.z1 - r.z0, 3.0f - 1e-3f);
    }
    // Rooms tile the rectangle: their areas add up to its area.
    float area = 0, x1 = 0, z1 = 0;
    for (const auto& r : layout.rooms)
      area += (r.x1 - r.x0) * (r.z1 - r.z0), x1 = std::max(x1, r.x1), z1 = std::max(z1, r.z1);
    EXPECT_NEAR(area, x1 * z1, 1e-2f);
    // Every room is reachable from room 0 through doors.
    std::vector<int> reached(layout.rooms.size(), 0);
    reached[0] = 1;
    for (size_t pass = 0; pass < layout.rooms.size(); ++pass)
      for (const auto& d : layout.doors)
        if (reached[d.roomA] || reached[d.roomB]) reached[d.roomA] = reached[d.roomB] = 1;
    EXPECT_EQ(std::count(reached.begin(), reached.end(), 1),
              static_cast<long>(layout.rooms.size()));
    expectValidAndEnclosed(layout);
    expectDoorsOpen(layout);
    // Deterministic in the seed.
    const LayoutSpec again = randomLayout(layout.name, seed);
    EXPECT_EQ(again.rooms.size(), layout.rooms.size());
    EXPECT_EQ(again.doors.size(), layout.doors.size());
  }
  EXPECT_GE(roomCounts.size(), 4u) << "the plans should vary in their number of rooms";
}

TEST(ProceduralScene, BuildingsHaveTheRoomsAskedForAndStayConnected) {
  for (int rooms : {6, 8, 11}) {
    for (uint64_t seed = 1; seed <= 3; ++seed) {
      const LayoutSpec layout = randomLayout("building", seed * 31 + rooms, rooms);
      SCOPED_TRACE(std::to_string(rooms) + " rooms, seed " + std::to_string(seed));
      ASSERT_EQ(static_cast<int>(layout.rooms.size()), rooms);
      float area = 0, x1 = 0, z1 = 0;
      for (const auto& r : layout.rooms) {
        EXPECT_GE(r.x1 - r.x0, 3.0f - 1e-3f);
        EXPECT_GE(r.z1 - r.z0, 3.0f - 1e-3f);
        area += (r.x1 - r.x0) * (r.z1 - r.z0), x1 = std::max(x1, r.x1), z1 = std::max(z1, r.z1);
      }
      EXPECT_NEAR(area, x1 * z1, 1e-1f);
      EXPECT_LE(area, rooms * 20.0f * 1.1f * 1.1f * 1.1f) << "a house, not a hangar";
      std::vector<int> reached(layout.rooms.size(), 0);
      reached[0] = 1;
      for (size_t pass = 0; pass < layout.rooms.size(); ++pass)
        for (const auto& d : layout.doors)
          if (reached[d.roomA] || reached[d.roomB]) reached[d.roomA] = reached[d.roomB] = 1;
      EXPECT_EQ(std::count(reached.begin(), reached.end(), 1), rooms);
      if (rooms == 6 && seed == 1) {
        expectValidAndEnclosed(layout);
        expectDoorsOpen(layout);
      }
    }
  }
}

TEST(ObjWriter, RoundTripsThroughTheLoader) {
  const Mesh mesh = buildLayout(shippedLayouts().front());
  const std::string path = testing::scratchDir("obj") + "/room.obj";
  writeObj(path, mesh);
  const Scene back = loadScene(path);
  ASSERT_EQ(back.mesh.numTriangles(), mesh.numTriangles());
  EXPECT_EQ(back.mesh.textures.size(), mesh.textures.size());
  EXPECT_TRUE(back.warnings.empty());
  const MeshStats a = computeStats(mesh), b = computeStats(back.mesh);
  EXPECT_TRUE(a.boundsMin.isApprox(b.boundsMin, 1e-5f));
  EXPECT_TRUE(a.boundsMax.isApprox(b.boundsMax, 1e-5f));
  // Same pictures: a view rendered from both agrees pixel for pixel in depth.
  RayCaster c1(mesh), c2(back.mesh);
  Camera cam = Camera::fromHfov(64, 64, 70);
  cam.lookAt({1.0, 1.5, 1.0}, {4, 1, 3}, {0, 1, 0});
  Frame f1, f2;
  c1.render(cam, RenderOptions{}, f1);
  c2.render(cam, RenderOptions{}, f2);
  for (size_t i = 0; i < f1.depth.size(); ++i)
    ASSERT_NEAR(f1.depth.data[i], f2.depth.data[i], 1e-4f);
  int differing = 0;
  for (size_t i = 0; i < f1.rgb.size(); ++i)
    differing += std::abs(int(f1.rgb.data[i]) - int(f2.rgb.data[i])) > 2;
  EXPECT_LT(differing, static_cast<int>(f1.rgb.size() / 50));
}

TEST(ProceduralScene, CommittedScenesMatchTheGenerator) {
  // scenes/ is generated by make_scenes; this fails when the generator changes without a rerun.
  for (const auto& layout : shippedLayouts()) {
    const std::string path =
        testing::sourceDir() + "/scenes/" + layout.name + "/" + layout.name + ".obj";
    const Scene shipped = loadScene(path);
    const Mesh fresh = buildLayout(layout);
    EXPECT_EQ(shipped.mesh.numTriangles(), fresh.numTriangles())
        << path << " is stale: run build/tools/make_scenes --out scenes";
    EXPECT_EQ(shipped.mesh.textures.size(), fresh.textures.size()) << path;
  }
}

}  // namespace
}  // namespace paircast
