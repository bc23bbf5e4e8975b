#include "dataset/floor_map.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "dataset/test_scenes.h"
#include "dataset/viewpoint_sampler.h"
#include "render/procedural_scene.h"
#include "render/scan_scene.h"
#include "test_errors.h"
#include "test_paths.h"
#include "util/error.h"
#include "util/random.h"

namespace paircast {
namespace {

Scene loadBoxes(const std::vector<testing::BoxSpec>& boxes, bool zUp, const std::string& name) {
  const std::string path = testing::scratchDir(name) + "/" + name + ".obj";
  testing::writeBoxesObj(path, boxes, zUp);
  LoadOptions o;
  o.up = zUp ? UpAxis::Z : UpAxis::Y;
  return loadScene(path, o);
}

TEST(FloorMap, FindsTheRoomFloorAndNotTheFurniture) {
  const Scene scene = loadBoxes(testing::roomBoxes(), false, "room");
  RayCaster caster(scene.mesh);
  FloorMap floor(scene, caster);
  ASSERT_FALSE(floor.empty());
  EXPECT_TRUE(floor.hasCeiling());
  // 6 x 5 m inside, minus the wall clearance band and the cabinet: roughly 5.5 x 4.5 - 1.
  EXPECT_GT(floor.area(), 15.0);
  EXPECT_LT(floor.area(), 30.0);
  for (const auto& p : floor.points()) {
    ASSERT_NEAR(p.y(), 0.0f, 1e-3f) << "table top or cabinet taken as floor";
    ASSERT_LT(std::abs(p.x()), 3.0f - 0.2f);
    ASSERT_LT(std::abs(p.z()), 2.5f - 0.2f);
    // Not under the table: its top leaves only 0.7 m of headroom.
    ASSERT_FALSE(std::abs(p.x()) < 0.55f && std::abs(p.z()) < 0.35f);
  }
}

// Scenes built in memory: the floor map needs no file.
Scene sceneOf(Mesh mesh, UpAxis up) {
  Scene scene;
  scene.path = scene.name = "test";
  scene.up = up;
  scene.mesh = std::move(mesh);
  return scene;
}

Scene boxesScene(const std::vector<testing::BoxSpec>& boxes) {
  Mesh mesh;
  const int material = mesh.addMaterial(Material{});
  for (const auto& b : boxes) addBox(mesh, b.lo, b.hi, material);
  return sceneOf(std::move(mesh), UpAxis::Y);
}

// A scan as make_scenes --scan writes it, small (100k triangles, so 5.7 cm cells) but with the
// noise scaled to match: 1.2 cm on 5.7 cm cells tilts the triangles as 3 mm does on 1.5 cm ones.
Scene noisyScan() {
  ScanSpec spec;
  spec.triangles = 100'000;
  spec.noise = 0.012f;
  spec.seed = 3;
  return sceneOf(buildScan(spec), UpAxis::Z);
}

TEST(FloorMap, NoisyDenselyTessellatedScanFloorIsWalkable) {
  const Scene scene = noisyScan();
  // The trait under test: many floor triangles tilt past the 20 degree slope limit.
  size_t floorTriangles = 0, tilted = 0;
  for (const auto& t : scene.mesh.triangles) {
    const Eigen::Vector3f a = scene.mesh.positions[t[0]], b = scene.mesh.positions[t[1]],
                          c = scene.mesh.positions[t[2]];
    if (std::max({a.z(), b.z(), c.z()}) > 0.05f) continue;
    ++floorTriangles;
    tilted += std::abs((b - a).cross(c - a).normalized().z()) < std::cos(20.0 * M_PI / 180);
  }
  ASSERT_GT(floorTriangles, 10000u);
  EXPECT_GT(tilted, floorTriangles / 20) << "the scan is not noisy enough to test anything";

  RayCaster caster(scene.mesh);
  FloorMap floor(scene, caster);
  ASSERT_FALSE(floor.empty());
  EXPECT_TRUE(floor.hasCeiling());
  // The room is about 7 x 5.5 m; furniture, the partition and the clearance band take a part.
  EXPECT_GT(floor.area(), 15.0);
  for (const auto& p : floor.points()) ASSERT_LT(std::abs(p.z()), 0.05f) << p.transpose();
}

TEST(FloorMap, FloorUnderAGapInTheCeilingIsKept) {
  const Scene scene = noisyScan();
  RayCaster caster(scene.mesh);
  FloorMap floor(scene, caster);
  int uncovered = 0;
  for (const auto& p : floor.points()) {
    Ray up{p + Eigen::Vector3f(0, 0, 0.05f), Eigen::Vector3f::UnitZ()};
    Hit hit;
    caster.intersect(&up, &hit, 1);
    uncovered += hit.triangle < 0;
  }
  // The scan's ceiling misses about 2 x 2 m and a strip along a wall.
  EXPECT_GT(uncovered, 100) << "floor under the ceiling's gap was dropped";
  EXPECT_LT(uncovered, static_cast<int>(floor.size()) / 2);
}

TEST(FloorMap, RoomWithoutCeilingHasAFloor) {
  std::vector<testing::BoxSpec> boxes = testing::roomBoxes();
  boxes.erase(boxes.begin() + 1);  // the ceiling slab
  const Scene scene = boxesScene(boxes);
  RayCaster caster(scene.mesh);
  FloorMap floor(scene, caster);
  ASSERT_FALSE(floor.empty());
  EXPECT_FALSE(floor.hasCeiling());
  EXPECT_GT(floor.area(), 15.0);
  for (const auto& p : floor.points()) ASSERT_NEAR(p.y(), 0.0f, 1e-3f);
}

TEST(FloorMap, GroundOutsideAndRoofAreNotInside) {
  // The room on a 30 x 30 m ground: the ground and the roof have nothing above them and no walls
  // around them; only the room's floor is walkable.
  std::vector<testing::BoxSpec> boxes = testing::roomBoxes();
  boxes.push_back({{-15.0f, -0.2f, -15.0f}, {15.0f, -0.1f, 15.0f}});
  const Scene scene = boxesScene(boxes);
  RayCaster caster(scene.mesh);
  FloorMap floor(scene, caster);
  ASSERT_FALSE(floor.empty());
  EXPECT_TRUE(floor.hasCeiling());
  for (const auto& p : floor.points()) {
    ASSERT_NEAR(p.y(), 0.0f, 1e-3f) << p.transpose();
    ASSERT_LT(std::abs(p.x()), 3.0f) << p.transpose();
    ASSERT_LT(std::abs(p.z()), 2.5f) << p.transpose();
  }
}

TEST(FloorMap, NobodyStandsOverAHoleInTheFloor) {
  // The floor slab has a 1 x 1 m hole over a basement 1.2 m below: what shows through it is
  // too small and too low (1.1 m of headroom around) to walk in.
  std::vector<testing::BoxSpec> boxes = testing::roomBoxes();
  boxes[0] = {{-3.1f, -0.1f, -2.6f}, {0.5f, 0.0f, 2.6f}};
  boxes.push_back({{1.5f, -0.1f, -2.6f}, {3.1f, 0.0f, 2.6f}});
  boxes.push_back({{0.5f, -0.1f, -2.6f}, {1.5f, 0.0f, 0.5f}});
  boxes.push_back({{0.5f, -0.1f, 1.5f}, {1.5f, 0.0f, 2.6f}});
  boxes.push_back({{-3.1f, -1.3f, -2.6f}, {3.1f, -1.2f, 2.6f}});  // the basement's floor
  const Scene scene = boxesScene(boxes);
  RayCaster caster(scene.mesh);
  FloorMap floor(scene, caster);
  ASSERT_FALSE(floor.empty());
  for (const auto& p : floor.points()) {
    ASSERT_NEAR(p.y(), 0.0f, 1e-3f);
    ASSERT_FALSE(p.x() > 0.5f && p.x() < 1.5f && p.z() > 0.5f && p.z() < 1.5f) << p.transpose();
  }
  EXPECT_GT(floor.area(), 12.0);
}

TEST(FloorMap, StairsLeaveNoPointInMidAir) {
  // A 8 x 6 m hall, 5.2 m high, with five 0.3 m treads rising 1/6 m each from x = 0 to a
  // platform 1 m high over x = 1.5 .. 4.
  std::vector<testing::BoxSpec> boxes = {
      {{-4.1f, -0.1f, -3.1f}, {4.1f, 0.0f, 3.1f}}, {{-4.1f, 5.2f, -3.1f}, {4.1f, 5.3f, 3.1f}},
      {{-4.1f, 0.0f, -3.1f}, {-4.0f, 5.2f, 3.1f}}, {{4.0f, 0.0f, -3.1f}, {4.1f, 5.2f, 3.1f}},
      {{-4.0f, 0.0f, -3.1f}, {4.0f, 5.2f, -3.0f}}, {{-4.0f, 0.0f, 3.0f}, {4.0f, 5.2f, 3.1f}},
      {{1.5f, 0.0f, -3.0f}, {4.0f, 1.0f, 3.0f}}};
  for (int i = 0; i < 5; ++i)
    boxes.push_back({{0.3f * i, 0.0f, -1.0f}, {0.3f * (i + 1), (i + 1) / 6.0f, 1.0f}});
  const Scene scene = boxesScene(boxes);
  RayCaster caster(scene.mesh);
  FloorMap floor(scene, caster);
  double ground = 0, platform = 0;
  const double cell = 0.01;  // the default cell is 0.1 m: 0.01 m^2 per point
  for (const auto& p : floor.points()) {
    // On a tread, the ground or the platform: a multiple of 1/6 m, never between.
    const float level = std::round(p.y() * 6.0f) / 6.0f;
    ASSERT_NEAR(p.y(), level, 1e-3f) << p.transpose();
    ASSERT_GE(level, 0.0f);
    ASSERT_LE(level, 1.0f + 1e-3f);
    ground += level == 0.0f ? cell : 0.0;
    platform += std::abs(level - 1.0f) < 1e-3f ? cell : 0.0;
  }
  EXPECT_GT(ground, 15.0);
  EXPECT_GT(platform, 8.0);
}

TEST(FloorMap, ClutterIsNotFloor) {
  // Boxes of 15-35 cm, 10-50 cm high, strewn over the room's floor: their tops are flat and
  // connect to the floor within a step, but no footprint fits on them.
  std::vector<testing::BoxSpec> boxes = testing::roomBoxes();
  Rng rng(11);
  for (int k = 0; k < 25; ++k) {
    const float x = static_cast<float>(rng.uniform(-2.5, 2.5));
    const float z = static_cast<float>(rng.uniform(-2.0, 2.0));
    const float w = static_cast<float>(rng.uniform(0.15, 0.35));
    const float h = static_cast<float>(rng.uniform(0.1, 0.5));
    boxes.push_back({{x, 0.0f, z}, {x + w, h, z + w}});
  }
  const Scene scene = boxesScene(boxes);
  RayCaster caster(scene.mesh);
  FloorMap floor(scene, caster);
  ASSERT_FALSE(floor.empty());
  EXPECT_GT(floor.area(), 8.0);
  for (const auto& p : floor.points()) ASSERT_NEAR(p.y(), 0.0f, 1e-3f) << p.transpose();
}

TEST(FloorMap, UpAxisOptionFindsTheFloorOfAZUpScene) {
  const Scene zup = loadBoxes(testing::roomBoxes(), true, "zup");
  RayCaster caster(zup.mesh);
  FloorMap floor(zup, caster);
  ASSERT_FALSE(floor.empty());
  for (const auto& p : floor.points()) ASSERT_NEAR(p.z(), 0.0f, 1e-3f);
  // Read as y-up, the same file is a room lying on its side: its "floor" is a wall.
  Scene wrong = zup;
  wrong.up = UpAxis::Y;
  FloorMap sideways(wrong, caster);
  ASSERT_FALSE(sideways.empty());
  for (const auto& p : sideways.points()) ASSERT_NEAR(p.y(), -2.5f, 1e-3f);
}

TEST(FloorMap, SnapReturnsTheNearestWalkablePoint) {
  const Scene scene = loadBoxes(testing::roomBoxes(), false, "snap");
  RayCaster caster(scene.mesh);
  FloorMap floor(scene, caster);
  auto p = floor.snap({0.0f, 1.0f, 2.45f});  // near the wall: snapped inside the clearance
  ASSERT_TRUE(p.has_value());
  EXPECT_NEAR(p->y(), 0.0f, 1e-3f);
  EXPECT_LT(p->z(), 2.3f);
  EXPECT_FALSE(floor.snap({50.0f, 0.0f, 50.0f}).has_value());
}

TEST(FloorMap, SnapAgreesWithABruteForceSearch) {
  // snap searches rings of cells nearest first; its answer must be the nearest walkable point
  // within the radius, as a scan of every point finds it, for points on, near and off the map.
  const Scene scene = loadBoxes(testing::roomBoxes(), false, "snap_brute");
  RayCaster caster(scene.mesh);
  FloorMap floor(scene, caster);
  ASSERT_GT(floor.size(), 100u);
  Rng rng(17);
  int found = 0, missing = 0;
  for (int k = 0; k < 3000; ++k) {
    const Eigen::Vector3f p(static_cast<float>(rng.uniform(-6, 6)),
                            static_cast<float>(rng.uniform(-0.5, 2)),
                            static_cast<float>(rng.uniform(-6, 6)));
    const double radius = k % 3 == 0 ? 0.35 : 2.0;
    float best = std::numeric_limits<float>::infinity();
    for (const Eigen::Vector3f& q : floor.points()) best = std::min(best, (q - p).squaredNorm());
    const auto snapped = floor.snap(p, radius);
    if (best > radius * radius) {
      EXPECT_FALSE(snapped.has_value()) << p.transpose();
      ++missing;
      continue;
    }
    ASSERT_TRUE(snapped.has_value()) << p.transpose();
    EXPECT_EQ((*snapped - p).squaredNorm(), best) << p.transpose();
    ++found;
  }
  EXPECT_GT(found, 600);
  EXPECT_GT(missing, 300);
}

TEST(ViewpointSampler, SceneWithoutFloorIsAnErrorNamingIt) {
  const Scene wall = loadBoxes({{{0, 0, 0}, {0.1f, 3, 4}}}, false, "wall");
  RayCaster caster(wall.mesh);
  try {
    ViewpointSampler sampler(wall, caster, SamplerOptions{});
    FAIL() << "expected no walkable floor";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("wall.obj"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("no walkable floor"), std::string::npos);
  }
}

TEST(ViewpointSampler, CamerasFollowCrocoRanges) {
  const Scene scene = loadBoxes(testing::roomBoxes(), false, "ranges");
  RayCaster caster(scene.mesh);
  SamplerOptions o;
  ViewpointSampler sampler(scene, caster, o);
  const Camera intr = Camera::fromHfov(32, 32, 60);
  Rng rng(42);
  const Eigen::Vector3d up(0, 1, 0);
  for (int i = 0; i < 300; ++i) {
    const Viewpoint v = sampler.sampleReference(intr, rng);
    const double height = v.camera.t_cam2world.y() - v.floorPoint.y();
    ASSERT_GE(height, 1.2 - 1e-9);
    ASSERT_LE(height, 1.8 + 1e-9);
    ASSERT_NEAR(v.floorPoint.y(), 0.0, 1e-3);
    const Eigen::Matrix3d& R = v.camera.R_cam2world;
    ASSERT_TRUE((R.transpose() * R).isIdentity(1e-9));
    // Tilt: the optical axis is within 10 deg (+ a little from pan/roll coupling) of horizontal.
    const double elevation = std::asin(R.col(2).dot(up)) * 180 / M_PI;
    ASSERT_LE(std::abs(elevation), 10.5);
    // Image down points down.
    ASSERT_LT(R.col(1).dot(up), -0.9);
    // The second view stands on the floor, at the same heights, looking at the target.
    const Eigen::Vector3d target(0, 1, 0);
    const Viewpoint w = sampler.sampleOther(intr, v, target, rng);
    ASSERT_NEAR(w.floorPoint.y(), 0.0, 1e-3);
    const double h2 = w.camera.t_cam2world.y() - w.floorPoint.y();
    ASSERT_GE(h2, 1.2 - 1e-9);
    ASSERT_LE(h2, 1.8 + 1e-9);
    const Eigen::Vector3d toTarget = (target - w.camera.t_cam2world).normalized();
    // Within the noise (3 deg pan, 10 deg tilt) of the look-at direction.
    ASSERT_GT(w.camera.R_cam2world.col(2).dot(toTarget), std::cos(11.0 * M_PI / 180));
  }
}

TEST(ViewpointSampler, NearMotionStaysWithinItsBounds) {
  // --motion near: the second camera is the first moved by at most nearTranslation (vertical
  // part halved) and turned by at most nearRotation in pan and tilt, half in roll. The bounds are
  // reached: over 300 draws the largest translation and turn come within 20 % of them.
  const Scene scene = loadBoxes(testing::roomBoxes(), false, "near");
  RayCaster caster(scene.mesh);
  SamplerOptions o;
  o.motion = SamplerOptions::Motion::kNear;
  o.nearTranslation = 0.2;
  o.nearRotation = 5.0;
  ViewpointSampler sampler(scene, caster, o);
  const Camera intr = Camera::fromHfov(32, 32, 60);
  Rng rng(7);
  const Eigen::Vector3d up(0, 1, 0);
  double farthest = 0, widest = 0;
  for (int i = 0; i < 300; ++i) {
    const Viewpoint v = sampler.sampleReference(intr, rng);
    const Viewpoint w = sampler.sampleOther(intr, v, Eigen::Vector3d(0, 1, 0), rng);
    const Eigen::Vector3d d = w.camera.t_cam2world - v.camera.t_cam2world;
    ASSERT_LE(d.norm(), 0.2 + 1e-9);
    ASSERT_LE(std::abs(d.dot(up)), 0.1 + 1e-9);
    const Eigen::Matrix3d turn = v.camera.R_cam2world.transpose() * w.camera.R_cam2world;
    const double angle = Eigen::AngleAxisd(turn).angle() * 180 / M_PI;
    // pan, tilt <= 5 and roll <= 2.5 degrees compose to at most sqrt(5^2 + 5^2 + 2.5^2).
    ASSERT_LE(angle, 7.5 + 1e-6);
    ASSERT_TRUE((w.camera.R_cam2world.transpose() * w.camera.R_cam2world).isIdentity(1e-9));
    farthest = std::max(farthest, d.norm());
    widest = std::max(widest, angle);
  }
  EXPECT_GT(farthest, 0.16);
  EXPECT_GT(widest, 5.0);
  EXPECT_EQ(parseMotion("near"), SamplerOptions::Motion::kNear);
  EXPECT_ERROR_CONTAINS(parseMotion("jump"), "walk or near, not 'jump'");
}

TEST(ViewpointSampler, OrientationNoiseAxes) {
  // Pan turns about the camera's up (-y), tilt about its right (+x), roll about forward (+z).
  const Eigen::Matrix3d pan = orientationNoise(90, 0, 0);
  EXPECT_TRUE((pan * Eigen::Vector3d::UnitY()).isApprox(Eigen::Vector3d::UnitY()));
  const Eigen::Matrix3d tilt = orientationNoise(0, 90, 0);
  EXPECT_TRUE((tilt * Eigen::Vector3d::UnitX()).isApprox(Eigen::Vector3d::UnitX()));
  const Eigen::Matrix3d roll = orientationNoise(0, 0, 90);
  EXPECT_TRUE((roll * Eigen::Vector3d::UnitZ()).isApprox(Eigen::Vector3d::UnitZ()));
}

}  // namespace
}  // namespace paircast
