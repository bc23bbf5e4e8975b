#include "dataset/floor_map.h"

#include <gtest/gtest.h>

#include "dataset/test_scenes.h"
#include "dataset/viewpoint_sampler.h"
#include "test_paths.h"
#include "util/error.h"

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
