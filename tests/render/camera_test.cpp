#include "util/camera.h"

#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>

#include "test_errors.h"
#include "test_paths.h"
#include "util/error.h"
#include "util/random.h"

namespace paircast {
namespace {

TEST(Camera, IntrinsicsFromHfov) {
  const Camera c = Camera::fromHfov(256, 192, 90.0);
  EXPECT_NEAR(c.K(0, 0), 128.0, 1e-9);  // (W/2) / tan(45 deg)
  EXPECT_NEAR(c.K(1, 1), 128.0, 1e-9);
  EXPECT_DOUBLE_EQ(c.K(0, 2), 128.0);
  EXPECT_DOUBLE_EQ(c.K(1, 2), 96.0);
  EXPECT_NEAR(c.hfovDegrees(), 90.0, 1e-9);
}

TEST(Camera, PixelCentreConvention) {
  // The principal point (W/2, H/2) is the corner shared by the four central pixels, so the
  // centre of pixel (W/2, H/2) projects half a pixel right and down of the optical axis.
  const Camera c = Camera::fromHfov(4, 4, 90.0);
  const Eigen::Vector3d r = c.rayCamera(2 + 0.5, 2 + 0.5);
  EXPECT_NEAR(r.x(), 0.5 / c.K(0, 0), 1e-12);
  EXPECT_NEAR(r.y(), 0.5 / c.K(1, 1), 1e-12);
  EXPECT_DOUBLE_EQ(r.z(), 1.0);
}

TEST(Camera, ProjectInvertsRay) {
  Rng rng(7);
  Camera c = Camera::fromHfov(320, 240, 70.0);
  c.K(0, 1) = 0.3;  // a skew, to exercise the general inverse
  for (int i = 0; i < 200; ++i) {
    const double x = rng.uniform(0, 320), y = rng.uniform(0, 240), z = rng.uniform(0.1, 50);
    const Eigen::Vector2d p = c.project(z * c.rayCamera(x, y));
    EXPECT_NEAR(p.x(), x, 1e-9);
    EXPECT_NEAR(p.y(), y, 1e-9);
  }
}

TEST(Camera, LookAtFollowsOpenCvAxes) {
  Camera c = Camera::fromHfov(64, 64, 60.0);
  // Looking along +x with z up: right is -y, down is -z, forward is +x.
  c.lookAt({1, 2, 3}, {5, 2, 3}, {0, 0, 1});
  EXPECT_TRUE(c.R_cam2world.col(0).isApprox(Eigen::Vector3d(0, -1, 0)));
  EXPECT_TRUE(c.R_cam2world.col(1).isApprox(Eigen::Vector3d(0, 0, -1)));
  EXPECT_TRUE(c.R_cam2world.col(2).isApprox(Eigen::Vector3d(1, 0, 0)));
  EXPECT_TRUE(c.t_cam2world.isApprox(Eigen::Vector3d(1, 2, 3)));
  // The target projects to the principal point.
  const Eigen::Vector3d p = c.cameraFromWorld() * Eigen::Vector3d(5, 2, 3);
  EXPECT_TRUE(c.project(p).isApprox(Eigen::Vector2d(32, 32)));
}

TEST(Camera, LookAtIsARotationForRandomPoses) {
  Rng rng(11);
  for (int i = 0; i < 100; ++i) {
    const Eigen::Vector3d eye(rng.normal(), rng.normal(), rng.normal());
    const Eigen::Vector3d target(rng.normal(), rng.normal(), rng.normal());
    const Eigen::Matrix3d R = lookAtRotation(eye, target, Eigen::Vector3d::UnitY());
    EXPECT_TRUE((R.transpose() * R).isIdentity(1e-9));
    EXPECT_NEAR(R.determinant(), 1.0, 1e-9);
    EXPECT_TRUE(R.col(2).isApprox((target - eye).normalized()));
    EXPECT_NEAR(R.col(0).dot(Eigen::Vector3d::UnitY()), 0.0, 1e-9);  // level: no roll
    EXPECT_LT(R.col(1).dot(Eigen::Vector3d::UnitY()), 0.0);          // image down is world down
  }
}

TEST(Camera, LookAtRejectsDegenerateViews) {
  EXPECT_ERROR_CONTAINS(lookAtRotation({0, 0, 0}, {0, 0, 0}, {0, 1, 0}), "eye and target coincide");
  EXPECT_ERROR_CONTAINS(lookAtRotation({0, 0, 0}, {0, 3, 0}, {0, 1, 0}),
                        "viewing direction is parallel to up");
}

TEST(CameraJson, RoundTrip) {
  Camera c = Camera::fromHfov(200, 100, 75.0);
  c.lookAt({0.5, 1.5, -2}, {3, 1, 4}, {0, 1, 0});
  const std::string path = testing::scratchDir("cam") + "/cam.json";
  writeCameraJson(path, c);
  const Camera d = readCameraJson(path);
  EXPECT_EQ(d.width, 200);
  EXPECT_EQ(d.height, 100);
  EXPECT_TRUE(d.K.isApprox(c.K));
  EXPECT_TRUE(d.R_cam2world.isApprox(c.R_cam2world));
  EXPECT_TRUE(d.t_cam2world.isApprox(c.t_cam2world));
}

TEST(CameraJson, AcceptsCrocoFilesWithoutSize) {
  nlohmann::json j = cameraToJson(Camera::fromHfov(320, 240, 60));
  j.erase("width");
  j.erase("height");
  const Camera c = cameraFromJson(j, "croco.json");
  EXPECT_EQ(c.width, 320);
  EXPECT_EQ(c.height, 240);
}

TEST(CameraJson, RejectsBadInputNamingTheFile) {
  const nlohmann::json good = cameraToJson(Camera::fromHfov(64, 64, 60));
  auto expectError = [](const nlohmann::json& j, const std::string& fragment) {
    try {
      cameraFromJson(j, "bad_cam.json");
      FAIL() << "expected an error for " << j.dump();
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("bad_cam.json"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    }
  };
  nlohmann::json j = good;
  j.erase("R_cam2world");
  expectError(j, "R_cam2world");
  j = good;
  j["t_cam2world"] = {1, 2};
  expectError(j, "t_cam2world");
  j = good;
  j["R_cam2world"] = {{2, 0, 0}, {0, 1, 0}, {0, 0, 1}};  // not a rotation
  expectError(j, "invalid camera");
  j = good;
  j["camera_intrinsics"][0][0] = "x";
  expectError(j, "camera_intrinsics");
  j = good;
  j["width"] = -3;
  expectError(j, "size");
  expectError(nlohmann::json::array(), "not an object");

  const std::string dir = testing::scratchDir("bad");
  std::ofstream(dir + "/bad_cam.json") << "{ not json";
  EXPECT_ERROR_CONTAINS(readCameraJson(dir + "/bad_cam.json"),
                        dir + "/bad_cam.json: not valid JSON");
  EXPECT_ERROR_CONTAINS(readCameraJson(dir + "/missing.json"),
                        dir + "/missing.json: cannot open file");
}

}  // namespace
}  // namespace paircast
